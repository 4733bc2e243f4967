"""Paired pedestrian delays and per-cell metrics (paper §IV-B, SPEC §7).

Pipeline: ``paired_delays(pedestrians)`` → ``cell_metrics(runs, paired)``.

A run is identified by (episode, population, controller, backend, mapping); the
``part`` column is only the first study part that planned it (shared runs are run
once), so it is never used as a key here. Select a sub-study by filtering on
episodes, populations, backends or mappings instead.

The delays follow SPEC §7: a pedestrian's added delay exists only when it arrived in
both runs. One that arrived without the robot but not with it is *blocked*: it keeps a
row of the paired table (``blocked``, delay NaN) and enters the burden as the cell's
``blocked_pct``, a ranked metric beside the delays (docs/analysis.md §2; the choice and
the censored alternative: docs/method.md §8).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from ..errors import InputError
from ..tables import NO_ROBOT, RUN_KEY
from .cells import CELL_COLUMNS, CELL_KEY, episode_cells
from .ranked import RANKED_METRICS, TAIL_SHARE, share_resampled, tail_count
from .resample import build_design

#: What a no-robot baseline shares with the robot runs it is paired with (besides ``slot``).
PAIR_KEY: tuple[str, ...] = ("episode", "population", "backend", "mapping")


def paired_delays(pedestrians: pd.DataFrame) -> pd.DataFrame:
    """Added travel time and distance of each pedestrian of each robot run.

    Args:
      pedestrians: one row per pedestrian per run, with ``episode, population,
        controller, backend, mapping, slot, persona_id, arrived, travel_time``
        [s] and ``walk_distance`` [m]; ``controller == "none"`` rows are the
        no-robot baselines.

    Returns:
      One row per (robot run, slot) whose pedestrian arrived in its baseline (same
      episode, population, backend, mapping, slot): ``episode, population, controller,
      backend, mapping, slot, persona_id``; ``blocked`` (it did not arrive with the
      robot); ``delay`` [s] = T(robot) − T(no robot) and ``added_distance`` [m] likewise
      from ``walk_distance``, both defined only when it arrived in both runs (SPEC §7)
      and NaN when blocked. The rows with ``blocked`` False are the paired delays. A
      pedestrian that did not arrive without the robot has no row, under every
      controller alike.

    Raises :class:`InputError` on duplicate pedestrian rows or when a pair's
    persona ids differ (the slot assignment would be broken).
    """
    key = [*PAIR_KEY, "slot"]
    cols = [*key, "controller", "persona_id", "arrived", "travel_time", "walk_distance"]
    peds = pedestrians[cols]
    if peds.duplicated([*key, "controller"]).any():
        raise InputError("pedestrians table: duplicate (run, slot) rows")
    arrived = peds["arrived"].astype(bool)
    is_base = peds["controller"] == NO_ROBOT
    base = peds[is_base & arrived].drop(columns=["controller", "arrived"])
    robot = peds[~is_base].assign(blocked=~arrived[~is_base]).drop(columns="arrived")
    both = robot.merge(base, on=key, how="inner", suffixes=("", "_base"))
    wrong = both["persona_id"] != both["persona_id_base"]
    if wrong.any():
        row = both[wrong].iloc[0]
        raise InputError(
            f"pedestrians table: slot {row['slot']} of episode {row['episode']!r} "
            f"({row['population']}) holds persona {row['persona_id']!r} with controller "
            f"{row['controller']!r} but {row['persona_id_base']!r} without robot",
            hint="robot and no-robot runs must share the slot assignment",
        )
    ok = ~both["blocked"]
    both["delay"] = (both["travel_time"] - both["travel_time_base"]).where(ok)
    both["added_distance"] = (both["walk_distance"] - both["walk_distance_base"]).where(ok)
    out = ["episode", "population", "controller", "backend", "mapping", "slot", "persona_id",
           "blocked"]
    return both[[*out, "delay", "added_distance"]].reset_index(drop=True)


def worst_decile(delays: np.ndarray) -> float:
    """Mean of the largest ⌈0.1 n⌉ of ``delays`` (shape (n,), [s]); NaN when n = 0."""
    x = np.sort(np.asarray(delays, dtype=float))[::-1]
    if x.size == 0:
        return float("nan")
    return float(x[: tail_count(x.size)].mean())


def cvar(delays: np.ndarray, share: float = TAIL_SHARE) -> float:
    """CVaR at level 1 − ``share``: the mean of the largest ``share`` of ``delays`` [s].

    With n records the tail holds t = share · n of them (at least 1): the largest ⌊t⌋
    count fully and the next one with weight t − ⌊t⌋, so the statistic moves
    smoothly with n (the worst decile jumps from 1 to 2 records at n = 11). NaN for
    n = 0. Computed on a cell's records pooled over every seed set analysed, it is
    the tail statistic that does not rest on 1–3 records.
    """
    x = np.sort(np.asarray(delays, dtype=float))[::-1]
    if x.size == 0:
        return float("nan")
    t = max(share * x.size, 1.0)
    w = np.clip(t - np.arange(x.size), 0.0, 1.0)
    return float((w * x).sum() / t)


def _row_sums(entries_ptr: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Σ of each row's entries of a CSR (``ptr`` (R + 1,), ``values`` (n,)): (R,) float."""
    rows = np.repeat(np.arange(entries_ptr.size - 1), np.diff(entries_ptr))
    return np.bincount(rows, weights=values, minlength=entries_ptr.size - 1)


def cell_metrics(runs: pd.DataFrame, paired: pd.DataFrame) -> pd.DataFrame:
    """Per (backend, mapping, cell, population, controller), pooling the cell's variants.

    Args:
      runs: the runs table (no-robot rows are ignored).
      paired: the output of :func:`paired_delays`.

    Returns:
      One row per robot controller with columns ``backend, mapping, cell,
      population, controller, scene, width, density, robot_speed``;
      ``n_runs`` (variants run); the robot's ranked metrics
      (:data:`popnavshift.analysis.ranked.RANKED_METRICS`, e.g. ``robot_time`` [s], the
      mean over variants of the run's robot time, 45 s for failed runs);
      ``success_share`` in [0, 1]; ``completed`` (every variant run succeeded);
      ``n_paired`` (paired delays: pedestrians that arrived in both runs) and
      ``n_blocked`` (arrived without the robot, not with it); the delay metrics over the
      pooled paired delays (``mean_delay``, ``worst_decile``, ``cvar90`` [s]; NaN when
      ``n_paired`` is 0) and ``blocked_pct`` [%] = 100 · n_blocked / (n_paired +
      n_blocked) (NaN when both are 0); ``mean_added_distance`` [m] over the paired
      records.

    Every ranked metric and ``success_share`` is its bootstrap function
    (:mod:`popnavshift.analysis.resample`) with unit weights: the point is a resample.
    """
    if runs[runs["controller"] != NO_ROBOT].duplicated(list(RUN_KEY)).any():
        raise InputError("runs table: duplicate run (episode, population, controller, backend, "
                         "mapping)")
    design = build_design(runs, paired)
    key = list(CELL_KEY)
    ones = np.ones((1, design.n_columns), dtype=np.int32)  # the bootstrap weights' dtype
    out = design.rows.copy()
    out["n_runs"] = np.diff(design.times.ptr)
    for metric in RANKED_METRICS:
        out[metric.name] = metric.compute(design, ones)[0]
    out["success_share"] = share_resampled(design.outcomes["success_share"], ones)[0]
    success = design.outcomes["success_share"]
    out["completed"] = _row_sums(success.ptr, success.val) == out["n_runs"]
    out["n_paired"] = _row_sums(design.delays.ptr, design.delays.aux).astype(np.int64)
    out["n_blocked"] = _row_sums(design.blocked.ptr, design.blocked.val).astype(np.int64)
    eps = episode_cells(runs)
    dist = (paired.merge(eps[["episode", "cell"]], on="episode")
            .groupby(key)["added_distance"].mean().rename("mean_added_distance"))
    out = out.join(dist, on=key)
    cells = eps.drop(columns=["episode", "variant"]).drop_duplicates("cell")
    out = out.merge(cells, on="cell", how="left")
    ranked = {a: [m.name for m in RANKED_METRICS if m.aspect == a] for a in ("robot", "burden")}
    cols = [*CELL_KEY, *CELL_COLUMNS, "n_runs", *ranked["robot"], "success_share", "completed",
            "n_paired", "n_blocked", *ranked["burden"], "mean_added_distance"]
    return out[cols].sort_values(key, ignore_index=True)
