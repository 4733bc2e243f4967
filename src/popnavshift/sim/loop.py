"""The stepping loop of one run: navground steps, the response layer, the robot's events.

:class:`StepLoop` steps a built world at ``DT`` until the limit, or until the
robot is done (or absent) and every pedestrian has left; it records a
:class:`.trace.Trace`. Per step: the navground update, the robot's contacts, one
:func:`.pedestrians.advance` kernel call (poses, exits, goal entry, response
layer) and its navground writes, and the loop driver's decision. Steps that need
none of these run in navground's own loop (:mod:`.quiet`).
"""

from __future__ import annotations

import math
from typing import cast

import numpy as np
from navground import sim
from numba import njit

from ..episodes.specs import EpisodeSpec
from .constants import (
    DT,
    MAX_STEPS,
    PED_RADIUS,
    ROBOT_GOAL_TOLERANCE,
    ROBOT_RADIUS,
    ROBOT_SENSING_RANGE,
)
from .controllers import LoopDriver
from .controllers._geometry import sense_neighbors, sense_positions, sense_velocities
from .pedestrians import ResponseLayer, advance
from .quiet import NotQuiet, quiet_steps, replay_quiet, robot_touched
from .trace import Trace
from .world import SimWorld, remove_agent, stop_agent

RECHECK_STEPS = 5  # after a step that could not start a quiet stretch, test again this later


class StepLoop:
    """One run's stepping loop; state lives on the instance, arrays are preallocated."""

    def __init__(self, spec: EpisodeSpec, sw: SimWorld, layer: ResponseLayer,
                 driver: LoopDriver | None, record: bool, stretches: bool = False) -> None:
        self.spec, self.sw, self.layer, self.record = spec, sw, layer, record
        # quiet stretches (see .quiet): not while recording flags, and with a loop
        # driver only if it can tell when a step without neighbours changes nothing
        self.driver_quiet = getattr(driver, "quiet", None)
        self.stretches = stretches and not record and (driver is None
                                                       or self.driver_quiet is not None)
        self.world = sw.world
        self.driver = driver
        n = spec.n_peds
        self.n = n
        na = n + (sw.robot is not None)
        self.pos = np.empty((MAX_STEPS + 1, na, 2))
        self.pos[0, :n] = spec.ped_starts
        if sw.robot is not None:
            self.pos[0, n] = spec.robot_start
        # the robot's goal disc: x, y, radius [m]
        self.goal = np.array([*spec.robot_goal, ROBOT_GOAL_TOLERANCE], dtype=np.float64)
        self.active = np.ones(n, dtype=np.bool_)
        self.no_robot = np.zeros(2)
        # row 0: exit-crossing fractions of the current step (scratch); row 1: of
        # each pedestrian's crossing step (1 until it crosses)
        self.fracs = np.zeros((2, n))
        self.fracs[1] = 1.0
        self.trace = Trace(n, self.pos, 0, np.full(n, -1, np.int64), self.fracs[1],
                            sw.robot is not None)
        if record:
            self.trace.flags = np.zeros((MAX_STEPS + 1, n), np.uint8)
            self.initial_poses = np.array(
                [[*a.position, a.orientation] for a in sw.world.agents], dtype=np.float64
            ).reshape(na, 3)
        # what the driver senses: the neighbours' rows and slots, and its views of
        # them for each number sensed; the robot's pose
        self.sensed = np.empty((n, 5))
        self.sensed_ids = np.empty(n, np.int64)
        self.sensed_views = [(self.sensed[:m], self.sensed_ids[:m]) for m in range(n + 1)]
        self.robot_pose = np.empty(3, np.float32)

    def execute(self) -> Trace:
        """Step until the limit, or until the robot is done (or absent) and all peds left.

        Per step: navground update, robot contacts, then one :func:`advance` kernel
        call (poses, exits, goal entry, response layer; with a loop driver
        :func:`advance_driven`, which also senses for it) and its navground writes,
        then the driver's decision.
        """
        sw, n, pos, tr, layer = self.sw, self.n, self.pos, self.trace, self.layer
        active = self.active
        self.robot_in = self.robot_active = sw.robot is not None
        self.robot = cast(sim.Agent, sw.robot)  # used only while robot_in
        self.contacts = _initial_contacts(self.spec, sw) if self.robot_in else set()
        driver = self.driver
        stretches = self.stretches
        config = sim.RecordConfig(pose=True, twist=driver is not None,
                                  collisions=stretches and self.robot_in)
        rec = sim.ExperimentalRun(sw.world, time_step=DT, steps=MAX_STEPS,
                                  terminate_when_all_idle_or_stuck=False,
                                  record_config=config, seed=0)
        rec.start()
        if stretches:  # records every step, in World.update and World.run alike
            sw.world.add_callback(rec.update)
        self.rec = rec
        exits_crossed = layer.buf[0]
        n_active, step = n, 0
        robot_start = pos[0, n] if self.robot_in else self.no_robot
        layer.step(0.0, pos[0, :n], active, robot_start, robot_start, self.robot_in)
        if driver is not None:
            agents = sw.world.agents
            self._drive(1, np.array([[*a.position, a.orientation] for a in agents], np.float32),
                        np.array([[*a.velocity, a.angular_speed] for a in agents], np.float32))
        # the hot loop: locals only (an attribute lookup costs ~30 ns, a call ~100 ns,
        # a kernel argument ~80 ns)
        update, packed, flags = sw.world.update, layer.packed_state, tr.flags
        record = None if stretches else rec.update
        world, peds, goal, fracs, arrival_step = sw.world, sw.peds, self.goal, self.fracs, \
            tr.arrival_step
        prm, fst, ist, speed = layer.prm, layer.fst, layer.ist, self.spec.robot_speed
        driver_quiet, next_check = self.driver_quiet, 0
        sensed, sensed_ids, views = self.sensed, self.sensed_ids, self.sensed_views
        robot_pose = self.robot_pose
        robot_in = robot_active = self.robot_in
        while True:
            if flags is not None:
                flags[step] = layer.flags
            if step == MAX_STEPS or (n_active == 0 and not robot_active):
                break
            if stretches and step >= next_check and not self.contacts and (
                    driver_quiet is None or not robot_active or driver_quiet()):
                k = quiet_steps(step, pos, robot_in, robot_active, speed, goal, active, prm,
                                fst, ist, MAX_STEPS - 1 - step)
                if k:
                    self._stretch(step, k, robot_in, robot_active)
                    step += k
                    continue
                next_check = step + RECHECK_STEPS
            update(DT)
            if record is not None:
                record()
            step += 1
            if robot_in:
                collisions = world.collisions
                if collisions or self.contacts:
                    robot_active = self._robot_contacts(step, collisions)
            if driver is None:
                k, s, n_speed, n_target = advance(step, rec.poses[-1], pos, robot_in,
                                                  robot_active, goal, active, fracs,
                                                  arrival_step, *packed)
                m = -1
            else:  # and what the driver senses before the next step, if it decides then
                k, s, n_speed, n_target, m = advance_driven(
                    step, rec.poses, pos, robot_in, robot_active, goal, active, fracs,
                    arrival_step, *packed, sensed, sensed_ids, robot_pose)
            if k:
                for i in exits_crossed[:k]:
                    remove_agent(peds[i], int(i))
                n_active -= k
            if s >= 0.0:
                self._robot_arrived(step, s)
                robot_in = robot_active = False
            if n_speed or n_target:
                layer.write(n_speed, n_target)
            if m >= 0:
                if m:
                    sense_velocities(rec.twists[-1], sensed, sensed_ids, m)
                driver.step(step + 1, robot_pose, *views[m])  # type: ignore[union-attr]
        tr.steps = step
        if tr.has_robot and tr.outcome == "none":
            tr.outcome, tr.outcome_step = "timeout", step
        if tr.has_robot and tr.robot_last_step < 0:
            tr.robot_last_step = step
        if self.record:
            tr.poses = np.concatenate([self.initial_poses[None], np.array(rec.poses)[:step]])
        return tr

    def _stretch(self, step: int, k: int, robot_in: bool, robot_active: bool) -> None:
        """Steps ``step`` + 1 … ``step`` + k in navground's loop, then the loop's kernel
        over their recorded poses; :class:`NotQuiet` if one of them needed the loop."""
        rec = self.rec
        touched_before = len(rec.collisions) if robot_in else 0
        self.world.run(k, DT)
        quiet = replay_quiet(step, rec.poses[-k:], self.pos, robot_in, robot_active, self.goal,
                             self.active, self.fracs, self.trace.arrival_step,
                             *self.layer.packed_state, self.driver is not None and robot_active,
                             self.sensed, self.sensed_ids)
        if not quiet or (robot_in and robot_touched(rec.collisions, touched_before,
                                                    self.robot._uid)):
            raise NotQuiet

    def _drive(self, upcoming: int, poses: np.ndarray, twists: np.ndarray) -> None:
        """The driver's decision for navground step ``upcoming``, from the float32
        poses and twists (agents, 3) that the step's sensing will read. (Not named
        ``step``: an error is dated by the loop's ``step``, as one raised by a
        behaviour during that navground step would be.)"""
        n, sensed, ids = self.n, self.sensed, self.sensed_ids
        m = sense_neighbors(poses, twists, n, self.active, ROBOT_SENSING_RANGE, sensed, ids)
        self.driver.step(upcoming, poses[n], sensed[:m], ids[:m])  # type: ignore[union-attr]

    def _robot_contacts(self, step: int, collisions) -> bool:
        """Robot contacts of step ``step`` (``collisions``: the world's pairs), called
        while the robot is in the scene and there are contacts now or the step
        before; the first one stops the robot. Returns whether it is still active."""
        self.contacts = self._count_contacts(step, collisions)
        if self.robot_active and self.trace.outcome_step == step:
            self.robot_active = False
            stop_agent(self.robot)
        return self.robot_active

    def _robot_arrived(self, step: int, s: float) -> None:
        """Success during ``step``, a fraction ``s`` into it: the robot leaves the scene."""
        tr = self.trace
        tr.outcome, tr.outcome_step, tr.outcome_frac = "success", step, s
        tr.robot_last_step = step
        self.robot_active = self.robot_in = False
        remove_agent(self.robot, self.n)

    def _count_contacts(self, step: int, collisions) -> set:
        """Count new robot contacts this step; set the outcome on the first one."""
        tr = self.trace
        uid = self.robot._uid
        now: dict[int, bool] = {}
        for e1, e2 in collisions:
            if e1._uid == uid:
                now[e2._uid] = isinstance(e2, sim.Agent)
            elif e2._uid == uid:
                now[e1._uid] = isinstance(e1, sim.Agent)
        new = [is_ped for other, is_ped in now.items() if other not in self.contacts]
        tr.ped_collisions += sum(new)
        tr.world_collisions += len(new) - sum(new)
        if new and self.robot_active:
            tr.outcome = "pedestrian_collision" if any(new) else "world_collision"
            tr.outcome_step = step
            # who moved into whom: read once, on the event (the robot stops right after)
            tr.contact_speed = float(np.hypot(*self.robot.velocity))
        return set(now)


@njit(cache=True)
def advance_driven(step, record, pos, robot_on, robot_active, goal, active, fracs, arrival_step,
                   prm, fst, ist, buf, consts, walls, obstacles, sensed, sensed_ids, robot_pose):
    """:func:`.pedestrians.advance` on the last row of the poses ``record`` (steps,
    agents, 3), then, if the loop driver decides before the next step (the robot is
    still active and the run goes on), what it senses: the robot's pose into
    ``robot_pose`` (3,) and the sensed pedestrians' positions into ``sensed`` and
    ``sensed_ids`` (:func:`.controllers._geometry.sense_positions`). Returns
    :func:`advance`'s four values and the number sensed, or −1 when no decision is due.
    One call instead of three: each call and each argument costs the loop time."""
    poses = record[record.shape[0] - 1]
    k, s, n_speed, n_target = advance(step, poses, pos, robot_on, robot_active, goal, active,
                                      fracs, arrival_step, prm, fst, ist, buf, consts, walls,
                                      obstacles)
    m = -1
    if robot_active and s < 0.0 and step < MAX_STEPS:
        n = active.shape[0]
        robot_pose[:] = poses[n]
        m = sense_positions(poses, n, active, ROBOT_SENSING_RANGE, sensed, sensed_ids)
    return k, s, n_speed, n_target, m


def _initial_contacts(spec: EpisodeSpec, sw: SimWorld) -> set:
    """Uids of entities the robot overlaps at t = 0 (their contact is not an event)."""
    r = np.asarray(spec.robot_start, dtype=float)
    out = set()
    for k, p in enumerate(spec.ped_starts):
        if math.dist(p, r) < ROBOT_RADIUS + PED_RADIUS:
            out.add(sw.peds[k]._uid)
    for wall, d in zip(sw.world.walls, _wall_distances(r, spec.walls), strict=True):
        if d < ROBOT_RADIUS:
            out.add(wall._uid)
    for obstacle, (x, y, rad) in zip(sw.world.obstacles, spec.obstacles, strict=True):
        if math.dist((x, y), r) < rad + ROBOT_RADIUS:
            out.add(obstacle._uid)
    return out


def _wall_distances(point: np.ndarray, walls) -> np.ndarray:
    """(W,) [m] distance from ``point`` (2,) to each wall segment (x0, y0, x1, y1).

    The arithmetic of :func:`popnavshift.episodes.scenes.distance_to_walls`, which
    gives only the nearest wall.
    """
    w = np.asarray(walls, dtype=float).reshape(-1, 4)
    a, ab = w[:, 0:2], w[:, 2:4] - w[:, 0:2]
    t = np.clip(np.sum((point - a) * ab, axis=1) / np.sum(ab * ab, axis=1), 0.0, 1.0)
    return np.linalg.norm(point - (a + t[:, None] * ab), axis=1)

