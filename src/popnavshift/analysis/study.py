"""One study's analysis: the main grid's tables → every section of the report, as tables.

``analyse(runs, pedestrians)`` computes, from the main grid
(:func:`popnavshift.read.folder.main_grid`), the noise floor, no-robot checks, paired
delays, cell metrics, Table I, Kendall τ, Table II and the trade-off, Fig. 2's change
in delay, population sensitivity by width, and the paper's findings on our numbers. A
section that cannot be computed on the study given (too few populations or controllers,
no baselines, no matched pair, no split halves) is left out of ``Analysis.tables`` with
the reason in ``Analysis.missing``.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from ..populations.identity import ARMS, MATCHED_PAIR, PopulationSpec
from ..read.folder import is_half, split_halves
from ..tables import NO_ROBOT
from .delay import cell_metrics, paired_delays
from .findings import WIDTH_SCENES, Finding, available_findings
from .paper_reference import REVERSAL_RATE
from .ranked import names
from .reversals import comparisons, population_pairs, ranking_tau
from .summary import (
    controller_outcomes,
    delay_change,
    no_robot_checks,
    noise_floor,
    paired_share,
    population_sensitivity,
    reversal_table,
    sensitivity_by_width,
)

#: the metrics of the change in delay (paper Fig. 2): the paper's burden metrics
CHANGE_METRICS: tuple[str, ...] = names("burden", paper=True)

@dataclass
class Analysis:
    """Everything the report shows, computed from one study's tables.

    ``populations``: those analysed (split halves aside); ``tables``: name → table, each
    declared in :data:`popnavshift.result_tables.RESULT_TABLES` (written as
    ``tables/<name>.csv``); ``missing``: declared table name → why it could not be
    computed; ``delays_missing``: why no pedestrian delay could be paired (every delay
    table); ``profiles_missing``: why the motion profiles could not be drawn;
    ``findings``: the paper's qualitative claims checked on our numbers; ``cells``,
    ``comps`` and ``paired`` are kept for choosing the illustrative replays.
    """

    selection: str
    populations: list[str] = field(default_factory=list)
    tables: dict[str, pd.DataFrame] = field(default_factory=dict)
    missing: dict[str, str] = field(default_factory=dict)
    delays_missing: str = ""
    profiles_missing: str = ""
    findings: list[Finding] = field(default_factory=list)
    cells: pd.DataFrame | None = None
    comps: pd.DataFrame | None = None
    paired: pd.DataFrame | None = None


def _sanity(a: Analysis, peds: pd.DataFrame) -> None:
    base = peds[peds["controller"] == NO_ROBOT]
    if base.empty:
        a.missing["no_robot_checks"] = "the study ran no no-robot baselines"
    else:
        a.tables["no_robot_checks"] = no_robot_checks(base)


def _rankings(a: Analysis, cells: pd.DataFrame, rng_seed: int, n_boot: int) -> None:
    pops = sorted(cells["population"].unique())
    ctrl = sorted(cells["controller"].unique())
    if len(pops) < 2 or len(ctrl) < 2:
        why = (f"rankings need at least 2 populations and 2 controllers; this study has "
               f"{len(pops)} population(s) and {len(ctrl)} controller(s)")
        for s in ("reversals", "kendall_tau"):
            a.missing[s] = why
        return
    t1 = reversal_table(cells, rng=np.random.default_rng(rng_seed), n_boot=n_boot)
    a.tables["reversals"] = t1.assign(paper_rate=[
        REVERSAL_RATE.get(c, {}).get(s, {}).get(m, np.nan)
        for c, s, m in t1[["comparison", "cells", "metric"]].itertuples(index=False)])
    a.comps = comparisons(cells, population_pairs(pops))
    tau = ranking_tau(a.comps).groupby(["metric", "pop_a", "pop_b"])
    a.tables["kendall_tau"] = tau.agg(tau=("tau", "mean"), n_cells=("tau", "count")).reset_index()


def _outcomes(a: Analysis, runs: pd.DataFrame, cells: pd.DataFrame) -> None:
    out = controller_outcomes(runs, cells)
    a.tables["controller_outcomes"] = out.reset_index()
    per_pop = [controller_outcomes(runs[runs["population"] == p], cells[cells["population"] == p])
               .reset_index().assign(population=p) for p in sorted(cells["population"].unique())]
    a.tables["tradeoff"] = pd.concat(per_pop, ignore_index=True)


def _delay_change(a: Analysis, cells: pd.DataFrame) -> None:
    pops = set(cells["population"])
    if not (set(MATCHED_PAIR) <= pops
            or ("homogeneous" in pops and pops - {"homogeneous", *MATCHED_PAIR})):
        a.missing["delay_change"] = ("the change in delay needs the matched pair, or the "
                                     "homogeneous reference and a population outside the "
                                     "matched pair")
        return
    frames = [delay_change(cells, metric=m).assign(metric=m) for m in CHANGE_METRICS]
    change = pd.concat(frames, ignore_index=True)
    if change.empty:
        a.missing["delay_change"] = "no cell has a paired delay under both populations of a row"
        return
    a.tables["delay_change"] = change


def _sensitivity(a: Analysis, cells: pd.DataFrame) -> None:
    if cells["population"].nunique() < 2:
        a.missing["sensitivity_by_width"] = "population sensitivity needs at least 2 populations"
        return
    sens = population_sensitivity(cells)
    a.tables["population_sensitivity"] = sens
    frames = []
    for scenes in (WIDTH_SCENES, *((s,) for s in WIDTH_SCENES)):
        label = "+".join(scenes)
        for done in (False, True):
            for by in ((), ("controller",)):
                f = sensitivity_by_width(sens, scenes=scenes, by=by, completed_only=done)
                frames.append(f.assign(scenes=label, cells="completed" if done else "all",
                                       controller=f.get("controller", "pooled")))
    by_width = pd.concat(frames, ignore_index=True)
    if by_width.empty:
        a.missing["sensitivity_by_width"] = "no sidewalk or bottleneck cell has a sensitivity value"
        return
    a.tables["sensitivity_by_width"] = by_width[
        ["scenes", "cells", "controller", "width", "sensitivity", "n"]]


def _noise_floor(a: Analysis, runs: pd.DataFrame, peds: pd.DataFrame) -> None:
    halves = split_halves(runs["population"].unique())
    robot = runs.loc[is_half(runs["population"]) & (runs["controller"] != NO_ROBOT), "controller"]
    if not halves or robot.nunique() < 2:
        a_, b_ = (PopulationSpec.half("<population>", arm).name for arm in ARMS)
        a.missing["noise_floor"] = (f"the noise floor was not run: the study has no split-half "
                              f"populations (named {a_} and {b_}) "
                              "with runs of 2 or more controllers")
        return
    frames = [noise_floor(runs, peds, (ha, hb), completed_only=done)
              .assign(population=base, cells="completed" if done else "all")
              for base, ha, hb in halves for done in (False, True)]
    a.tables["noise_floor"] = pd.concat(frames, ignore_index=True)


def analyse(runs: pd.DataFrame, peds: pd.DataFrame, *, selection: str = "",
            rng_seed: int = 0, n_boot: int = 1000) -> Analysis:
    """Every section of the report from one analysis's runs and pedestrians tables.

    Split-half populations (``<population>_half_a`` / ``_half_b``) feed only the
    noise floor; every other section uses the other populations. ``rng_seed``
    seeds the Table I bootstrap (``numpy.random.default_rng(rng_seed)``, fresh, so
    the intervals can be recomputed); ``n_boot`` is its resample count.
    """
    a = Analysis(selection=selection)
    _noise_floor(a, runs, peds)
    runs, peds = runs[~is_half(runs["population"])], peds[~is_half(peds["population"])]
    a.populations = sorted(runs["population"].unique())
    _sanity(a, peds)
    if runs[runs["controller"] != NO_ROBOT].empty:
        why = "the study has no robot runs"
        for s in ("reversals", "kendall_tau", "controller_outcomes", "tradeoff",
                  "delay_change", "sensitivity_by_width", "findings"):
            a.missing[s] = why
        return a
    a.paired = paired_delays(peds)
    if a.paired.empty:
        a.delays_missing = "no pedestrian has a paired delay (no no-robot baseline?)"
    a.tables["paired_share"] = paired_share(peds, a.paired)
    a.cells = cell_metrics(runs, a.paired)
    a.tables["cell_metrics"] = a.cells
    _rankings(a, a.cells, rng_seed, n_boot)
    _outcomes(a, runs, a.cells)
    _delay_change(a, a.cells)
    _sensitivity(a, a.cells)
    a.findings, why = check_findings(a.tables)
    if why:
        a.missing["findings"] = why
    if a.findings:
        a.tables["findings"] = pd.DataFrame(
            [{"key": f.key, "statement": f.statement, "holds": f.holds,
              "numbers": json.dumps(f.numbers, default=str)} for f in a.findings])
    return a


def _widths(tables: dict[str, pd.DataFrame]) -> dict[str, pd.DataFrame]:
    """The pooled and per-panel width curves with at least two widths (all cells, pooled)."""
    bw = tables.get("sensitivity_by_width")
    if bw is None:
        return {}
    sel = bw[(bw["cells"] == "all") & (bw["controller"] == "pooled")]
    out = {}
    for scenes, label in (("+".join(WIDTH_SCENES), "pooled"), *((s, s) for s in WIDTH_SCENES)):
        w = sel[sel["scenes"] == scenes][["width", "sensitivity"]]
        if len(w) >= 2:
            out[label] = w.reset_index(drop=True)
    return out


def check_findings(tables: dict[str, pd.DataFrame]) -> tuple[list[Finding], str]:
    """The paper's findings (:func:`.findings.available_findings`) on our tables, and
    what could not be checked (with every input present, exactly ``paper_findings``)."""
    if "controller_outcomes" not in tables:
        return [], "no controller outcomes"
    outcomes = tables["controller_outcomes"].set_index("controller")
    t1 = tables.get("reversals", pd.DataFrame(columns=["comparison", "cells", "metric", "rate"]))
    change = tables.get("delay_change", pd.DataFrame(columns=["metric", "controller", "population",
                                                             "change"]))
    delays = bool(outcomes["mean_delay"].notna().all())
    pairs = "reversals" in tables and delays
    matched = pairs and bool((t1["comparison"] == "matched").any())
    found, left = available_findings(t1, outcomes, _widths(tables),
                                     change[change["metric"] == "mean_delay"],
                                     pairs=pairs, matched=matched, delays=delays)
    return found, ("not checked on this study: " + "; ".join(left)) if left else ""
