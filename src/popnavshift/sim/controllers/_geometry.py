"""Geometry and sensing the controllers and the stepping loop share, in numba.

Sensing turns navground's state (or the loop's pose arrays) into the neighbour layout
every kernel takes: ``peds`` (N, 5): x, y, vx, vy, radius [m, m/s]; ``walls`` (M, 4):
x1, y1, x2, y2 [m]; ``discs`` (K, 3): x, y, radius [m]. The distances are the ones the
sampling controller (:mod:`._rollout`) and the yielding state machine score with.
"""

from __future__ import annotations

import math

import numpy as np
from navground import core, sim
from numba import njit

from ...episodes.specs import PED_RADIUS

EMPTY_PEDS = np.zeros((0, 5))
EMPTY_WALLS = np.zeros((0, 4))
EMPTY_DISCS = np.zeros((0, 3))


# ---------------------------------------------------------------- navground -> arrays
def neighbors_array(state: core.GeometricState) -> tuple[np.ndarray, list[int]]:
    """Neighbours of a GeometricState as a (N, 5) array and their ids.

    The binding's vector conversions (~0.9 us each) are the floor here, about
    2 us per neighbour; building rows of Python floats avoids numpy scalars.
    """
    ns = state.neighbors
    if not ns:
        return EMPTY_PEDS, []
    rows, ids = [], []
    for n in ns:
        p, v = n.position, n.velocity
        rows.append((float(p[0]), float(p[1]), float(v[0]), float(v[1]), n.radius))
        ids.append(n.id)
    return np.array(rows), ids


def static_arrays(state: core.GeometricState | sim.World) -> tuple[np.ndarray, np.ndarray]:
    """Walls (M, 4) and static discs (K, 3) of a GeometricState, or of a World
    (the same float32 values: bounded sensing copies the world's in ``prepare``)."""
    if isinstance(state, sim.World):
        lines, disc_list = state.line_obstacles, state.discs
    else:
        lines, disc_list = state.line_obstacles, state.static_obstacles
    walls = [(*w.p1, *w.p2) for w in lines]
    discs = [(*d.position, d.radius) for d in disc_list]
    return (
        np.array(walls, dtype=np.float64) if walls else EMPTY_WALLS,
        np.array(discs, dtype=np.float64) if discs else EMPTY_DISCS,
    )


@njit(cache=True)
def sense_neighbors(poses, twists, robot, active, reach, out, ids):
    """What navground's bounded sensing gives the robot, from the loop's arrays.

    ``poses`` and ``twists`` (agents, 3) are the step's float32 record (x, y, θ and
    vx, vy, ω; pedestrians first, ``robot`` the robot's row). A pedestrian still in
    the scene (``active``) is sensed when its centre is closer than ``reach`` plus
    its radius, computed in float32 as ``World::get_neighbors`` does, so the same
    neighbours are found. Writes their rows (x, y, vx, vy, radius) into ``out``
    and their slots into ``ids``, in slot order; returns their number. Every
    kernel that reads them is order-free (minima and per-row tests).
    """
    m = sense_positions(poses, robot, active, reach, out, ids)
    sense_velocities(twists, out, ids, m)
    return m


@njit(cache=True, inline="always")
def sense_positions(poses, robot, active, reach, out, ids):
    """:func:`sense_neighbors` without the velocities: x, y and radius of each row of
    ``out``, the slots in ``ids``; returns their number. The stepping loop reads the
    step's twists only when somebody is sensed (:func:`sense_velocities`)."""
    rx, ry = poses[robot, 0], poses[robot, 1]
    radius = np.float32(PED_RADIUS)
    limit = np.float32(reach) + radius
    m = 0
    for i in range(active.shape[0]):
        if not active[i]:
            continue
        dx, dy = poses[i, 0] - rx, poses[i, 1] - ry
        if np.sqrt(dx * dx + dy * dy) < limit:
            out[m, 0], out[m, 1] = poses[i, 0], poses[i, 1]
            out[m, 4] = radius
            ids[m] = i
            m += 1
    return m


@njit(cache=True)
def sense_velocities(twists, out, ids, m):
    """The velocity columns of the ``m`` rows :func:`sense_positions` wrote."""
    for j in range(m):
        out[j, 2], out[j, 3] = twists[ids[j], 0], twists[ids[j], 1]


# ---------------------------------------------------------------------- geometry
@njit(cache=True)
def wrap_angle(a: float) -> float:
    return (a + math.pi) % (2.0 * math.pi) - math.pi


@njit(cache=True)
def point_segment_distance_sq(px, py, x1, y1, x2, y2):
    """Squared distance [m^2] from point P to segment 1-2."""
    dx, dy = x2 - x1, y2 - y1
    l2 = dx * dx + dy * dy
    t = 0.0 if l2 <= 0.0 else min(1.0, max(0.0, ((px - x1) * dx + (py - y1) * dy) / l2))
    ex, ey = px - x1 - t * dx, py - y1 - t * dy
    return ex * ex + ey * ey


@njit(cache=True)
def point_segment_distance(px, py, x1, y1, x2, y2):
    return math.sqrt(point_segment_distance_sq(px, py, x1, y1, x2, y2))


@njit(cache=True)
def _cross(ax, ay, bx, by):
    return ax * by - ay * bx


@njit(cache=True)
def segments_distance(ax, ay, bx, by, cx, cy, dx, dy):
    """Smallest distance [m] between segments AB and CD (0 when they cross)."""
    d1 = _cross(bx - ax, by - ay, cx - ax, cy - ay)
    d2 = _cross(bx - ax, by - ay, dx - ax, dy - ay)
    d3 = _cross(dx - cx, dy - cy, ax - cx, ay - cy)
    d4 = _cross(dx - cx, dy - cy, bx - cx, by - cy)
    if d1 * d2 < 0.0 and d3 * d4 < 0.0:
        return 0.0
    # one square root of the smallest square: sqrt is monotonic and correctly
    # rounded, so this is exactly the smallest of the four distances
    return math.sqrt(min(point_segment_distance_sq(ax, ay, cx, cy, dx, dy),
                         point_segment_distance_sq(bx, by, cx, cy, dx, dy),
                         point_segment_distance_sq(cx, cy, ax, ay, bx, by),
                         point_segment_distance_sq(dx, dy, ax, ay, bx, by)))


# ------------------------------------------------------------------------ rollouts
