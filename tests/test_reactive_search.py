"""The reactive controller's branch-and-bound arc search picks the grid's winner, bit for bit.

:func:`popnavshift.sim.controllers._rollout.reactive_command` searches its (speed, turn)
grid from the fastest level down and skips arcs whose score bound cannot win. The
oracle below is the plain search it replaced: every arc in grid order, the first
highest score wins. Both use the same rollout, sweep and sight kernels, so their
(v, w, mode) must be equal, not just close.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from popnavshift.sim.controllers import _geometry as G
from popnavshift.sim.controllers import _rollout as R
from popnavshift.sim.controllers.reactive import CLEARANCE_CAP, PARAMS

AXIS = 0.5


def _cfg(speed: float, **params) -> np.ndarray:
    p = {name: spec.default for name, spec in PARAMS.items()} | params
    values = {
        "speed": speed, "tol": 0.3, "v_top": speed, "wheel_max": speed, "axis": AXIS,
        "w_max": 4.0 * speed, "rot_tau": 0.5, "radius": 0.35, "buffer": p["buffer"],
        "dt": 0.1, "n_steps": round(p["rollout_time"] / 0.1), "n_v": p["n_speeds"],
        "n_w": p["n_turns"], "cap": CLEARANCE_CAP, "sight": p["sight_distance"],
        "w_progress": p["progress_weight"], "w_heading": p["heading_weight"],
        "w_clearance": p["clearance_weight"], "w_sight": p["sight_weight"],
    }
    return np.array([values[f] for f in R.REACTIVE_CFG], dtype=np.float64)


def grid_search(x, y, th, gx, gy, cfg, peds, walls, discs):
    """The exhaustive search: every arc in grid order, strict improvement."""
    tol, v_top, wheel_max, axis, w_max = cfg[1], cfg[2], cfg[3], cfg[4], cfg[5]
    radius, buffer, dt, cap, sight, weights = cfg[7], cfg[8], cfg[9], cfg[13], cfg[14], cfg[15:]
    n_steps, n_v, n_w = int(cfg[10]), int(cfg[11]), int(cfg[12])
    horizon = n_steps * dt
    movers, near = R._nearby(x, y, radius, v_top * horizon + cap, horizon, peds, walls, discs)
    tracks, active = R._tracks(x, y, radius, v_top, cap, movers, near, n_steps, dt)
    thr = R._thresholds(x, y, radius, buffer, movers, near)
    xs, ys = np.empty(n_steps + 1), np.empty(n_steps + 1)
    d0 = math.hypot(gx - x, gy - y)
    reach = max(v_top * horizon, 1e-9)
    w_turn = min(w_max, math.pi / horizon)
    best, best_v, best_w = -np.inf, 0.0, 0.0
    cos_th, sin_th = np.empty(n_steps), np.empty(n_steps)
    for i in range(n_v):
        v = v_top * i / max(n_v - 1, 1)
        w_lim = min(w_turn, 2.0 * max(0.0, wheel_max - v) / axis)
        for j in range(n_w):
            w = -w_lim + 2.0 * w_lim * j / max(n_w - 1, 1)
            th_end = R.arc_headings(th, w, dt, cos_th, sin_th)
            R.arc_rollout(x, y, v, dt, cos_th, sin_th, xs, ys)
            free, clear = R.sweep(xs, ys, radius, tracks, active, movers, near, thr, cap)
            if not free:
                continue
            xe, ye = xs[-1], ys[-1]
            d_end = math.hypot(gx - xe, gy - ye)
            heading, open_path = 1.0, cap
            if d_end > tol:
                heading = math.cos(G.wrap_angle(math.atan2(gy - ye, gx - xe) - th_end))
                open_path = R.sight_clearance(xe, ye, gx, gy, sight, horizon, radius, peds,
                                              walls, discs) - buffer
            score = (weights[0] * (d0 - d_end) / reach + weights[1] * heading
                     + weights[2] * clear / cap
                     + weights[3] * max(-cap, min(open_path, cap)) / cap)
            if score > best:
                best, best_v, best_w = score, v, w
    if best == -np.inf:
        return 0.0, 0.0, 2
    return best_v, best_w, 1


def _scenario(rng: np.random.Generator):
    """A robot near the origin, a goal ahead, pedestrians close enough to force a
    sampled decision often, and sometimes a corridor and a pillar."""
    x, y, th = rng.uniform(-0.5, 0.5), rng.uniform(-0.5, 0.5), rng.uniform(-math.pi, math.pi)
    gx, gy = rng.uniform(-8, 8), rng.uniform(-8, 8)
    n = int(rng.integers(0, 6))
    peds = np.column_stack([rng.uniform(-3, 3, n), rng.uniform(-3, 3, n),
                            rng.uniform(-1.2, 1.2, n), rng.uniform(-1.2, 1.2, n),
                            np.full(n, 0.25)]) if n else G.EMPTY_PEDS
    walls, discs = G.EMPTY_WALLS, G.EMPTY_DISCS
    if rng.random() < 0.5:
        half = rng.uniform(0.8, 2.5)
        walls = np.array([[-20, -half, 20, -half], [-20, half, 20, half]], dtype=np.float64)
    if rng.random() < 0.3:
        discs = np.array([[rng.uniform(-2, 2), rng.uniform(-2, 2), rng.uniform(0.2, 0.8)]])
    return x, y, th, gx, gy, peds, walls, discs


@pytest.mark.parametrize("speed,params", [
    (1.0, {}),  # the top level has no turn left: its 11 arcs are one straight line
    (0.6, {}),
    (1.2, {"n_speeds": 5, "n_turns": 9, "sight_weight": 0.0}),
    (0.8, {"progress_weight": 0.0, "heading_weight": 2.0, "buffer": 0.3}),
])
def test_branch_and_bound_picks_the_grid_winner(speed, params):
    cfg = _cfg(speed, **params)
    rng = np.random.default_rng(7)
    sampled = stopped = 0
    for _ in range(400):
        x, y, th, gx, gy, peds, walls, discs = _scenario(rng)
        got = R.reactive_command(x, y, th, gx, gy, cfg, peds, walls, discs)
        if got[2] == 0:
            continue  # the drive-to-goal command was free: no search
        sampled += 1
        stopped += got[2] == 2
        assert got == grid_search(x, y, th, gx, gy, cfg, peds, walls, discs)
    assert sampled >= 40  # the scenarios do exercise the search
    assert stopped < sampled  # and it does find arcs
