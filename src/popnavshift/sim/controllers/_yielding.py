"""Numba kernels of the early-yielding controller: conflicts and pull-aside points.

Same array layouts as :mod:`._rollout` (``peds`` (N, 5): x, y, vx, vy, radius;
``walls`` (M, 4); ``discs`` (K, 3)); the geometry helpers come from there.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ._geometry import point_segment_distance

_RAY_TIME = 100.0  # [s] a constant-velocity path this long stands for the whole ray


@njit(cache=True)
def conflicting(x, y, ux, uy, radius, peds, horizon, margin, min_speed, same_cos, out):
    """Closest-approach test of each neighbour against the robot moving at
    (ux, uy) over ``horizon`` [s]: ``out[i]`` is True when the neighbour moves
    (speed >= ``min_speed``), does not walk the robot's way (cosine between
    its heading and the robot's < ``same_cos``), is still approaching, and the
    closest centre distance is below the radii plus ``margin``. Returns the
    number of conflicts."""
    count = 0
    u = math.hypot(ux, uy)
    for i in range(peds.shape[0]):
        out[i] = False
        vx, vy = peds[i, 2], peds[i, 3]
        speed = math.hypot(vx, vy)
        if speed < min_speed or (u > 0.0 and vx * ux + vy * uy >= same_cos * speed * u):
            continue
        dx, dy = peds[i, 0] - x, peds[i, 1] - y
        dvx, dvy = vx - ux, vy - uy
        a = dvx * dvx + dvy * dvy
        if a < 1e-12:
            continue
        t = -(dx * dvx + dy * dvy) / a
        if t <= 0.0:
            continue  # already separating
        t = min(t, horizon)
        if math.hypot(dx + dvx * t, dy + dvy * t) < radius + peds[i, 4] + margin:
            out[i] = True
            count += 1
    return count


@njit(cache=True)
def _static_clearance(x, y, radius, walls, discs):
    c = np.inf
    for j in range(walls.shape[0]):
        w = walls[j]
        c = min(c, point_segment_distance(x, y, w[0], w[1], w[2], w[3]) - radius)
    for k in range(discs.shape[0]):
        c = min(c, math.hypot(x - discs[k, 0], y - discs[k, 1]) - radius - discs[k, 2])
    return c


@njit(cache=True)
def _path_clearance(x, y, radius, peds, horizon, conflict):
    """Clearance [m] of a point from every neighbour's constant-velocity path:
    the segment swept in ``horizon`` [s], or for neighbours in ``conflict``
    the whole ray ahead of them (they will get there, however slow)."""
    c = np.inf
    for i in range(peds.shape[0]):
        t = _RAY_TIME if conflict[i] else horizon
        x1, y1 = peds[i, 0], peds[i, 1]
        x2, y2 = x1 + peds[i, 2] * t, y1 + peds[i, 3] * t
        c = min(c, point_segment_distance(x, y, x1, y1, x2, y2) - radius - peds[i, 4])
    return c


@njit(cache=True)
def pull_aside_point(x, y, fx, fy, radius, buffer, peds, conflict, walls, discs, horizon,
                     forward, lateral_step, lateral_max):
    """A pull-aside point ``forward`` [m] along the unit path direction (fx, fy)
    and sideways. Each side is scanned outwards in ``lateral_step`` steps while
    wall/obstacle clearance stays >= ``buffer``; that reach is the side's free
    space. The freer side (right on ties within one step) gets the smallest
    offset whose clearance from all pedestrian paths (rays for those in
    ``conflict``, see :func:`_path_clearance`) is >= ``buffer``, then the
    other side; failing both, the statically clear point farthest from the
    pedestrian paths; failing that, the robot's own position.

    Returns (qx, qy, kind): kind 0 = clear point, 1 = best effort, 2 = in place.
    """
    n_lat = int(lateral_max / lateral_step + 0.5)
    lx, ly = -fy, fx  # left normal
    points = np.empty((2, n_lat, 2))  # side 0 = right, 1 = left
    reach = np.zeros(2)
    ok = np.zeros((2, n_lat), dtype=np.bool_)
    path_c = np.full((2, n_lat), -np.inf)
    for s in range(2):
        sign = -1.0 if s == 0 else 1.0
        started = False
        for k in range(n_lat):
            lat = (k + 1) * lateral_step
            qx = x + forward * fx + sign * lat * lx
            qy = y + forward * fy + sign * lat * ly
            points[s, k, 0], points[s, k, 1] = qx, qy
            if _static_clearance(qx, qy, radius, walls, discs) >= buffer:
                started = True
                ok[s, k] = True
                reach[s] = lat
                path_c[s, k] = _path_clearance(qx, qy, radius, peds, horizon, conflict)
            elif started:
                break  # a wall or an obstacle closes this side
    first = 1 if reach[1] > reach[0] + lateral_step / 2 else 0
    best_c, best_s, best_k = -np.inf, -1, -1
    for s in (first, 1 - first):
        for k in range(n_lat):
            if ok[s, k] and path_c[s, k] >= buffer:
                return points[s, k, 0], points[s, k, 1], 0
            if ok[s, k] and path_c[s, k] > best_c:
                best_c, best_s, best_k = path_c[s, k], s, k
    if best_s < 0:
        return x, y, 2
    return points[best_s, best_k, 0], points[best_s, best_k, 1], 1
