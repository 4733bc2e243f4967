"""Numba kernels of the sampling controller (the geometry and sensing it shares with the
others are in :mod:`._geometry`).

Why numba: a numpy rollout of 81 wheel pairs x 20 steps costs ~15x a navground
step (notes §8); these loops run once per control step and must stay in the
microseconds. Every kernel takes plain float64 arrays in one layout:

* ``peds``  (N, 5): x, y, vx, vy, radius — neighbours [m, m/s], constant velocity
* ``walls`` (M, 4): x1, y1, x2, y2 — wall segments [m]
* ``discs`` (K, 3): x, y, radius — static obstacles [m]

Motion is integrated like navground's ``Pose2.integrate`` (explicit Euler:
position first with the current heading, then heading), so a rollout of a
constant command reproduces what the simulator will do with it.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ._geometry import (
    point_segment_distance,
    point_segment_distance_sq,
    segments_distance,
    wrap_angle,
)

_ESCAPE_EPS = 1e-6  # [m] tolerance of the "do not get closer" rule
_BOUND_SLACK = 1e-9  # a sampled arc is skipped if its score bound is this far below the best


@njit(cache=True)
def feasible_speed(v, w, v_top, wheel_max, axis):
    """Clamp forward speed like TwoWheelsDifferentialDriveKinematics.feasible
    (keep the angular speed, cut the linear one; no reversing)."""
    return min(max(v, 0.0), v_top, max(0.0, wheel_max - abs(w) * axis / 2.0))


@njit(cache=True)
def goal_rollout(x, y, th, gx, gy, speed, v_top, wheel_max, axis, w_max, rot_tau, tol,
                 dt, xs, ys):
    """Closed-loop drive-to-goal rollout (navground's heading=velocity law:
    w = angle error / rotation_tau, v = speed * cos(error)), written into
    ``xs, ys`` (n+1). Returns the first command (v [m/s], w [rad/s])."""
    v0 = w0 = 0.0
    xs[0], ys[0] = x, y
    for k in range(xs.shape[0] - 1):
        v = w = 0.0
        if math.hypot(gx - x, gy - y) > tol:
            err = wrap_angle(math.atan2(gy - y, gx - x) - th)
            w = min(max(err / rot_tau, -w_max), w_max)
            v = feasible_speed(speed * math.cos(err), w, v_top, wheel_max, axis)
        if k == 0:
            v0, w0 = v, w
        x += v * math.cos(th) * dt
        y += v * math.sin(th) * dt
        th += w * dt
        xs[k + 1], ys[k + 1] = x, y
    return v0, w0


@njit(cache=True)
def arc_headings(th, w, dt, cos_out, sin_out):
    """cos and sin of the headings of a constant-``w`` rollout from ``th`` (one per
    step, as :func:`arc_rollout` integrates them); returns the final heading. They
    depend on w only, so arcs that share a turn rate share them."""
    for k in range(cos_out.shape[0]):
        cos_out[k], sin_out[k] = math.cos(th), math.sin(th)
        th += w * dt
    return th


@njit(cache=True)
def arc_rollout(x, y, v, dt, cos_th, sin_th, xs, ys):
    """Constant-speed rollout into ``xs, ys`` (n+1) along the headings given by
    :func:`arc_headings` (navground's Euler step: position first, then heading)."""
    xs[0], ys[0] = x, y
    for k in range(xs.shape[0] - 1):
        x += v * cos_th[k] * dt
        y += v * sin_th[k] * dt
        xs[k + 1], ys[k + 1] = x, y


# ------------------------------------------------------------- reactive sampling
@njit(cache=True)
def _nearby(x, y, radius, reach, horizon, peds, walls, discs):
    """The discs (pedestrians and static discs as (n, 5) with zero velocity)
    and walls that can come within ``reach`` [m] of a robot moving at most
    ``reach - cap`` in ``horizon`` [s]; the others cannot change a rollout."""
    movers = np.empty((peds.shape[0] + discs.shape[0], 5))
    n = 0
    for i in range(peds.shape[0]):
        gap = math.hypot(peds[i, 0] - x, peds[i, 1] - y) - radius - peds[i, 4]
        if gap - math.hypot(peds[i, 2], peds[i, 3]) * horizon < reach:
            movers[n] = peds[i]
            n += 1
    for k in range(discs.shape[0]):
        if math.hypot(discs[k, 0] - x, discs[k, 1] - y) - radius - discs[k, 2] < reach:
            movers[n, 0], movers[n, 1], movers[n, 4] = discs[k, 0], discs[k, 1], discs[k, 2]
            movers[n, 2] = movers[n, 3] = 0.0
            n += 1
    near_walls = np.empty_like(walls)
    m = 0
    for j in range(walls.shape[0]):
        w = walls[j]
        if point_segment_distance(x, y, w[0], w[1], w[2], w[3]) - radius < reach:
            near_walls[m] = w
            m += 1
    return movers[:n], near_walls[:m]


@njit(cache=True)
def _tracks(x, y, radius, v_top, cap, movers, walls, n_steps, dt):
    """Constant-velocity positions (n_steps+1, n, 2) of the discs, and which
    discs and walls (n_steps+1, n+m) the robot, starting at (x, y) and moving
    at most ``v_top``, could bring within ``cap`` of its edge at each step."""
    n = movers.shape[0]
    out = np.empty((n_steps + 1, n, 2))
    active = np.empty((n_steps + 1, n + walls.shape[0]), dtype=np.bool_)
    wall_gap = np.empty(walls.shape[0])
    for j in range(walls.shape[0]):
        w = walls[j]
        wall_gap[j] = point_segment_distance(x, y, w[0], w[1], w[2], w[3]) - radius
    for k in range(n_steps + 1):
        travel = v_top * k * dt + cap
        for e in range(n):
            px = movers[e, 0] + movers[e, 2] * k * dt
            py = movers[e, 1] + movers[e, 3] * k * dt
            out[k, e, 0], out[k, e, 1] = px, py
            active[k, e] = math.hypot(px - x, py - y) - radius - movers[e, 4] < travel
        for j in range(walls.shape[0]):
            active[k, n + j] = wall_gap[j] < travel
    return out, active


@njit(cache=True)
def _thresholds(x, y, radius, buffer, movers, walls):
    """Per-entity collision threshold on clearance [m]: the buffer, or — for an
    entity already inside it — the current clearance (the robot may not get
    closer, but may escape)."""
    n = movers.shape[0]
    thr = np.empty(n + walls.shape[0])
    for e in range(n):
        c0 = math.hypot(x - movers[e, 0], y - movers[e, 1]) - radius - movers[e, 4]
        thr[e] = min(buffer, c0 - _ESCAPE_EPS)
    for j in range(walls.shape[0]):
        w = walls[j]
        c0 = point_segment_distance(x, y, w[0], w[1], w[2], w[3]) - radius
        thr[n + j] = min(buffer, c0 - _ESCAPE_EPS)
    return thr


@njit(cache=True)
def sweep(xs, ys, radius, tracks, active, movers, walls, thr, cap):
    """Check a rollout (steps 1..n) against moving discs and walls.

    Returns (free, clearance): free is False at the first clearance below its
    threshold; clearance [m] is the smallest one, capped at ``cap``. Squared
    distances first: a square root only for entities nearer than the cap.
    """
    return sweep_to_win(xs, ys, radius, tracks, active, movers, walls, thr, cap, 0.0, 0.0,
                        -np.inf)


@njit(cache=True, inline="always")
def sweep_to_win(xs, ys, radius, tracks, active, movers, walls, thr, cap, lead, w_clear,
                 limit):
    """:func:`sweep` for a sampled arc that needs a score of at least ``limit`` to win:
    its score is at most ``lead + w_clear * clearance / cap`` (``lead``: its progress,
    heading and sight terms at most), so the sweep gives up, as if the arc were
    blocked, once the clearance found so far puts that below ``limit``."""
    n = movers.shape[0]
    best = cap
    for k in range(1, xs.shape[0]):
        x, y = xs[k], ys[k]
        for e in range(n):
            if not active[k, e]:
                continue
            reach = radius + movers[e, 4]
            dx, dy = x - tracks[k, e, 0], y - tracks[k, e, 1]
            d2 = dx * dx + dy * dy
            lim = thr[e] + reach
            if lim > 0.0 and d2 < lim * lim:
                return False, 0.0
            near = best + reach
            if d2 < near * near:
                best = math.sqrt(d2) - reach
                if lead + w_clear * best / cap < limit:
                    return False, 0.0
        for j in range(walls.shape[0]):
            if not active[k, n + j]:
                continue
            w = walls[j]
            d2 = point_segment_distance_sq(x, y, w[0], w[1], w[2], w[3])
            lim = thr[n + j] + radius
            if lim > 0.0 and d2 < lim * lim:
                return False, 0.0
            near = best + radius
            if d2 < near * near:
                best = math.sqrt(d2) - radius
                if lead + w_clear * best / cap < limit:
                    return False, 0.0
    return True, best


@njit(cache=True)
def sight_clearance(x, y, gx, gy, length, t, radius, peds, walls, discs):
    """Clearance [m] of the straight path from (x, y) towards the goal, over at
    most ``length`` [m], from pedestrians (at their positions at time ``t``),
    walls and discs; 0 or less when the path is blocked."""
    dist = math.hypot(gx - x, gy - y)
    if dist > length:
        gx = x + (gx - x) * length / dist
        gy = y + (gy - y) * length / dist
    c = np.inf
    for i in range(peds.shape[0]):
        px, py = peds[i, 0] + peds[i, 2] * t, peds[i, 1] + peds[i, 3] * t
        c = min(c, point_segment_distance(px, py, x, y, gx, gy) - radius - peds[i, 4])
    for j in range(walls.shape[0]):
        w = walls[j]
        c = min(c, segments_distance(x, y, gx, gy, w[0], w[1], w[2], w[3]) - radius)
    for k in range(discs.shape[0]):
        c = min(c, point_segment_distance(discs[k, 0], discs[k, 1], x, y, gx, gy)
                - radius - discs[k, 2])
    return c


#: the fields of the ``cfg`` array of :func:`reactive_command`, in order (one
#: float64 array: numba checks each argument's type on every call, ~0.1 us each)
REACTIVE_CFG = ("speed", "tol", "v_top", "wheel_max", "axis", "w_max", "rot_tau", "radius",
                "buffer", "dt", "n_steps", "n_v", "n_w", "cap", "sight", "w_progress",
                "w_heading", "w_clearance", "w_sight")


@njit(cache=True)
def reactive_command(x, y, th, gx, gy, cfg, peds, walls, discs):
    """One decision of the reactive controller; ``cfg`` holds :data:`REACTIVE_CFG`.

    Returns (v [m/s], w [rad/s], mode): mode 0 = the drive-to-goal command is
    conflict-free over ``n_steps * dt``; 1 = adjusted to the best free sampled
    arc; 2 = no free sample, stop. A sample's score is
    ``weights @ (progress, heading, clearance, sight)``: progress towards the
    goal over the rollout / (v_top * horizon); cosine of the final heading
    error; smallest clearance along the arc and clearance of the straight path
    from the arc's end towards the goal (over ``sight`` m), both capped at
    ``cap`` m and divided by it.
    """
    speed, tol, v_top, wheel_max, axis, w_max, rot_tau = cfg[0], cfg[1], cfg[2], cfg[3], \
        cfg[4], cfg[5], cfg[6]
    radius, buffer, dt, cap = cfg[7], cfg[8], cfg[9], cfg[13]
    n_steps = int(cfg[10])
    horizon = n_steps * dt
    movers, near_walls = _nearby(x, y, radius, v_top * horizon + cap, horizon, peds, walls,
                                 discs)
    tracks, active = _tracks(x, y, radius, v_top, cap, movers, near_walls, n_steps, dt)
    thr = _thresholds(x, y, radius, buffer, movers, near_walls)
    xs, ys = np.empty(n_steps + 1), np.empty(n_steps + 1)
    v0, w0 = goal_rollout(x, y, th, gx, gy, speed, v_top, wheel_max, axis, w_max,
                          rot_tau, tol, dt, xs, ys)
    if sweep(xs, ys, radius, tracks, active, movers, near_walls, thr, cap)[0]:
        return v0, w0, 0
    return _best_arc(x, y, th, gx, gy, cfg, peds, walls, discs, tracks, active, movers,
                     near_walls, thr)


@njit(cache=True)
def _best_arc(x, y, th, gx, gy, cfg, peds, walls, discs, tracks, active, movers, near_walls,
              thr):
    """The sampling step of :func:`reactive_command`: the best free arc of the grid
    (mode 1) or a stop (mode 2).

    The grid's winner is the first arc, in grid order (speed levels up, then turn
    rates), with the highest score ``progress + heading + clearance + sight``, each
    weighted; heading, clearance and sight are at most their weights (cosine; capped
    at ``cap`` and divided by it), and progress is at most the level's speed over
    ``v_top`` (the arc is that long). Branch and bound: speed levels are searched
    from the fastest down, so a level whose bound cannot beat the best score found is
    skipped with every slower one, and within a level an arc whose bound with its
    actual progress and heading cannot beat it skips the sweep and the sight line;
    an arc leaves the sweep once its clearance so far cannot win
    (:func:`sweep_to_win`). Ties go to the earlier arc in grid order. The weights are
    not negative and rounding is monotonic, so a score exceeds its bound by a few
    ulps at most; bounds are compared with a slack of :data:`_BOUND_SLACK`: the
    winner is the grid's, bit for bit.
    """
    tol, v_top, wheel_max, axis, w_max = cfg[1], cfg[2], cfg[3], cfg[4], cfg[5]
    radius, buffer, dt, cap, sight, weights = cfg[7], cfg[8], cfg[9], cfg[13], cfg[14], cfg[15:]
    n_steps, n_v, n_w = int(cfg[10]), int(cfg[11]), int(cfg[12])
    horizon = n_steps * dt
    d0 = math.hypot(gx - x, gy - y)
    reach = max(v_top * horizon, 1e-9)
    w_turn = min(w_max, math.pi / horizon)  # at most half a turn per rollout
    xs, ys = np.empty(n_steps + 1), np.empty(n_steps + 1)
    cos_th, sin_th = np.empty((n_w, n_steps)), np.empty((n_w, n_steps))
    th_end = np.empty(n_w)
    headings_of = -1.0  # the turn-rate limit the headings were computed for
    rest = weights[2] + weights[3] + weights[1]  # heading, clearance and sight at most
    best, best_v, best_w, best_a = -np.inf, 0.0, 0.0, n_v * n_w
    for i in range(n_v - 1, -1, -1):
        v = v_top * i / max(n_v - 1, 1)
        if weights[0] * (v * horizon) / reach + rest < best - _BOUND_SLACK:
            break  # nor can any slower level
        w_lim = min(w_turn, 2.0 * max(0.0, wheel_max - v) / axis)
        # no turn left at this speed: the level's arcs are one straight line (w = ±0),
        # the first of them wins their tie
        n_turns = 1 if w_lim == 0.0 else n_w
        if w_lim != headings_of:  # slow levels share the w_turn limit, and so the trig
            for j in range(n_turns):
                w = -w_lim + 2.0 * w_lim * j / max(n_w - 1, 1)
                th_end[j] = arc_headings(th, w, dt, cos_th[j], sin_th[j])
            headings_of = w_lim
        for j in range(n_turns):
            w = -w_lim + 2.0 * w_lim * j / max(n_w - 1, 1)
            arc_rollout(x, y, v, dt, cos_th[j], sin_th[j], xs, ys)
            xe, ye = xs[-1], ys[-1]
            d_end = math.hypot(gx - xe, gy - ye)
            heading, far = 1.0, d_end > tol
            if far:
                heading = math.cos(wrap_angle(math.atan2(gy - ye, gx - xe) - th_end[j]))
            lead = weights[0] * (d0 - d_end) / reach + weights[1] * heading
            if lead + weights[2] + weights[3] < best - _BOUND_SLACK:
                continue
            free, clear = sweep_to_win(xs, ys, radius, tracks, active, movers, near_walls, thr,
                                       cap, lead + weights[3], weights[2], best - _BOUND_SLACK)
            if not free:  # blocked, or its clearance cannot win
                continue
            partial = lead + weights[2] * clear / cap
            open_path = cap
            if far:
                if partial + weights[3] < best - _BOUND_SLACK:
                    continue
                open_path = sight_clearance(xe, ye, gx, gy, sight, horizon, radius, peds,
                                            walls, discs) - buffer
            score = partial + weights[3] * max(-cap, min(open_path, cap)) / cap
            a = i * n_w + j
            if score > best or (score == best and a < best_a):
                best, best_v, best_w, best_a = score, v, w, a
    if best == -np.inf:
        return 0.0, 0.0, 2
    return best_v, best_w, 1


@njit(cache=True)
def reactive_pose_command(pose, goal, cfg, peds, walls, discs):
    """:func:`reactive_command` for the robot's float32 ``pose`` (x, y, θ) and ``goal``
    (2,): the loop driver's call, without unpacking them in Python first."""
    return reactive_command(np.float64(pose[0]), np.float64(pose[1]), np.float64(pose[2]),
                            goal[0], goal[1], cfg, peds, walls, discs)
