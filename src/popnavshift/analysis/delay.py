"""Paired pedestrian delays and per-cell metrics (paper §IV-B, SPEC §7).

Pipeline: ``paired_delays(pedestrians)`` → ``cell_metrics(runs, paired)``.

A run is identified by (episode, population, controller, backend, mapping); the
``part`` column is only the first study part that planned it (shared runs are run
once), so it is never used as a key here. Select a sub-study by filtering on
episodes, populations, backends or mappings instead.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from ..errors import InputError
from ..tables import NO_ROBOT
from .ranked import RANKED_METRICS, TAIL_SHARE, Pooled, tail_count

CELL_COLUMNS: tuple[str, ...] = ("scene", "width", "density", "robot_speed")
#: What a no-robot baseline shares with the robot runs it is paired with (besides ``slot``).
PAIR_KEY: tuple[str, ...] = ("episode", "population", "backend", "mapping")
#: One comparable unit: a physical cell under one pedestrian backend and mapping.
UNIT: tuple[str, ...] = ("backend", "mapping", "cell")
#: Key of the cell-metrics table.
CELL_KEY: tuple[str, ...] = (*UNIT, "population", "controller")


def cell_key(scene: str, width: float, density: float, robot_speed: float) -> str:
    """``"sidewalk-w1.8-d0.12-s0.6"``, the format of :class:`popnavshift.episodes.Cell`.

    Floats are converted to Python floats first: ``repr(np.float64(1.8))`` is
    ``"np.float64(1.8)"`` under numpy 2.
    """
    return f"{scene}-w{float(width)!r}-d{float(density)!r}-s{float(robot_speed)!r}"


def episode_cells(runs: pd.DataFrame) -> pd.DataFrame:
    """One row per episode: ``episode, cell, scene, width, density, robot_speed, variant``.

    Raises :class:`InputError` when an episode appears with two different cells.
    """
    cols = ["episode", *CELL_COLUMNS, "variant"]
    eps = runs[cols].drop_duplicates().reset_index(drop=True)
    dup = eps["episode"].duplicated()
    if dup.any():
        bad = eps.loc[dup, "episode"].iloc[0]
        raise InputError(f"runs table: episode {bad!r} has rows with different cell columns")
    rows = list(eps[list(CELL_COLUMNS)].itertuples(index=False, name=None))
    eps.insert(1, "cell", [cell_key(*r) for r in rows])
    return eps


def paired_delays(pedestrians: pd.DataFrame) -> pd.DataFrame:
    """Added travel time and distance of each pedestrian of each robot run.

    Args:
      pedestrians: one row per pedestrian per run, with ``episode, population,
        controller, backend, mapping, slot, persona_id, arrived, travel_time``
        [s] and ``walk_distance`` [m]; ``controller == "none"`` rows are the
        no-robot baselines.

    Returns:
      One row per (robot run, slot) whose pedestrian arrived in *both* the robot
      run and its baseline (same episode, population, backend, mapping, slot):
      ``episode, population, controller, backend, mapping, slot, persona_id,
      delay`` [s] = T(robot) − T(no robot) and ``added_distance`` [m] likewise.
      Pedestrians without a baseline row or that did not arrive in either run are
      left out, so the table has no NaN.

    Raises :class:`InputError` on duplicate pedestrian rows or when a pair's
    persona ids differ (the slot assignment would be broken).
    """
    key = [*PAIR_KEY, "slot"]
    cols = [*key, "controller", "persona_id", "arrived", "travel_time", "walk_distance"]
    peds = pedestrians[cols]
    if peds.duplicated([*key, "controller"]).any():
        raise InputError("pedestrians table: duplicate (run, slot) rows")
    arrived = peds["arrived"].astype(bool)
    base = peds[(peds["controller"] == NO_ROBOT) & arrived].drop(columns=["controller", "arrived"])
    robot = peds[(peds["controller"] != NO_ROBOT) & arrived].drop(columns="arrived")
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
    both["delay"] = both["travel_time"] - both["travel_time_base"]
    both["added_distance"] = both["walk_distance"] - both["walk_distance_base"]
    out = ["episode", "population", "controller", "backend", "mapping", "slot", "persona_id"]
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


def _pooled(robot: pd.DataFrame, paired: pd.DataFrame, eps: pd.DataFrame) -> Pooled:
    """The robot runs and paired delays grouped by CELL_KEY, records largest first."""
    p = paired.merge(eps[["episode", "cell"]], on="episode", how="inner")
    p = p.sort_values("delay", ascending=False, kind="stable")
    g = p.groupby(list(CELL_KEY), sort=False)
    return Pooled(robot.groupby(list(CELL_KEY)), p, g.cumcount().to_numpy(),
                  g["delay"].transform("size").to_numpy(), list(CELL_KEY))


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
      ``n_paired``; the burden metrics over the pooled paired delays (``mean_delay``,
      ``worst_decile``, ``cvar90`` [s]); ``mean_added_distance`` [m]. The delay columns
      are NaN and ``n_paired`` is 0 when the cell has no paired record.
    """
    eps = episode_cells(runs)
    robot = runs[runs["controller"] != NO_ROBOT].merge(eps[["episode", "cell"]], on="episode")
    if robot.duplicated([*CELL_KEY, "episode"]).any():
        raise InputError("runs table: duplicate run (episode, population, controller, backend, "
                         "mapping)")
    robot = robot.assign(success=robot["outcome"] == "success")
    pooled = _pooled(robot, paired, eps)
    g = pooled.runs
    out = g.agg(n_runs=("episode", "size"), success_share=("success", "mean"))
    out["completed"] = g["success"].all()
    records = pooled.records.groupby(pooled.key, sort=False)
    out = out.join(records.agg(n_paired=("delay", "size"),
                               mean_added_distance=("added_distance", "mean")), how="left")
    out["n_paired"] = out["n_paired"].fillna(0).astype(np.int64)
    for metric in RANKED_METRICS:
        out[metric.name] = metric.point(pooled)
    cells = eps.drop(columns=["episode", "variant"]).drop_duplicates("cell")
    out = out.reset_index().merge(cells, on="cell", how="left")
    ranked = {a: [m.name for m in RANKED_METRICS if m.aspect == a] for a in ("robot", "burden")}
    cols = [*CELL_KEY, *CELL_COLUMNS, "n_runs", *ranked["robot"], "success_share", "completed",
            "n_paired", *ranked["burden"], "mean_added_distance"]
    return out[cols].sort_values(list(CELL_KEY), ignore_index=True)
