"""Simulate one episode: the stepping loop, the robot's outcome and the run's metrics.

``simulate(spec, slots, controller, backend)`` → :class:`SimResult` with one run row
and one row per pedestrian (SPEC §6–7). The loop steps navground at ``DT`` for at
most 45 s and stops early once the robot is done (or absent) and every pedestrian
has left the scene. Outcome = the robot's first event:

* ``success``: within 0.3 m of its goal; the robot then leaves the scene;
* ``pedestrian_collision`` / ``world_collision``: a new robot contact with a
  pedestrian / a wall or obstacle (both in one step counts as pedestrian); the
  robot then stops in place and pedestrians carry on;
* ``timeout``: none of these within 45 s;
* ``controller_error``: the controller raised (:class:`ControllerError`); recorded by
  the study engine with :func:`failed_result`, not by :func:`simulate`.

Without a robot the outcome is ``none`` and robot metrics are NaN.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field
from typing import Any, cast

import numpy as np
import pandas as pd
from navground import sim
from numba import njit

from ..episodes.specs import PED_RADIUS, EpisodeSpec
from ..errors import ConfigError, PopNavShiftError
from ..tables import PARAMS
from .controllers import CONTROLLERS, GOAL_TOLERANCE, ROBOT_RADIUS, ROBOT_SENSING_RANGE, LoopDriver
from .controllers._rollout import sense_neighbors
from .pedestrians import BACKENDS, ResponseLayer, advance
from .quiet import NotQuiet, quiet_steps, replay_quiet, robot_touched
from .slots import SlotProfiles, slot_profiles
from .world import DT, MAX_STEPS, SimWorld, build_world, remove_agent, stop_agent

V_STOP = 0.05  # [m/s] an agent moving slower than this is stopped
TIME_LIMIT = MAX_STEPS * DT  # [s] travel time of a failed robot run
RECHECK_STEPS = 5  # after a step that could not start a quiet stretch, test again this later


@dataclass
class SimResult:
    """``run``: one row (dict); ``ped_columns``: one row per slot, as columns;
    ``trajectory``: replay arrays. :attr:`pedestrians` is the DataFrame of
    ``ped_columns``; the study engine joins the columns of a whole batch into one
    table instead (:func:`pedestrian_table`), a DataFrame per run costs ~1 ms."""

    run: dict
    ped_columns: dict
    trajectory: dict | None = None

    @functools.cached_property
    def pedestrians(self) -> pd.DataFrame:
        return pedestrian_table([self.ped_columns])


def pedestrian_table(columns: list[dict], keys: dict[str, list] | None = None) -> pd.DataFrame:
    """One DataFrame from the ``ped_columns`` of several runs, plus ``keys``: extra
    columns with one value per run (repeated over its pedestrians)."""
    sizes = [len(c["slot"]) for c in columns]
    table: dict[str, Any] = {}
    for name in columns[0] if columns else _PED_COLUMNS:
        parts = [c[name] for c in columns]
        if name in _PER_RUN:
            table[name] = pd.Series(np.repeat(np.array(parts, dtype=object), sizes), dtype=str)
        elif name == "persona_id":
            table[name] = pd.Series([x for part in parts for x in part], dtype=str)
        else:
            table[name] = np.concatenate(parts) if parts else np.empty(0)
    for name, values in (keys or {}).items():
        array = np.asarray(values)  # ints stay int64 (seed_set); text stays Python str
        table[name] = np.repeat(array.astype(object) if array.dtype.kind in "US" else array, sizes)
    return pd.DataFrame(table)


def simulate(
    spec: EpisodeSpec,
    slots: pd.DataFrame | SlotProfiles | None,
    controller,
    backend: str = "orca",
    *,
    record: bool = False,
    stretches: bool = True,
) -> SimResult:
    """Run ``spec`` with slot profiles ``slots`` (see :func:`episodes.assign_slots`).

    ``slots`` None gives every pedestrian the mid-range profile; a
    :class:`SlotProfiles` is used as it is. ``controller`` is a
    controller id (see :func:`resolve_controller`), a ControllerFactory, or
    None/"none" for the no-robot baseline. ``record`` adds a trajectory for replays.
    ``stretches`` False steps every step from Python (:mod:`.quiet` lets navground
    run the steps that need nothing from the loop; the results are the same).
    Raises :class:`ControllerError` when the controller raises (see
    :func:`failed_result` for the row a study records instead).
    """
    profiles, persona_ids = slot_profiles(spec, slots)
    factory, controller_name = resolve_controller(controller)
    ped_backend = BACKENDS.make(backend)
    try:
        trace = _run(spec, profiles, factory, controller_name, ped_backend, record,
                     stretches=stretches and not record)
    except NotQuiet:  # a quiet stretch was not: the run again, step by step
        trace = _run(spec, profiles, factory, controller_name, ped_backend, record,
                     stretches=False)
    run = {
        **_episode_columns(spec),
        "controller": controller_name,
        "backend": backend,
        "outcome": trace.outcome,
        **robot_metrics(trace),
        "peds_arrived": int(np.sum(trace.arrival_step >= 0)),
        "steps": trace.steps,
    }
    peds = _pedestrian_columns(spec, controller_name, backend, trace, profiles, persona_ids)
    return SimResult(run, peds, trace.trajectory(spec) if record else None)


def _run(spec: EpisodeSpec, profiles: np.ndarray, factory, controller_name: str,
         ped_backend, record: bool, stretches: bool) -> _Trace:
    """Build the run's world and step it; a controller's exception becomes a
    :class:`ControllerError`."""
    sw: SimWorld | None = None
    driver: LoopDriver | None = None
    try:
        if hasattr(factory, "loop_driver"):
            driver = factory.loop_driver()
        sw = build_world(spec, profiles[:, 0], driver or factory, ped_backend)
        if driver is not None:  # navground hands behaviours its float32 time step
            driver.start(cast(sim.Agent, sw.robot), sw.world, float(np.float32(DT)))
        layer = ResponseLayer(sw.ped_behaviors, spec, profiles, ROBOT_RADIUS)
        return _Loop(spec, sw, layer, driver, record, stretches).execute()
    except NotQuiet:
        raise
    except Exception as exc:
        robot = sw.robot_behavior if sw is not None else None
        blamed = _blame_controller(exc, controller_name, (factory, robot, driver))
        if blamed is None:
            raise
        raise blamed from exc
    finally:  # the recording callback (see _Loop.execute) would keep world and run alive:
        if sw is not None:  # a reference cycle through C++ that Python cannot collect
            sw.world.reset_callbacks()


def _episode_columns(spec: EpisodeSpec) -> dict:
    return {
        "episode": spec.id,
        "scene": spec.scene,
        "width": spec.width,
        "density": spec.density,
        "robot_speed": spec.robot_speed,
        "variant": spec.variant,
        "n_peds": spec.n_peds,
    }


_PER_RUN = ("episode", "controller", "backend")  # one value per run in ped_columns
_PED_COLUMNS = (*_PER_RUN, "slot", "persona_id", "arrived", "travel_time", "walk_distance",
                "stop_time", "detour", "min_robot_clearance", *PARAMS)


def _pedestrian_columns(spec: EpisodeSpec, controller: str, backend: str, trace: _Trace,
                        profiles: np.ndarray, persona_ids: list[str]) -> dict:
    """The run's pedestrian rows as columns (see :func:`pedestrian_table`)."""
    columns = {
        "episode": spec.id,
        "controller": controller,
        "backend": backend,
        "slot": np.arange(len(persona_ids), dtype=np.int64),
        "persona_id": persona_ids,
        **pedestrian_metrics(trace),
        **{p: profiles[:, j] for j, p in enumerate(PARAMS)},
    }
    assert tuple(columns) == _PED_COLUMNS
    return columns


def resolve_controller(controller):
    """(factory or None, name) for a controller id (a registered name, an entry point or
    ``package.module:Class``, optionally with JSON parameters; see
    :mod:`popnavshift.sim.controllers.registry`), a factory object, or None/"none"."""
    if controller is None or controller == "none":
        return None, "none"
    if isinstance(controller, str):
        return CONTROLLERS.make(controller), controller
    if not (hasattr(controller, "build") and hasattr(controller, "after_placement")):
        raise ConfigError(
            "controller must be a name, a ControllerFactory or None, "
            f"got {type(controller).__name__}"
        )
    return controller, str(getattr(controller, "name", type(controller).__name__))


class ControllerError(PopNavShiftError):
    """The robot's controller raised while it was built, placed or stepped."""


def _blame_controller(exc: Exception, controller_name: str,
                      suspects: tuple) -> ControllerError | None:
    """A ControllerError for ``exc`` if a method of one of ``suspects`` (the
    controller factory, the robot's behaviour) is on its traceback; else None:
    the error is ours and must crash. Configuration errors are never a run outcome."""
    if isinstance(exc, PopNavShiftError):
        return None
    blamed, step = False, None
    tb = exc.__traceback__
    while tb is not None:
        owner = tb.tb_frame.f_locals.get("self")
        blamed = blamed or any(owner is s for s in suspects if s is not None)
        if isinstance(owner, _Loop) and "step" in tb.tb_frame.f_locals:
            step = tb.tb_frame.f_locals["step"]
        tb = tb.tb_next
    if not blamed:
        return None
    when = "while building the robot" if step is None else f"at t = {step * DT:.1f} s"
    return ControllerError(
        f"controller {controller_name!r} raised {type(exc).__name__} {when}: {exc}")


def failed_result(spec: EpisodeSpec, controller: str, backend: str) -> SimResult:
    """The result recorded for a run whose controller raised: outcome
    ``controller_error``, robot time the 45 s of a failure, other robot metrics NaN,
    no pedestrian rows (their run did not finish)."""
    empty = _Trace(0, np.zeros((1, 0, 2)), 0, np.zeros(0, np.int64), np.ones(0), False)
    run = {
        **_episode_columns(spec),
        "controller": controller,
        "backend": backend,
        "outcome": "controller_error",
        **robot_metrics(empty),
        "robot_time": TIME_LIMIT,
        "peds_arrived": 0,
        "steps": 0,
    }
    peds = _pedestrian_columns(spec, controller, backend, empty, np.zeros((0, len(PARAMS))), [])
    return SimResult(run, peds)


@dataclass
class _Trace:
    """What the loop records (positions [m] per step; agent n is the robot)."""

    n: int
    pos: np.ndarray  # (steps + 1, n [+ 1], 2)
    steps: int
    arrival_step: np.ndarray  # (n,) step during which the exit was crossed, −1 if never
    arrival_frac: np.ndarray  # (n,) fraction of that step before the crossing
    has_robot: bool
    outcome: str = "none"
    outcome_step: int = -1
    outcome_frac: float = 1.0
    robot_last_step: int = -1  # last step the robot is in the scene
    ped_collisions: int = 0
    world_collisions: int = 0
    flags: np.ndarray | None = None
    poses: np.ndarray | None = field(default=None, repr=False)
    measured: dict | None = field(default=None, repr=False)  # see _measure

    def trajectory(self, spec: EpisodeSpec) -> dict:
        """Replay arrays: poses (x, y, θ) per step, NaN once an agent has left the scene."""
        T, n = self.steps, self.n
        assert self.poses is not None
        ped = self.poses[:, :n].copy()
        left = np.arange(T + 1)[:, None] > np.where(self.arrival_step >= 0, self.arrival_step, T)
        ped[left] = np.nan
        flags = self.flags[: T + 1] if self.flags is not None else np.zeros((T + 1, n), np.uint8)
        robot = None
        if self.has_robot:
            robot = self.poses[:, n].copy()
            robot[self.robot_last_step + 1:] = np.nan
        return {
            "time": np.arange(T + 1) * DT,
            "ped_pose": ped,
            "robot_pose": robot,
            "ped_flags": flags,
            "flag_bits": {"reacting": 1, "yielding": 2, "detouring": 4},
            "walls": np.asarray(spec.walls, dtype=float).reshape(-1, 4),
            "obstacles": np.asarray(spec.obstacles, dtype=float).reshape(-1, 3),
            "ped_radius": PED_RADIUS,
            "robot_radius": ROBOT_RADIUS,
            "robot_goal": np.asarray(spec.robot_goal, dtype=float),
            "arrival_step": self.arrival_step.copy(),
        }


class _Loop:
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
        self.goal = np.array([*spec.robot_goal, GOAL_TOLERANCE], dtype=np.float64)
        self.active = np.ones(n, dtype=np.bool_)
        self.no_robot = np.zeros(2)
        # row 0: exit-crossing fractions of the current step (scratch); row 1: of
        # each pedestrian's crossing step (1 until it crosses)
        self.fracs = np.zeros((2, n))
        self.fracs[1] = 1.0
        self.trace = _Trace(n, self.pos, 0, np.full(n, -1, np.int64), self.fracs[1],
                            sw.robot is not None)
        if record:
            self.trace.flags = np.zeros((MAX_STEPS + 1, n), np.uint8)
            self.initial_poses = np.array(
                [[*a.position, a.orientation] for a in sw.world.agents], dtype=np.float64
            ).reshape(na, 3)
        # what the driver senses: the neighbours' rows and slots
        self.sensed = np.empty((n, 5))
        self.sensed_ids = np.empty(n, np.int64)

    def execute(self) -> _Trace:
        """Step until the limit, or until the robot is done (or absent) and all peds left.

        Per step: navground update, robot contacts, then one :func:`advance` kernel
        call (poses, exits, goal entry, response layer) and its navground writes.
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
            poses = rec.poses[-1]
            k, s, n_speed, n_target = advance(step, poses, pos, robot_in, robot_active, goal,
                                              active, fracs, arrival_step, *packed)
            if k:
                for i in exits_crossed[:k]:
                    remove_agent(peds[i], int(i))
                n_active -= k
            if s >= 0.0:
                self._robot_arrived(step, s)
                robot_in = robot_active = False
            if n_speed or n_target:
                layer.write(n_speed, n_target)
            if driver is not None and robot_active and step < MAX_STEPS:
                self._drive(step + 1, poses, rec.twists[-1])
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
        return set(now)


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


# ---- metrics, from the trace (positions per step) ----


def _step_lengths(xy: np.ndarray) -> np.ndarray:
    """Distance [m] moved during each step: (T + 1, ...) positions → (T, ...)."""
    return np.linalg.norm(np.diff(xy, axis=0), axis=-1)


def pedestrian_travel_time(tr: _Trace) -> np.ndarray:
    """(n,) [s] from t = 0 to the (interpolated) exit crossing; NaN if never arrived."""
    arrived = tr.arrival_step >= 0
    return np.where(arrived, (tr.arrival_step - 1 + tr.arrival_frac) * DT, np.nan)


@njit(cache=True)
def _metrics(pos, n, steps, arrival_step, arrival_frac, has_robot, robot_last, outcome_step,
             v_stop_step, walked, stop_steps, detour, min_clear):
    """Per-pedestrian metrics and the robot's minimum clearance, in one pass over the
    trace (arithmetic and summation order as numpy's row-by-row reductions, so the
    values are those of the per-metric formulas in the docstrings above).

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


def _measure(tr: _Trace) -> dict:
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


def pedestrian_metrics(tr: _Trace) -> dict[str, np.ndarray]:
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


def robot_metrics(tr: _Trace) -> dict:
    """Robot columns of the run row; NaN (counts 0) without a robot.

    Over the robot's active period, t = 0 to its outcome: ``robot_time`` [s] (the
    success time, else the 45 s limit), ``outcome_time`` [s], ``robot_path_length``
    [m], ``robot_stop_time`` [s] (slower than V_STOP), ``robot_min_clearance`` [m]
    (to any pedestrian, centre distance minus radii). Collision counts are new
    contact events (a contact lasting several steps counts once) over the whole run.
    """
    out = {
        "robot_time": np.nan,
        "outcome_time": np.nan,
        "robot_path_length": np.nan,
        "robot_stop_time": np.nan,
        "robot_min_clearance": np.nan,
        "ped_collisions": tr.ped_collisions,
        "world_collisions": tr.world_collisions,
    }
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
