"""The population-robustness card's tables (pure).

Pipeline: ``card_tables(runs, pedestrians, controller, baselines, robustness, rng=...)`` →
:class:`Card` (pure, from :mod:`popnavshift.analysis`) → ``card_figure`` and
``render_html`` of :mod:`.card_page` (given the replay SVG of the worst run, drawn
elsewhere).

What the card says:

* first, its two verdicts (:mod:`.verdict`): **robustness**, decided against the
  controller's own null runs on every evaluation part (:mod:`.robustness`, computed by
  the caller: the observed reversal rates of its orderings against the baselines beside
  their null, with the deciding intervals and the card's own calibration), and
  **safety**, under one rule for every controller (:mod:`.safety`);
* on the main part (every population × cell): outcomes per controller (Table II's
  columns, pedestrian collisions with the robot moving apart from pedestrians walking into
  the standing robot, controller errors included, and the robot's minimum clearance, path
  length and stop time); robot time, mean and worst-decile pedestrian delay per population
  [s], each the mean over cells of the cell metric, with the gap to the best baseline;
  the populations where it does worst; ranks with rank intervals, wins and losses per
  cell and the crossover tests (:func:`.verdict.card_evidence`);
* the worst run: a collision, else a timeout, else the largest worst-decile delay.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd

from ..analysis import (
    METRICS,
    RANKED_METRICS,
    cell_metrics,
    controller_outcomes,
    paired_delays,
    worst_decile,
)
from ..analysis.cells import UNIT
from ..tables import RUN_KEY
from .robustness import Robustness
from .safety import (
    SAFETY_THRESHOLD,
    failure,
    failure_rates,
    paired_differences,
    safety_verdict,
)
from .verdict import Evidence, Verdict, card_evidence, card_verdict

FAILURE_ORDER = ("pedestrian_collision", "world_collision", "timeout")  # worst first
METRIC_LABELS = {m.name: m.axis_label for m in RANKED_METRICS}
#: the outcomes table's columns as the card and its Markdown / LaTeX export name them
OUTCOME_LABELS = {"controller": "controller", "success_pct": "success %",
                  "pedestrian_collision_pct": "ped. coll. % (robot moving)",
                  "standing_contact_pct": "standing contacts %",
                  "world_collision_pct": "world coll. %", "timeout_pct": "timeout %",
                  "controller_error_pct": "ctrl error %",
                  **{m: METRIC_LABELS[m] for m in METRICS},
                  "min_clearance": "min. clearance [m]", "path_length": "path [m]",
                  "stop_time": "stop time [s]", "n_runs": "runs"}
N_WORST = 2  # populations named as "where it does worst"


@dataclass
class Card:
    """The card's tables. ``per_population``: one row per (population, controller);
    ``gaps``: per population, controller minus best baseline per metric [s], worst
    first; ``robustness``: the verdict's tables (:class:`.robustness.Robustness`);
    ``worst_run``: run key and why."""

    controller: str
    baselines: tuple[str, ...]
    outcomes: pd.DataFrame
    per_population: pd.DataFrame
    gaps: pd.DataFrame
    robustness: Robustness
    errors: pd.DataFrame
    worst_run: dict[str, Any] | None
    evidence: Evidence
    verdict: Verdict
    safety_rates: pd.DataFrame  # per (kind, scope, controller): rate with its interval
    safety_differences: pd.DataFrame  # per (kind, scope, baseline): paired difference

    def tables(self) -> dict[str, pd.DataFrame]:
        """Every table the card shows, by the name of its CSV file (``<name>.csv``)."""
        rob = self.robustness
        return {"outcomes": self.outcomes.reset_index(), "per_population": self.per_population,
                "gaps": self.gaps, "robustness": rob.headline,
                "robustness_by_baseline": rob.by_baseline,
                "robustness_null_rates": rob.null_rates,
                "robustness_calibration": rob.calibration,
                "robustness_interaction": rob.interaction, "ranks": self.evidence.ranks,
                "wins": self.evidence.wins, "crossovers": self.evidence.crossovers,
                "safety_rates": self.safety_rates,
                "safety_differences": self.safety_differences, "errors": self.errors}


def card_tables(runs: pd.DataFrame, pedestrians: pd.DataFrame, controller: str,
                baselines: tuple[str, ...], robustness: Robustness, *,
                rng: np.random.Generator, n_boot: int = 1000,
                safety_threshold: float = SAFETY_THRESHOLD, decide: str = "") -> Card:
    """Every table of the card from the main part's runs and pedestrians and the
    robustness verdict's tables (computed on every evaluation part by the caller).

    ``rng`` draws the episode bootstraps of the evidence and of the safety differences;
    ``decide``: what would decide an undecided robustness verdict.
    """
    paired = paired_delays(pedestrians)
    cells = cell_metrics(runs, paired)
    order = [controller, *baselines]
    outcomes = card_outcomes(runs, cells, order)
    errors = runs.loc[runs["outcome"] == "controller_error",
                      ["episode", "population", "controller", "error"]].reset_index(drop=True)
    ev = card_evidence(runs, pedestrians, controller, baselines, rng=rng, n_boot=n_boot)
    rates = failure_rates(runs, order)
    diffs = paired_differences(runs, controller, list(baselines), rng=rng, n_boot=n_boot)
    safety = safety_verdict(rates, controller, safety_threshold)
    return Card(controller, baselines, outcomes, per_population(cells),
                population_gaps(cells, controller, baselines), robustness, errors,
                worst_run(runs, paired, controller), ev,
                card_verdict(runs, controller, robustness, safety, decide), rates, diffs)


def card_outcomes(runs: pd.DataFrame, cells: pd.DataFrame, order: list[str]) -> pd.DataFrame:
    """Table II per controller (``controller_outcomes``), with pedestrian collisions split
    by who moved (``pedestrian_collision_pct``: the robot moving; ``standing_contact_pct``:
    a pedestrian walking into the standing robot, :func:`.safety.failure`) and the robot's
    mean path length [m] and stop time [s] beside its mean minimum clearance [m]."""
    out = controller_outcomes(runs, cells).reindex(order)
    robot = runs[runs["controller"].isin(order)]
    kind = failure(robot)
    share = (pd.crosstab(robot["controller"], kind, normalize="index") * 100.0).reindex(order)
    for k in ("pedestrian_collision", "standing_contact"):
        out[f"{k}_pct"] = share.get(k, 0.0)
    g = robot.groupby("controller")
    out["path_length"] = g["robot_path_length"].mean()
    out["stop_time"] = g["robot_stop_time"].mean()
    return out


def per_population(cells: pd.DataFrame) -> pd.DataFrame:
    """Mean over cells of robot time, mean delay and worst decile [s] and success share
    [%] per (population, controller); delay cells without a paired record are ignored."""
    g = cells.assign(success_pct=100.0 * cells["success_share"]).groupby(
        ["population", "controller"])
    return g.agg(robot_time=("robot_time", "mean"), success_pct=("success_pct", "mean"),
                 mean_delay=("mean_delay", "mean"), worst_decile=("worst_decile", "mean"),
                 n_cells=("cell", "size")).reset_index()


def population_gaps(cells: pd.DataFrame, controller: str,
                    baselines: tuple[str, ...]) -> pd.DataFrame:
    """Per population, the controller's ``success_pct`` [%] and, per metric, the mean
    over units of metric(controller) − min over baselines [s] (NaN-skipping; positive
    = worse than the best baseline). Worst first: lowest success, then largest
    mean-delay gap."""
    key = [*UNIT, "population", "controller"]
    out = {}
    for metric in METRICS:
        wide = cells.set_index(key)[metric].unstack("controller").astype(float)
        best = wide.reindex(columns=list(baselines)).min(axis=1)
        out[metric] = (wide[controller] - best).groupby(level="population").mean()
    own = cells[cells["controller"] == controller].groupby("population")["success_share"]
    gaps = pd.DataFrame({"success_pct": 100.0 * own.mean(), **out}).rename_axis("population")
    return gaps.reset_index().sort_values(["success_pct", "mean_delay"], ascending=[True, False],
                                          na_position="last", ignore_index=True)


def worst_run(runs: pd.DataFrame, paired: pd.DataFrame, controller: str) -> dict | None:
    """The controller's worst replayable run: a failure (collision before world
    collision before timeout, then the larger worst-decile delay), else the run
    with the largest worst-decile delay [s]; None when neither exists."""
    own = runs[runs["controller"] == controller]
    mine = paired[(paired["controller"] == controller) & paired["delay"].notna()]  # not blocked
    tails = (mine.groupby(list(RUN_KEY))["delay"]
             .agg(worst_decile).rename("run_worst_decile").reset_index())
    own = own.merge(tails, on=list(RUN_KEY), how="left")
    failed = own[own["outcome"].isin(FAILURE_ORDER)]
    if len(failed):
        rank = failed["outcome"].map({o: i for i, o in enumerate(FAILURE_ORDER)})
        row = failed.assign(rank=rank).sort_values(
            ["rank", "run_worst_decile"], ascending=[True, False], na_position="last").iloc[0]
        why = f"a {row['outcome'].replace('_', ' ')}"
    elif own["run_worst_decile"].notna().any():
        row = own.loc[own["run_worst_decile"].idxmax()]
        why = "the largest worst-decile delay of its runs"
    else:
        return None
    out = {k: row[k] for k in RUN_KEY}
    out.update(outcome=row["outcome"], robot_time=float(row["robot_time"]),
               run_worst_decile=float(row["run_worst_decile"]), why=why)
    return out
