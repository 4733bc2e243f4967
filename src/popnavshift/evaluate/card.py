"""The population-robustness card's tables (pure).

Pipeline: ``card_tables(runs, pedestrians, controller, baselines, rng=...)`` →
:class:`Card` (pure, from :mod:`popnavshift.analysis`) → ``card_figure`` and
``render_html`` of :mod:`.card_page` (given the replay SVG of the worst run, drawn
elsewhere).

What the card says, for the evaluated part of a study (every population × cell):

* outcomes per controller (Table II's columns, controller errors included);
* robot time, mean and worst-decile pedestrian delay per population [s], each
  the mean over cells of the cell metric, with the gap to the best baseline;
* how often the controller's ranking against each baseline reverses between two
  populations (pooled over every cell and population pair, cluster-bootstrap CI
  over cells, tie tolerances of the paper);
* the populations where it does worst: lowest success share, then largest mean-delay
  gap to the best baseline;
* the worst run: a collision, else a timeout, else the largest worst-decile delay;
* first of all, the verdict (:mod:`.verdict`): per-population ranks with rank
  intervals, wins and losses per cell, significant reversals (paired episode
  bootstrap), and a safety banner naming each failure that makes it less safe than the
  baselines (:mod:`.safety`; an absolute threshold is an option). A controller that
  fails every run never reads as robust.
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
    comparisons,
    controller_outcomes,
    paired_delays,
    population_pairs,
    rate_intervals,
    worst_decile,
)
from ..analysis.cells import UNIT
from ..tables import RUN_KEY
from .safety import failure_rates, paired_differences, safety_findings
from .verdict import (
    Evidence,
    Verdict,
    card_evidence,
    verdict,
)

FAILURE_ORDER = ("pedestrian_collision", "world_collision", "timeout")  # worst first
METRIC_LABELS = {m.name: m.axis_label for m in RANKED_METRICS}
#: the outcomes table's columns as the card and its Markdown / LaTeX export name them
OUTCOME_LABELS = {"controller": "controller", "success_pct": "success %",
                  "pedestrian_collision_pct": "ped. coll. %",
                  "world_collision_pct": "world coll. %", "timeout_pct": "timeout %",
                  "controller_error_pct": "ctrl error %",
                  **{m: METRIC_LABELS[m] for m in METRICS}, "n_runs": "runs"}
N_WORST = 2  # populations named as "where it does worst"


@dataclass
class Card:
    """The card's tables. ``per_population``: one row per (population, controller);
    ``gaps``: per population, controller minus best baseline per metric [s], worst
    first; ``reversals``: per (baseline, metric); ``worst_run``: run key and why."""

    controller: str
    baselines: tuple[str, ...]
    outcomes: pd.DataFrame
    per_population: pd.DataFrame
    gaps: pd.DataFrame
    reversals: pd.DataFrame
    errors: pd.DataFrame
    worst_run: dict[str, Any] | None
    evidence: Evidence
    verdict: Verdict
    safety_rates: pd.DataFrame  # per (kind, scope, controller): rate with its interval
    safety_differences: pd.DataFrame  # per (kind, scope, baseline): paired difference

    def tables(self) -> dict[str, pd.DataFrame]:
        """Every table the card shows, by the name of its CSV file (``<name>.csv``)."""
        return {"outcomes": self.outcomes.reset_index(), "per_population": self.per_population,
                "gaps": self.gaps, "reversals": self.reversals,
                "significant_reversals": self.evidence.reversals, "ranks": self.evidence.ranks,
                "wins": self.evidence.wins, "safety_rates": self.safety_rates,
                "safety_differences": self.safety_differences, "errors": self.errors}


def card_tables(runs: pd.DataFrame, pedestrians: pd.DataFrame, controller: str,
                baselines: tuple[str, ...], *, rng: np.random.Generator,
                n_boot: int = 1000, seed_sets: int = 1,
                safety_threshold: float | None = None) -> Card:
    """Every table of the card from the evaluated part's runs and pedestrians.

    ``rng`` draws the cell bootstrap of the raw rates, then the episode bootstrap of
    the verdict; ``seed_sets`` is the number of episode seed sets in ``runs`` (for
    the advice of an inconclusive verdict).
    """
    paired = paired_delays(pedestrians)
    cells = cell_metrics(runs, paired)
    order = [controller, *baselines]
    outcomes = controller_outcomes(runs, cells).reindex(order)
    errors = runs.loc[runs["outcome"] == "controller_error",
                      ["episode", "population", "controller", "error"]].reset_index(drop=True)
    reversals = reversals_against(cells, controller, baselines, rng=rng, n_boot=n_boot)
    ev = card_evidence(runs, pedestrians, controller, baselines, rng=rng, n_boot=n_boot,
                       seed_sets=seed_sets)
    rates = failure_rates(runs, order)
    diffs = paired_differences(runs, controller, list(baselines), rng=rng, n_boot=n_boot)
    unsafe = safety_findings(rates, diffs, controller, list(baselines), safety_threshold)
    return Card(controller, baselines, outcomes, per_population(cells),
                population_gaps(cells, controller, baselines), reversals, errors,
                worst_run(runs, paired, controller), ev,
                verdict(runs, controller, ev, seed_sets=seed_sets, safety=unsafe), rates, diffs)


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


def reversals_against(cells: pd.DataFrame, controller: str, baselines: tuple[str, ...], *,
                      rng: np.random.Generator, n_boot: int = 1000) -> pd.DataFrame:
    """Reversal rate of (controller vs each baseline) over every population pair, per
    metric, with a cluster-bootstrap interval over cells. Columns ``baseline, metric,
    reversals, comparisons, rate, ci_low, ci_high`` (rates in [0, 1])."""
    pairs = population_pairs(sorted(cells["population"].unique()))
    frames = []
    for b in baselines:
        comps = comparisons(cells, pairs, controllers=[controller, b])
        frames.append(rate_intervals(comps, ("metric",), rng=rng, n_boot=n_boot)
                      .assign(baseline=b))
    out = pd.concat(frames, ignore_index=True)
    out["metric"] = pd.Categorical(out["metric"], METRICS, ordered=True)
    out = out.sort_values(["baseline", "metric"], key=_baseline_order(baselines))
    return out[["baseline", "metric", "reversals", "comparisons", "rate", "ci_low",
                "ci_high"]].astype({"metric": str}).reset_index(drop=True)


def _baseline_order(baselines: tuple[str, ...]):
    rank = {b: i for i, b in enumerate(baselines)}
    return lambda s: s.map(rank) if s.name == "baseline" else s


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
