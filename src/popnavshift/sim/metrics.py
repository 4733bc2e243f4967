"""Every metric of a run, computed from its :class:`.trace.Trace`.

A metric is a column of the ``runs`` table (:func:`robot_metrics`) or of the
``pedestrians`` table (:func:`pedestrian_metrics`); its name, unit and meaning
are declared once in :mod:`popnavshift.tables` (``ROBOT_METRICS``,
``PEDESTRIAN_METRICS``). Adding a metric: declare its column there and compute it
here (a test checks that the two agree). Trace-wide quantities are computed in
one numba pass (:func:`_metrics`), once per trace.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..tables import ROBOT_METRICS
from .constants import DT, PED_RADIUS, ROBOT_RADIUS, TIME_LIMIT, V_STOP
from .trace import Trace


def _step_lengths(xy: np.ndarray) -> np.ndarray:
    """Distance [m] moved during each step: (T + 1, ...) positions → (T, ...)."""
    return np.linalg.norm(np.diff(xy, axis=0), axis=-1)


def pedestrian_travel_time(tr: Trace) -> np.ndarray:
    """(n,) [s] from t = 0 to the (interpolated) exit crossing; NaN if never arrived."""
    arrived = tr.arrival_step >= 0
    return np.where(arrived, (tr.arrival_step - 1 + tr.arrival_frac) * DT, np.nan)


@njit(cache=True)
def _metrics(pos, n, steps, arrival_step, arrival_frac, has_robot, robot_last, outcome_step,
             v_stop_step, walked, stop_steps, detour, min_clear):
    """Per-pedestrian metrics and the robot's minimum clearance, in one pass over the
    trace (arithmetic and summation order as numpy's row-by-row reductions, so the
    values are those of the per-metric formulas in the docstrings of
    :func:`pedestrian_metrics` and :func:`robot_metrics`).

    Fills ``walked`` [m], ``stop_steps`` (steps slower than V_STOP before the exit),
    ``detour`` [m] (NaN if not arrived) and ``min_clear`` [m] (NaN without robot);
    returns the robot's smallest clearance to any pedestrian up to its outcome
    (NaN if none)."""
    robot_min = np.inf
    for i in range(n):
        arrived = arrival_step[i] >= 0
        end = arrival_step[i] if arrived else steps + 1  # whole steps before the exit
        total = 0.0
        stopped = 0
        for t in range(1, steps + 1):
            dx, dy = pos[t, i, 0] - pos[t - 1, i, 0], pos[t, i, 1] - pos[t - 1, i, 1]
            seg = math.sqrt(dx * dx + dy * dy)
            if t < end:
                total += seg
                if seg < v_stop_step:
                    stopped += 1
        if arrived and steps > 0:
            k = arrival_step[i]
            dx, dy = pos[k, i, 0] - pos[k - 1, i, 0], pos[k, i, 1] - pos[k - 1, i, 1]
            total += arrival_frac[i] * math.sqrt(dx * dx + dy * dy)
        walked[i] = total
        stop_steps[i] = stopped
        detour[i] = np.nan
        if arrived:
            k = arrival_step[i]
            ax, ay = pos[k - 1, i, 0], pos[k - 1, i, 1]
            ex = ax + arrival_frac[i] * (pos[k, i, 0] - ax)
            ey = ay + arrival_frac[i] * (pos[k, i, 1] - ay)
            sx, sy = ex - pos[0, i, 0], ey - pos[0, i, 1]
            detour[i] = total - math.sqrt(sx * sx + sy * sy)
        min_clear[i] = np.nan
        if has_robot:
            present = arrival_step[i] if arrived else steps
            best = np.inf
            for t in range(min(robot_last, present) + 1):
                dx, dy = pos[t, i, 0] - pos[t, n, 0], pos[t, i, 1] - pos[t, n, 1]
                gap = math.sqrt(dx * dx + dy * dy) - PED_RADIUS - ROBOT_RADIUS
                best = min(best, gap)
                if t <= outcome_step:
                    robot_min = min(robot_min, gap)
            if best < np.inf:
                min_clear[i] = best
    return robot_min if robot_min < np.inf else np.nan


def _measure(tr: Trace) -> dict:
    """Every trace-wide metric, computed once per trace (see :func:`_metrics`)."""
    if tr.measured is None:
        n = tr.n
        walked, stop_steps = np.empty(n), np.empty(n, np.int64)
        detour, min_clear = np.empty(n), np.empty(n)
        robot_min = _metrics(tr.pos, n, tr.steps, tr.arrival_step, tr.arrival_frac,
                             tr.has_robot, tr.robot_last_step, tr.outcome_step,
                             V_STOP * DT, walked, stop_steps, detour, min_clear)
        tr.measured = {"walk_distance": walked, "stop_time": stop_steps * DT,
                       "detour": detour, "min_robot_clearance": min_clear,
                       "robot_min_clearance": robot_min}
    return tr.measured


def pedestrian_metrics(tr: Trace) -> dict[str, np.ndarray]:
    """Per-pedestrian columns:

    * ``arrived``; ``travel_time`` [s] from t = 0 to the interpolated exit crossing
      (NaN if never arrived);
    * ``walk_distance`` [m]: path length until the exit (the end of the run if not
      arrived), the crossing step counted up to the crossing;
    * ``stop_time`` [s]: time spent slower than V_STOP before leaving the scene;
    * ``detour`` [m]: walked minus the straight line from start to the exit point
      (NaN if not arrived);
    * ``min_robot_clearance`` [m]: smallest centre distance to the robot minus both
      radii while both are in the scene (NaN without robot).
    """
    m = _measure(tr)
    return {
        "arrived": tr.arrival_step >= 0,
        "travel_time": pedestrian_travel_time(tr),
        "walk_distance": m["walk_distance"],
        "stop_time": m["stop_time"],
        "detour": m["detour"],
        "min_robot_clearance": m["min_robot_clearance"],
    }


def robot_metrics(tr: Trace) -> dict:
    """Robot columns of the run row; NaN (counts 0) without a robot.

    Over the robot's active period, t = 0 to its outcome: ``robot_time`` [s] (the
    success time, else the 45 s limit), ``outcome_time`` [s], ``robot_path_length``
    [m], ``robot_stop_time`` [s] (slower than V_STOP), ``robot_min_clearance`` [m]
    (to any pedestrian, centre distance minus radii). Collision counts are new
    contact events (a contact lasting several steps counts once) over the whole run;
    ``contact_speed`` [m/s] is the robot's speed at the contact that ended its run.
    """
    out: dict = {c.name: np.nan for c in ROBOT_METRICS}
    out.update(ped_collisions=tr.ped_collisions, world_collisions=tr.world_collisions,
               contact_speed=tr.contact_speed)
    if not tr.has_robot:
        return out
    s_out = tr.outcome_step
    seg = _step_lengths(tr.pos[: s_out + 1, tr.n])
    success = tr.outcome == "success"
    frac = tr.outcome_frac if success else 1.0
    out_time = float((s_out - 1 + frac) * DT) if s_out > 0 else 0.0
    out.update(
        robot_time=out_time if success else TIME_LIMIT,
        outcome_time=out_time,
        robot_path_length=float(np.sum(seg) - (1.0 - frac) * (seg[-1] if len(seg) else 0.0)),
        robot_stop_time=float(np.sum(seg < V_STOP * DT) * DT),
        robot_min_clearance=float(_measure(tr)["robot_min_clearance"]),
    )
    return out
