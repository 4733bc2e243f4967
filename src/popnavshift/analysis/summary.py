"""Study-level summaries set beside the paper (§V) and the paper's own figures.

Table I (``reversal_table``), Table II (``controller_outcomes``), Fig. 2
(``delay_change``), Fig. 4 (``population_sensitivity`` → ``sensitivity_by_width``),
and beyond the paper a noise floor and no-robot sanity checks. The paper's
qualitative findings are checked in :mod:`popnavshift.analysis.findings`, its own
figures are in :mod:`popnavshift.analysis.paper_reference`. Kendall τ lives with the
comparisons it is computed from (:mod:`popnavshift.analysis.reversals`).
Pass the tables of one analysis (e.g. the main grid: ORCA backend, Mapping A,
104 cells); rates and means pool every backend and mapping present.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pandas as pd

from ..paper import PAPER_CONTROLLERS
from ..populations.identity import MATCHED_PAIR
from ..tables import NO_ROBOT
from .bootstrap import LEVEL, N_BOOT, rate_intervals
from .cells import UNIT
from .delay import cell_metrics, paired_delays
from .ranked import TOLERANCES
from .reversals import (
    METRICS,
    comparisons,
    completed_units,
    population_pairs,
    reversal_rates,
)

OUTCOMES: tuple[str, ...] = ("success", "pedestrian_collision", "world_collision", "timeout",
                            "controller_error")
MAX_STUCK_SHARE = 0.05  # no-robot runs: more pedestrians than this never arriving is a flag


def controller_order(names: Sequence[str]) -> list[str]:
    """The paper's controllers in its order, then any other, sorted."""
    given = set(names)
    return [c for c in PAPER_CONTROLLERS if c in given] + sorted(given - set(PAPER_CONTROLLERS))


# --- Table I -------------------------------------------------------------------------------


def reversal_table(
    cells: pd.DataFrame,
    *,
    rng: np.random.Generator,
    n_boot: int = N_BOOT,
    level: float = LEVEL,
    matched: tuple[str, str] = MATCHED_PAIR,
    tolerances: dict[str, float] = TOLERANCES,
) -> pd.DataFrame:
    """Reversal rates with cluster-bootstrap intervals, as Table I and §V-A.

    Rows: ``comparison`` ∈ {matched, all_pairs} × ``cells`` ∈ {all, completed}
    × ``metric``; columns ``reversals, comparisons, rate, ci_low, ci_high``
    (rates in [0, 1]). ``all_pairs`` pools every pair of the populations in
    ``cells`` (8 → 28 pairs); the matched rows are left out when ``cells`` lacks
    either matched population.
    """
    pops = sorted(cells["population"].unique())
    comps = comparisons(cells, population_pairs(pops), tolerances=tolerances)
    scopes = [("all_pairs", comps)]
    if set(matched) <= set(pops):
        is_matched = comps["pop_a"].isin(matched) & comps["pop_b"].isin(matched)
        scopes.insert(0, ("matched", comps[is_matched]))
    frames = []
    for label, sel in scopes:
        for scope, done in (("all", False), ("completed", True)):
            f = rate_intervals(sel, ("metric",), rng=rng, n_boot=n_boot, level=level,
                               completed_only=done)
            frames.append(f.assign(comparison=label, cells=scope))
    out = pd.concat(frames, ignore_index=True)
    order = ["comparison", "cells", "metric", "reversals", "comparisons", "rate", "ci_low",
             "ci_high"]
    return out[order]


# --- Table II ------------------------------------------------------------------------------


def controller_outcomes(runs: pd.DataFrame, cells: pd.DataFrame) -> pd.DataFrame:
    """Per controller, over every robot run and cell of the tables given (Table II).

    Outcome shares (``*_pct``, % of robot runs); ``robot_time`` [s], mean over
    runs with 45 s for failures; ``min_clearance`` [m], mean over runs of the
    robot's minimum pedestrian clearance (runs without one ignored);
    ``mean_delay`` and ``worst_decile`` [s] (paired delays: pedestrians that arrived in
    both runs) and ``blocked_pct`` [%] (of those that arrived without the robot, the share
    that did not arrive with it), the mean over (cell, population) rows of the cell
    statistics (rows without a paired record ignored), so each cell and population
    weighs the same, as in the reversal analysis; ``n_runs`` and ``n_cells`` (rows with a
    mean delay).
    """
    robot = runs[runs["controller"] != NO_ROBOT]
    shares = pd.crosstab(robot["controller"], robot["outcome"], normalize="index") * 100.0
    out = shares.reindex(columns=list(OUTCOMES), fill_value=0.0)
    out.columns = [f"{o}_pct" for o in OUTCOMES]
    g = robot.groupby("controller")
    out["robot_time"] = g["robot_time"].mean()
    out["min_clearance"] = g["robot_min_clearance"].mean()
    c = cells.groupby("controller")
    out["mean_delay"] = c["mean_delay"].mean()
    out["worst_decile"] = c["worst_decile"].mean()
    out["blocked_pct"] = c["blocked_pct"].mean()
    out["n_runs"] = g.size()
    out["n_cells"] = c["mean_delay"].count()
    return out.reindex(controller_order(out.index)).rename_axis("controller")


# --- Fig. 4: population sensitivity ----------------------------------------------------------


def population_sensitivity(
    cells: pd.DataFrame, metric: str = "mean_delay", populations: Sequence[str] | None = None
) -> pd.DataFrame:
    """Range (max − min) of ``metric`` across populations per unit and controller [s].

    Returns one row per (backend, mapping, cell, controller) with the cell
    columns, ``sensitivity`` (NaN unless every population in ``populations``,
    default all in ``cells``, has a value: a range over fewer populations is not
    the same statistic) and ``completed`` (every controller completed every
    variant of the cell under every one of those populations).
    """
    pops = sorted(cells["population"].unique()) if populations is None else list(populations)
    sub = cells[cells["population"].isin(pops)]
    wide = sub.set_index([*UNIT, "controller", "population"])[metric].unstack("population")
    wide = wide.reindex(columns=pops).astype(float)
    rng_ = (wide.max(axis=1) - wide.min(axis=1)).where(wide.notna().all(axis=1))
    out = rng_.rename("sensitivity").reset_index()
    done = completed_units(sub).unstack("population").reindex(columns=pops)
    done = done.eq(True).all(axis=1).rename("completed").reset_index()
    geo = cells[[*UNIT, "scene", "width", "density", "robot_speed"]].drop_duplicates(list(UNIT))
    out = out.merge(done, on=list(UNIT), how="left").merge(geo, on=list(UNIT), how="left")
    out["completed"] = out["completed"].eq(True)
    return out


def sensitivity_by_width(
    sens: pd.DataFrame,
    *,
    scenes: Sequence[str] = ("sidewalk", "bottleneck"),
    by: Sequence[str] = (),
    completed_only: bool = False,
) -> pd.DataFrame:
    """Mean population sensitivity per width [s] over the cells of ``scenes``.

    ``by`` adds grouping columns (e.g. ``("scene",)``, ``("controller",)``);
    ``by=()`` pools scenes and controllers (our reading of the paper's "pooled
    population sensitivity"). Rows with NaN sensitivity are ignored; ``n``
    counts the rows averaged.
    """
    s = sens[sens["scene"].isin(scenes) & sens["sensitivity"].notna()]
    if completed_only:
        s = s[s["completed"]]
    g = s.groupby([*by, "width"])["sensitivity"]
    return g.agg(sensitivity="mean", n="size").reset_index()


# --- Fig. 2: change in delay -----------------------------------------------------------------


def delay_change(
    cells: pd.DataFrame,
    *,
    metric: str = "mean_delay",
    reference: str = "homogeneous",
    matched: tuple[str, str] = MATCHED_PAIR,
) -> pd.DataFrame:
    """Shifted minus reference ``metric`` per controller and population [s] (Fig. 2).

    Each population other than ``reference`` and the matched pair is compared
    with ``reference``; ``matched[1]`` is compared with ``matched[0]``. The change
    is the mean over units (backend, mapping, cell) where both have a value of
    the per-unit difference. Returns long rows ``controller, population,
    reference, change, n_cells``; pivot on population × controller for a heatmap.
    """
    wide = cells.set_index([*UNIT, "controller", "population"])[metric].unstack("population")
    rows = [(p, reference) for p in sorted(wide.columns) if p not in (reference, *matched)]
    rows.insert(0, (matched[1], matched[0]))
    frames = []
    for shifted, ref in rows:
        if shifted not in wide or ref not in wide:
            continue
        d = (wide[shifted] - wide[ref]).dropna().groupby("controller")
        f = d.agg(change="mean", n_cells="size").reset_index()
        frames.append(f.assign(population=shifted, reference=ref))
    out = pd.concat(frames, ignore_index=True)
    return out[["controller", "population", "reference", "change", "n_cells"]]


# --- Noise floor and no-robot sanity checks -------------------------------------------------


def noise_floor(
    runs: pd.DataFrame,
    pedestrians: pd.DataFrame,
    halves: tuple[str, str],
    *,
    tolerances: dict[str, float] = TOLERANCES,
    completed_only: bool = False,
) -> pd.DataFrame:
    """Reversal rates between two random halves of one population, per metric.

    ``halves`` names the two half-populations in the tables (built upstream by
    splitting a population's members at random). Their rates are what sampling
    noise alone produces, a floor for reading rates between real populations.
    """
    keep = runs["population"].isin(halves)
    peds = pedestrians[pedestrians["population"].isin(halves)]
    cells = cell_metrics(runs[keep], paired_delays(peds))
    comps = comparisons(cells, [halves], tolerances=tolerances, metrics=METRICS)
    return reversal_rates(comps, ("metric",), completed_only=completed_only)


def no_robot_checks(
    pedestrians: pd.DataFrame, *, by: Sequence[str] = ("population",),
    max_stuck: float = MAX_STUCK_SHARE,
) -> pd.DataFrame:
    """Per group, pedestrians of the no-robot runs: do the populations walk sensibly?

    Columns: ``n_peds``; ``stuck_share`` (never arrived, in [0, 1]) and
    ``stuck_flag`` (> ``max_stuck``); over arrived pedestrians: ``travel_time``
    mean and 10/50/90th percentiles [s], ``walk_distance`` mean and median [m],
    ``speed`` mean of walk_distance / travel_time [m/s].
    """
    p = pedestrians[pedestrians["controller"] == NO_ROBOT]
    arrived = p["arrived"].astype(bool)
    p = p.assign(stuck=~arrived, speed=(p["walk_distance"] / p["travel_time"]).where(arrived))
    ok = p[arrived]
    g, ga = p.groupby(list(by)), ok.groupby(list(by))
    out = g.agg(n_peds=("stuck", "size"), stuck_share=("stuck", "mean"))
    out["stuck_flag"] = out["stuck_share"] > max_stuck
    tt = ga["travel_time"]
    out["travel_time_mean"] = tt.mean()
    for q in (10, 50, 90):
        out[f"travel_time_p{q}"] = tt.quantile(q / 100)
    out["walk_distance_mean"] = ga["walk_distance"].mean()
    out["walk_distance_median"] = ga["walk_distance"].median()
    out["speed_mean"] = ga["speed"].mean()
    return out.reset_index()


def paired_share(pedestrians: pd.DataFrame, paired: pd.DataFrame,
                 by: Sequence[str] = ("controller",)) -> pd.DataFrame:
    """Per group, the robot-run pedestrian records and how the burden counts them.

    Columns: ``n_records``; ``n_paired``, those with a paired delay (arrived in both runs),
    and ``share`` = n_paired / n_records in [0, 1]; ``n_blocked``, those that arrived
    without the robot but not with it, and ``blocked_share`` = n_blocked / (n_paired +
    n_blocked) in [0, 1], pooled over the group's records. ``paired`` is
    :func:`popnavshift.analysis.delay.paired_delays` (a ``blocked`` row has no delay).
    """
    robot = pedestrians[pedestrians["controller"] != NO_ROBOT]
    n = robot.groupby(list(by)).size()
    b = paired.groupby(list(by))["blocked"].sum().reindex(n.index, fill_value=0)
    k = paired[~paired["blocked"]].groupby(list(by)).size().reindex(n.index, fill_value=0)
    b, k = b.astype(np.int64), k.astype(np.int64)
    return pd.DataFrame({"n_records": n, "n_paired": k, "share": k / n, "n_blocked": b,
                         "blocked_share": b / (k + b).where(k + b > 0)}).reset_index()
