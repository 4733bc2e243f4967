"""Quiet stretches: steps in which the stepping loop has nothing to do, run by navground.

The stepping loop (:mod:`popnavshift.sim.loop`) acts on navground only on events: a
pedestrian crosses its via or exit line, the response layer changes a speed or a target, the
robot touches something or enters its goal, a loop driver decides something. Far
from every line and from the robot, with no pedestrian yielding or detouring, none
of these can happen for a while: :func:`quiet_steps` bounds how long (from the
agents' speed caps, with a margin). The loop then lets navground's own C++ loop
(``World.run``) do those steps, recording poses through a world callback, and
replays its per-step kernel over the recorded poses afterwards
(:func:`replay_quiet`). The kernel is the same and sees the same poses, so the
state it leaves is the one the step-by-step loop would have left; the replay also
checks that no step of the stretch needed the loop after all (a push in a
collision can beat the bound). If one did, the run is discarded and simulated
again step by step (:class:`NotQuiet`): the tables never depend on the shortcut.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .constants import DT, PED_RADIUS, ROBOT_SENSING_RANGE
from .controllers._geometry import sense_positions
from .pedestrians import SENSE_RANGE, advance

MARGIN = 0.3  # [m] kept free beyond the speed bound: collision pushes, float32 poses
MIN_STRETCH = 4  # shorter stretches save less than their set-up costs
#: [m] a pedestrian farther than this from the robot is neither sensed by it nor sees it
REACH = max(SENSE_RANGE, ROBOT_SENSING_RANGE + PED_RADIUS)


class NotQuiet(Exception):
    """A stretch contained a step that needed the loop: simulate the run step by step."""


@njit(cache=True)
def quiet_steps(step, pos, robot_in, robot_active, robot_speed, goal, active, prm, fst, ist,
                limit):
    """How many of the next steps (at most ``limit``) certainly need nothing from the
    loop, or 0 if fewer than :data:`MIN_STRETCH`.

    ``pos[step]`` (agents, 2) [m] are the current positions (robot last); ``goal``
    (3,) the robot's goal disc; ``prm``, ``fst``, ``ist`` the response layer's state
    (:class:`.pedestrians.ResponseLayer`). Every pedestrian in the scene must walk
    its route at full speed (no detour, speed factor 1), and stay, moving at its speed
    cap v (its kinematics' max speed), :data:`MARGIN` short of its next line and
    beyond :data:`REACH` + :data:`MARGIN` of the robot moving at ``robot_speed``;
    the robot must stay that far from its goal disc.
    """
    n = active.shape[0]
    now = pos[step]
    k = limit
    for i in range(n):
        if not active[i]:
            continue
        if ist[i, 0] != 0 or fst[i, 4] != 1.0:
            return 0
        v = prm[i, 0]
        line = prm[i, 9] if ist[i, 1] == 1 else min(prm[i, 8], prm[i, 9])
        room = line - (now[i, 0] * prm[i, 6] + now[i, 1] * prm[i, 7]) - MARGIN
        k = min(k, math.floor(room / (v * DT)))
        if robot_in:
            gap = math.hypot(now[i, 0] - now[n, 0], now[i, 1] - now[n, 1]) - REACH - MARGIN
            k = min(k, math.floor(gap / ((v + robot_speed) * DT)))
        if k < MIN_STRETCH:
            return 0
    if robot_active:
        gap = math.hypot(goal[0] - now[n, 0], goal[1] - now[n, 1]) - goal[2] - MARGIN
        k = min(k, math.floor(gap / (robot_speed * DT)))
    return k if k >= MIN_STRETCH else 0


@njit(cache=True)
def replay_quiet(step, poses, pos, robot_on, robot_active, goal, active, fracs, arrival_step,
                 prm, fst, ist, buf, consts, walls, obstacles, driven, sensed, sensed_ids):
    """Run :func:`.pedestrians.advance` on each recorded step after ``step``
    (``poses`` (k, agents, 3), float32) exactly as the loop would have; returns
    whether every one of them was quiet: no exit crossed, no goal entered, no
    navground write, and (``driven``: a loop driver decides while the robot is
    active) nobody the robot senses (``sensed``, ``sensed_ids``: scratch of
    :func:`.controllers._geometry.sense_positions`)."""
    n = active.shape[0]
    for j in range(poses.shape[0]):
        k, s, n_speed, n_target = advance(step + j + 1, poses[j], pos, robot_on, robot_active,
                                          goal, active, fracs, arrival_step, prm, fst, ist, buf,
                                          consts, walls, obstacles)
        if k or s >= 0.0 or n_speed or n_target:
            return False
        if driven and sense_positions(poses[j], n, active, ROBOT_SENSING_RANGE, sensed,
                                      sensed_ids):
            return False
    return True


def robot_touched(collisions: np.ndarray, since: int, uid: int) -> bool:
    """Whether rows ``since:`` of a run's collision record ((K, 3): step, uid, uid)
    involve the entity ``uid``."""
    new = collisions[since:]
    return bool(len(new)) and bool(((new[:, 1] == uid) | (new[:, 2] == uid)).any())
