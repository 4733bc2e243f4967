"""Several controllers side by side: their cards' verdicts and one table on the same runs.

Pipeline: ``compare(controllers, study, base_folder)`` evaluates each controller
(:func:`.run.evaluate`: cached, so a controller already evaluated simulates nothing) and
writes its card unless a current one is there: same identity (controller, baselines,
study configuration, bootstrap resamples and seed, safety threshold, runs, code) and
every file as written (:mod:`.card_files`); so cards made under other rules are never set
side by side, they are made again. Then ``compare_table`` (pure) puts every controller in one
table, on the union of their runs — the same episodes and populations for all:

* the card's two verdicts: robustness, with the rate that carries it (its excess over the
  null and interval), and safety, with its findings;
* outcome shares [%] with exact (Clopper–Pearson) 95 % intervals;
* robot time, mean delay, worst decile and CVaR-90 [s], each the mean over (cell,
  population) rows of the cell statistic (as on the card);
* per metric, the controller's rank among the compared (1 = lowest), and its best and
  worst rank over the populations (how much its standing moves with the population).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from ..analysis import cell_metrics, paired_delays
from ..analysis.ranked import RANKED_NAMES
from ..analysis.summary import OUTCOMES
from ..analysis.verdicts import clopper_pearson
from ..controller_ids import named_controller
from ..design.study import Study
from ..errors import InputError
from ..read.access import card_intact
from ..sim.controllers import CONTROLLERS
from ..tables import NO_ROBOT, RUN_KEY
from .card_files import check_card_settings, current_card
from .run import BASELINES, evaluate, make_card
from .safety import SAFETY_THRESHOLD, failure

COMPARE_METRICS: tuple[str, ...] = RANKED_NAMES  # every ranked metric, as the card
LEVEL = 0.95
Log = Callable[[str], None]


@dataclass
class Comparison:
    """The compared controllers (in the order given), their table (:func:`compare_table`),
    the per-population means behind the figure, each controller's card page, the
    ``verdict`` object of its ``card.json`` and the settings every card was made under."""

    controllers: tuple[str, ...]
    table: pd.DataFrame
    per_population: pd.DataFrame
    cards: dict[str, Path]
    verdicts: dict[str, dict[str, Any]]
    study: Study
    base_folder: Path
    #: the rules every card was made under (one set for all: n_boot, seed,
    #: safety_threshold, baselines)
    settings: dict[str, Any] = field(default_factory=dict)
    #: when the comparison was made (ISO 8601, UTC, seconds)
    made: str = ""
    #: what it is: "compare" (controllers named) or "leaderboard" (every controller)
    kind: str = "compare"


#: the outcome shares compared: a run's outcome, a pedestrian collision split by who moved
#: (:func:`.safety.failure`: ``standing_contact`` is a pedestrian walking into the standing
#: robot, ``pedestrian_collision`` the robot moving)
SHARES: tuple[str, ...] = (*OUTCOMES[:2], "standing_contact", *OUTCOMES[2:])
#: the robot's run metrics compared, mean over its runs [m, m, s]
RUN_MEANS = {"min_clearance": "robot_min_clearance", "path_length": "robot_path_length",
             "stop_time": "robot_stop_time"}


def outcome_shares(runs: pd.DataFrame, controllers: Sequence[str]) -> pd.DataFrame:
    """Per controller (index): ``runs``, per outcome of :data:`SHARES` ``<outcome>_pct`` [%]
    with its Clopper–Pearson ``<outcome>_low`` / ``<outcome>_high`` [%] over the
    controller's runs, and the means of :data:`RUN_MEANS`."""
    rows = []
    kinds = failure(runs)
    for ctrl in controllers:
        mine = runs["controller"] == ctrl
        outcome = kinds[mine]
        row: dict[str, Any] = {"controller": ctrl, "runs": len(outcome)}
        row.update({k: float(runs.loc[mine, c].mean()) for k, c in RUN_MEANS.items()})
        for o in SHARES:
            k = int((outcome == o).sum())
            low, high = clopper_pearson(k, len(outcome), LEVEL)
            row.update({f"{o}_pct": 100 * k / len(outcome) if len(outcome) else np.nan,
                        f"{o}_low": 100 * low, f"{o}_high": 100 * high})
        rows.append(row)
    return pd.DataFrame(rows).set_index("controller")


def population_means(cells: pd.DataFrame, controllers: Sequence[str]) -> pd.DataFrame:
    """Per (population, controller): the mean over cells of each compared metric [s]."""
    c = cells[cells["controller"].isin(controllers)]
    return c.groupby(["population", "controller"])[list(COMPARE_METRICS)].mean().reset_index()


def ranks(cells: pd.DataFrame, per_population: pd.DataFrame,
          controllers: Sequence[str]) -> pd.DataFrame:
    """Per controller (index) and metric: ``rank_<m>`` of its mean over every (cell,
    population) row among ``controllers`` (1 = lowest, ties share the best rank), and
    ``rank_<m>_best`` / ``rank_<m>_worst``, its best and worst rank over populations."""
    c = cells[cells["controller"].isin(controllers)]
    overall = c.groupby("controller")[list(COMPARE_METRICS)].mean()
    out = pd.DataFrame(index=pd.Index(list(controllers), name="controller"))
    for m in COMPARE_METRICS:
        out[f"rank_{m}"] = overall[m].rank(method="min").reindex(out.index).astype("Int64")
        by_pop = per_population.groupby("population")[m].rank(method="min")
        r = by_pop.groupby(per_population["controller"])
        out[f"rank_{m}_best"] = r.min().reindex(out.index).astype("Int64")
        out[f"rank_{m}_worst"] = r.max().reindex(out.index).astype("Int64")
    return out


def compare_table(runs: pd.DataFrame, pedestrians: pd.DataFrame, controllers: Sequence[str],
                  verdicts: dict[str, dict[str, Any]]) -> tuple[pd.DataFrame, pd.DataFrame]:
    """The comparison (module doc): one row per controller, in the order given, and the
    per-population means [s] it ranks (for the figure). ``verdicts``: controller → the
    ``verdict`` object of its ``card.json`` (``label``, ``safety``)."""
    cells = cell_metrics(runs, paired_delays(pedestrians))
    per_pop = population_means(cells, controllers)
    means = cells[cells["controller"].isin(controllers)].groupby("controller")[
        list(COMPARE_METRICS)].mean()
    head = verdict_columns(verdicts, controllers)
    table = pd.concat([head, outcome_shares(runs, controllers), means.reindex(head.index),
                       ranks(cells, per_pop, controllers)], axis=1)
    return table.reset_index(), per_pop


def verdict_columns(verdicts: dict[str, dict[str, Any]],
                    controllers: Sequence[str]) -> pd.DataFrame:
    """Per controller (index): its robustness verdict with the rate that carries it (design,
    metric, excess over the null and its simultaneous interval, in percentage points) and
    its safety verdict with the number of unsafe findings and the findings themselves."""
    rows = []
    for c in controllers:
        rob, safe = verdicts[c]["robustness"], verdicts[c]["safety"]
        row = rob.get("row") or {}
        rows.append({"controller": c, "robustness": rob["label"],
                     "robustness_design": row.get("design", ""),
                     "robustness_metric": row.get("metric", ""),
                     "excess_pp": 100 * row["excess"] if row else np.nan,
                     "excess_low_pp": 100 * row["ci_low"] if row else np.nan,
                     "excess_high_pp": 100 * row["ci_high"] if row else np.nan,
                     # the second question: rows whose differences from the baselines
                     # change beyond the null, of the rows tested
                     "differences_change": _of(rob.get("interaction_rows")),
                     "safety": safe["label"], "safety_findings": len(safe["findings"]),
                     "safety_text": " / ".join(safe["findings"])})
    return pd.DataFrame(rows).set_index("controller")


def _of(counts: Any) -> str:
    """``2 of 10``: a card's interaction rows that change, of those tested ("" if none)."""
    if not counts or not counts[1]:
        return ""
    return f"{int(counts[0])} of {int(counts[1])}"


# ------------------------------------------------------------------ files and runs
def compare(controllers: Sequence[str], study: Study, base_folder: Path, *, workers: int = 2,
            n_boot: int = 1000, seed: int = 0, safety_threshold: float | None = None,
            baselines: Sequence[str] = BASELINES, show_progress: bool = True,
            log: Log | None = None, kind: str = "compare") -> Comparison:
    """Evaluate (cached) every controller and make its card unless the one in
    ``STUDY/evaluate`` is current under these settings (:func:`.card_files.card_is_current`:
    same identity, every file intact; else it is made again and ``log`` says why), then
    compare them all on the union of their runs (module doc)."""
    say = log or (lambda _msg: None)
    ids = tuple(dict.fromkeys(named_controller(c) for c in controllers))
    threshold = SAFETY_THRESHOLD if safety_threshold is None else safety_threshold
    check_card_settings(n_boot, seed, threshold)
    for c in (*ids, *baselines):  # every name must resolve before anything runs
        CONTROLLERS.make(c)
    evaluations, verdicts, cards = [], {}, {}
    for c in ids:
        ev = evaluate(c, study, base_folder, baselines=baselines, workers=workers,
                      show_progress=show_progress, log=say)
        out, why = current_card(c, study, base_folder, ev.out, baselines=baselines,
                                n_boot=n_boot, seed=seed, safety_threshold=threshold)
        if why:
            make_card(ev, n_boot=n_boot, seed=seed, safety_threshold=threshold)
            made_again = "" if why == "no card yet" else f" (made again: {why})"
            say(f"{c}: card → {out / 'card.html'}{made_again}")
        else:
            say(f"{c}: card reused ({out / 'card.html'})")
        doc, why = card_intact(out)
        if why:  # written a moment ago: only a concurrent writer gets here
            raise InputError(f"card {out}: {why}", hint="make it again")
        verdicts[c] = doc["verdict"]
        cards[c] = out / "card.html"
        evaluations.append(ev)
    runs = pd.concat([e.runs for e in evaluations]).drop_duplicates(list(RUN_KEY))
    peds = pd.concat([e.pedestrians for e in evaluations]).drop_duplicates([*RUN_KEY, "slot"])
    runs = runs[runs["controller"].isin([*ids, NO_ROBOT])]
    peds = peds[peds["controller"].isin([*ids, NO_ROBOT])]
    table, per_pop = compare_table(runs, peds, ids, verdicts)
    settings = {"n_boot": n_boot, "seed": seed, "safety_threshold": threshold,
                "baselines": list(baselines)}
    return Comparison(ids, table, per_pop, cards, verdicts, study, Path(base_folder), settings,
                      datetime.now(UTC).isoformat(timespec="seconds"), kind)
