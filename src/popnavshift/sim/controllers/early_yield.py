"""``early_yield``: see a conflict early, pull aside, let the pedestrian pass.

Paper §III-F: "detects conflicts over a 4.5 s horizon, moves toward a clear
pull-aside pose with a 0.16 m buffer, and waits while the pedestrian crosses
the conflict region". A Python behaviour wraps a C++ ORCA (notes §4: sensing
fills the inner state, each step copies the outer state into it) and runs a
three-state machine:

* GO — the inner ORCA drives to the goal. A *conflict* is a neighbour that
  moves (>= ``MIN_PED_SPEED``), crosses or comes towards the robot (heading
  more than 60 deg off the robot's; same-way walkers are ORCA's to overtake),
  and whose closest approach to the robot, both at constant velocity (the
  robot at its cell speed towards the goal), within ``conflict_horizon`` (cut
  at the time to reach the goal) is below the radii plus ``buffer``. Any
  conflict: pick a pull-aside point (:func:`._yielding.pull_aside_point`) →
  PULL_ASIDE.
* PULL_ASIDE — the inner ORCA drives to that point; on arrival (or after
  ``pull_aside_timeout``) → WAIT.
* WAIT — zero twist.

From PULL_ASIDE or WAIT the robot returns to GO as soon as no conflict is
predicted any more (the pedestrian has crossed the conflict region and is
separating), with a hysteresis of ``EXIT_HYSTERESIS`` on the distance test.
A yield lasts at most ``max_wait``; the pedestrians still in conflict then are
not yielded to again (the inner ORCA still avoids them), so crowds cannot hold
the robot forever. The behaviour's own target stays the goal throughout, so
arrival is judged against the goal (notes §3).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any, SupportsFloat, cast

import numpy as np
from navground import core, sim

from ._geometry import neighbors_array, static_arrays
from ._params import Param, require_two_wheels, resolve_params
from ._yielding import conflicting, pull_aside_point
from .robot_orca import break_symmetry, configure_orca, first_command_workaround

GO, PULL_ASIDE, WAIT = "go", "pull_aside", "wait"

PARAMS: dict[str, Param] = {
    "conflict_horizon": Param(4.5, 0.5, 20.0, doc="closest-approach horizon [s]"),
    "buffer": Param(0.16, 0.0, 1.0,
                    doc="clearance beyond the radii [m]: conflict test and pull-aside point"),
    "max_wait": Param(8.0, 0.5, 45.0, doc="longest yield (pull aside + wait) [s]"),
    "pull_aside_timeout": Param(3.0, 0.2, 20.0, doc="longest drive to the pull-aside point [s]"),
    "horizon": Param(5.0, 0.5, 50.0, doc="inner ORCA spatial horizon [m]"),
    "safety_margin": Param(0.12, 0.0, 1.0, doc="inner ORCA safety margin [m]"),
    "time_horizon": Param(2.0, 0.1, 30.0, doc="inner ORCA tau against agents [s]"),
    "static_time_horizon": Param(1.0, 0.1, 30.0, doc="inner ORCA tau against walls [s]"),
}
MIN_PED_SPEED = 0.1  # [m/s] slower neighbours are obstacles for ORCA, not crossers to wait for
SAME_WAY_COS = 0.5  # heading within 60 deg of the robot's: walking its way, ORCA overtakes
EXIT_HYSTERESIS = 0.1  # [m] extra distance required to end a yield
ASIDE_FORWARD = 0.5  # [m] pull-aside point ahead along the path (a diff-drive cannot slide)
ASIDE_STEP, ASIDE_MAX = 0.1, 2.0  # [m] lateral offsets scanned per side
ASIDE_TOLERANCE = 0.1  # [m] the pull-aside point counts as reached within this distance
NAME = "early_yield"
NAVGROUND_NAME = "PopNavShiftEarlyYield"  # the behaviour's navground type name


class YieldMachine:
    """The GO / PULL_ASIDE / WAIT state machine, fed with the sensed neighbours
    by whichever runs it (:class:`EarlyYieldBehavior` or :class:`EarlyYieldDriver`).

    :attr:`phase` is the state, :attr:`aside_point` the current pull-aside point
    [m] (None in GO and when waiting in place), :attr:`yields` the number of
    yields started (diagnostics). :attr:`static` holds the walls and discs.
    """

    def __init__(self, params: dict[str, Any], radius: float, speed: float,
                 static: tuple[np.ndarray, np.ndarray]) -> None:
        self.params, self.radius, self.speed, self.static = params, radius, speed, static
        self._horizon = params["conflict_horizon"]
        self._mask = np.empty(64, dtype=np.bool_)  # reused by the conflict test
        self.phase = GO
        self._step = self._phase_start = self._yield_start = 0
        self.aside_point: tuple[float, float] | None = None
        self._ignored: set[int] = set()
        self.yields = 0

    def _enter(self, phase: str) -> None:
        self.phase, self._phase_start = phase, self._step
        if phase == GO:
            self.aside_point = None

    def _conflicts(self, x: float, y: float, gx: float, gy: float, peds: np.ndarray,
                   ids: Sequence[int] | np.ndarray, margin: float) -> np.ndarray | None:
        """Boolean mask (N,) of neighbours in conflict, ignored ones excluded; None
        for no conflict (the common case, answered without a mask operation)."""
        n = len(ids)
        dx, dy = gx - x, gy - y
        dist = math.hypot(dx, dy)
        if not n or dist <= 0.0 or self.speed <= 0.0:
            return None
        horizon = min(self._horizon, dist / self.speed)
        mask = self._mask[:n] if n <= len(self._mask) else np.empty(n, dtype=np.bool_)
        if not conflicting(x, y, self.speed * dx / dist, self.speed * dy / dist, self.radius,
                           peds, horizon, margin, MIN_PED_SPEED, SAME_WAY_COS, mask):
            return None
        if self._ignored:
            mask &= np.array([pid not in self._ignored for pid in ids], dtype=np.bool_)
            if not mask.any():
                return None
        return mask.copy()

    def _start_yield(self, x: float, y: float, gx: float, gy: float, peds: np.ndarray,
                     conflict: np.ndarray) -> None:
        walls, discs = self.static
        dx, dy = gx - x, gy - y
        norm = math.hypot(dx, dy) or 1.0
        qx, qy, kind = pull_aside_point(
            x, y, dx / norm, dy / norm, self.radius, self.params["buffer"], peds,
            conflict, walls, discs, self.params["conflict_horizon"], ASIDE_FORWARD,
            ASIDE_STEP, ASIDE_MAX)
        self.yields += 1
        self._yield_start = self._step
        self._enter(WAIT if kind == 2 else PULL_ASIDE)  # 2: nowhere to go, wait here
        self.aside_point = None if kind == 2 else (qx, qy)

    def update(self, step: int, x: float, y: float, gx: float, gy: float, peds: np.ndarray,
               ids: Sequence[int] | np.ndarray, dt: float) -> str:
        """The phase for control step ``step`` (counted from 1) of the robot at
        (x, y) heading to (gx, gy), among neighbours ``peds`` (N, 5) with ids ``ids``."""
        self._step = step
        buffer = self.params["buffer"]
        if self.phase == GO:
            conflict = self._conflicts(x, y, gx, gy, peds, ids, buffer)
            if conflict is not None:
                self._start_yield(x, y, gx, gy, peds, conflict)
            return self.phase
        still = self._conflicts(x, y, gx, gy, peds, ids, buffer + EXIT_HYSTERESIS)
        if still is None:
            self._enter(GO)
        elif (step - self._yield_start) * dt >= self.params["max_wait"]:
            self._ignored.update(int(pid) for pid, c in zip(ids, still, strict=True) if c)
            self._enter(GO)
        elif self.phase == PULL_ASIDE:
            assert self.aside_point is not None
            near = math.hypot(self.aside_point[0] - x, self.aside_point[1] - y)
            late = (step - self._phase_start) * dt >= self.params["pull_aside_timeout"]
            if near <= ASIDE_TOLERANCE or late:
                self._enter(WAIT)
        return self.phase


def aside_target(point: tuple[float, float]) -> core.Target:
    return core.Target.Point(point, ASIDE_TOLERANCE / 2)


class EarlyYieldBehavior(core.Behavior, name=NAVGROUND_NAME):
    """The early-yielding controller as a navground behaviour: a Python wrapper
    around a C++ ORCA (:attr:`inner`) driven by a :class:`YieldMachine`
    (:attr:`machine`; :attr:`phase` and :attr:`yields` are its diagnostics)."""

    def __init__(self, kinematics: core.Kinematics | None = None, radius: float = 0.0,
                 **params: Any) -> None:
        core.Behavior.__init__(self, kinematics, radius)
        self.params = resolve_params(NAME, PARAMS, params)
        self.inner = inner_orca(kinematics, radius, self.params)
        self.horizon = self.params["horizon"]
        self.safety_margin = self.params["safety_margin"]
        # The inner ORCA's state, cached: the property costs ~6 us per read.
        self._state = cast(core.GeometricState, self.inner.environment_state)
        self.machine: YieldMachine | None = None
        self._step = 0

    @property
    def phase(self) -> str:
        return GO if self.machine is None else self.machine.phase

    @property
    def yields(self) -> int:
        return 0 if self.machine is None else self.machine.yields

    def get_environment_state(self) -> core.GeometricState:
        return self._state  # sensing fills the inner ORCA's state directly

    def compute_cmd_internal(self, time_step: SupportsFloat) -> core.Twist2:
        time_step = float(time_step)
        self._step += 1
        inner = self.inner
        inner.set_state_from(self)  # pose, twist, target (the goal), speeds, margin
        goal = self.get_target_position(_ABSOLUTE)
        if goal is None:  # arrived: the inner ORCA brakes
            return inner.compute_cmd(time_step)
        if self.machine is None:  # bounded sensing set walls and discs once, in prepare
            self.machine = YieldMachine(self.params, float(self.radius),
                                        float(self.optimal_speed), static_arrays(self._state))
        x, y = self.position.tolist()
        gx, gy = goal.tolist()
        peds, ids = neighbors_array(self._state)
        phase = self.machine.update(self._step, x, y, gx, gy, peds, ids, time_step)
        if phase == WAIT:
            return _ZERO_TWIST
        if phase == PULL_ASIDE:
            assert self.machine.aside_point is not None
            inner.target = aside_target(self.machine.aside_point)
        return inner.compute_cmd(time_step)


def inner_orca(kinematics: core.Kinematics | None, radius: float,
               params: dict[str, Any]) -> core.behaviors.ORCABehavior:
    """The ORCA that drives between yields (effective centre off, as ``robot_orca``)."""
    orca = core.behaviors.ORCABehavior(kinematics, radius)
    configure_orca(orca, {**params, "effective_center": False})
    return orca


class EarlyYieldDriver:
    """The early-yielding controller on the stepping loop's fast path (see
    :class:`..LoopDriver`). The robot's behaviour is the C++ ORCA itself, set up
    as :class:`EarlyYieldBehavior`'s inner one; the :class:`YieldMachine` runs
    on the loop's sensed neighbours and touches navground only when the phase
    or the pull-aside point changes: the ORCA target (goal or pull-aside point),
    or a manual zero command while waiting. Same inputs and the same machine as
    the behaviour, so the same run."""

    sensing = True  # the ORCA senses for itself

    def __init__(self, params: dict[str, Any]) -> None:
        self.params = params
        self.machine: YieldMachine | None = None

    def build(self, kinematics: core.Kinematics, radius: float, speed: float) -> core.Behavior:
        require_two_wheels(NAME, kinematics)
        orca = inner_orca(kinematics, radius, self.params)
        orca.horizon = self.params["horizon"]
        orca.safety_margin = self.params["safety_margin"]
        orca.optimal_speed = speed
        orca.heading_behavior = core.Behavior.Heading.velocity
        return orca

    def after_placement(self, behavior: core.Behavior, dt: float) -> None:
        break_symmetry(behavior)
        first_command_workaround(behavior, dt)

    def start(self, robot: sim.Agent, world: sim.World, dt: float) -> None:
        self._behavior = cast(core.Behavior, robot.behavior)
        self._controller = robot.controller
        target = self._behavior.target  # the goal, shifted by break_symmetry
        gx, gy = cast(np.ndarray, target.position).tolist()
        self._goal = (gx, gy)
        self._goal_target = core.Target.Point(self._goal, target.position_tolerance)
        self._dt = dt
        self.machine = YieldMachine(self.params, float(self._behavior.radius),
                                    float(self._behavior.optimal_speed), static_arrays(world))

    def quiet(self) -> bool:
        """Whether a step with nobody sensed changes nothing (see :class:`..LoopDriver`)."""
        return cast(YieldMachine, self.machine).phase == GO

    def step(self, step: int, pose: np.ndarray, peds: np.ndarray, ids: np.ndarray) -> None:
        m = cast(YieldMachine, self.machine)
        if m.phase == GO and not len(ids):
            return  # going, nobody sensed: the machine would stay in GO and change nothing
        before = (m.phase, m.aside_point)
        x, y = pose[:2].tolist()
        gx, gy = self._goal
        m.update(step, x, y, gx, gy, peds, ids, self._dt)
        if (m.phase, m.aside_point) == before:
            return
        if m.phase == WAIT:
            self._controller.follow_manual_cmd(_ZERO_TWIST)
            return
        if before[0] == WAIT:
            self._controller.stop()  # back to the ORCA
        self._behavior.target = (self._goal_target if m.phase == GO
                                 else aside_target(cast(tuple, m.aside_point)))


_ABSOLUTE = core.Frame.absolute  # enum lookups cost 0.1 us
_ZERO_TWIST = core.Twist2((0.0, 0.0), 0.0, core.Frame.relative)


class EarlyYield:
    """Factory of :class:`EarlyYieldBehavior` (registered as ``early_yield``); the
    stepping loop runs it as :class:`EarlyYieldDriver`."""

    name = NAME

    def __init__(self, **params: Any) -> None:
        self.params = resolve_params(self.name, PARAMS, params)

    def build(self, kinematics: core.Kinematics, radius: float, speed: float) -> core.Behavior:
        require_two_wheels(self.name, kinematics)
        behavior = EarlyYieldBehavior(kinematics, radius, **self.params)
        behavior.optimal_speed = speed
        behavior.heading_behavior = core.Behavior.Heading.velocity
        return behavior

    def after_placement(self, behavior: core.Behavior, dt: float) -> None:
        """The ORCA first-command workaround, on the inner ORCA only (the outer
        state machine must not take a step before the run)."""
        assert isinstance(behavior, EarlyYieldBehavior)
        break_symmetry(behavior)  # the inner ORCA gets the outer target every step
        behavior.inner.set_state_from(behavior)
        first_command_workaround(behavior.inner, dt)

    def loop_driver(self) -> EarlyYieldDriver:
        return EarlyYieldDriver(self.params)

    def describe(self) -> dict[str, Any]:
        return {"controller": self.name, **self.params, "inner": "ORCA",
                "effective_center": False, "min_ped_speed": MIN_PED_SPEED,
                "same_way_cos": SAME_WAY_COS, "exit_hysteresis": EXIT_HYSTERESIS,
                "aside_forward": ASIDE_FORWARD,
                "aside_lateral_step": ASIDE_STEP, "aside_lateral_max": ASIDE_MAX,
                "aside_tolerance": ASIDE_TOLERANCE}
