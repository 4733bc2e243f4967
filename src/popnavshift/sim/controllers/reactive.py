"""``reactive``: drive straight to the goal; sample wheel commands only when a
conflict is imminent.

Paper §III-F: "samples feasible wheel commands over a 2 s horizon with a
0.04 m safety buffer and adjusts its trajectory when a conflict becomes
imminent". Each step the robot rolls out its drive-to-goal law for
``rollout_time`` against constant-velocity neighbours, walls and static discs
(:func:`._rollout.reactive_command`). If nothing comes within ``buffer`` it
applies that command; otherwise it rolls out a grid of constant (v, w) arcs —
(left, right) wheel pairs within the kinematic limits, no reversing, at most
half a turn per rollout — drops those that come within ``buffer``, scores
the rest by progress to goal, final heading, clearance along the arc and
clearance of the straight path on from the arc's end ("sight", which keeps it
from creeping into a dead end in front of an obstacle), and applies the best.
No free arc: it stops. Choices and measurements: docs/method.md §7.
"""

from __future__ import annotations

from typing import Any, SupportsFloat, cast

import numpy as np
from navground import core, sim

from ._geometry import neighbors_array, static_arrays
from ._params import Param, require_two_wheels, resolve_params
from ._rollout import REACTIVE_CFG, reactive_command, reactive_pose_command

MODES = ("go", "adjust", "stop")

PARAMS: dict[str, Param] = {
    "rollout_time": Param(2.0, 0.2, 10.0, doc="prediction horizon [s]"),
    "buffer": Param(0.04, 0.0, 1.0, doc="clearance required beyond the radii [m]"),
    "n_speeds": Param(7, 2, 41, int, "linear-speed levels in [0, max forward speed]"),
    "n_turns": Param(11, 3, 41, int, "angular-speed levels per linear speed"),
    "progress_weight": Param(1.0, 0.0, 100.0, doc="weight of progress to goal"),
    "heading_weight": Param(0.3, 0.0, 100.0, doc="weight of final heading to goal"),
    "clearance_weight": Param(0.4, 0.0, 100.0, doc="weight of clearance along the arc"),
    "sight_weight": Param(0.5, 0.0, 100.0,
                          doc="weight of clearance of the straight path from arc end to goal"),
    "sight_distance": Param(4.0, 0.0, 20.0, doc="length of that straight path checked [m]"),
}
CLEARANCE_CAP = 1.0  # [m] clearance beyond this earns nothing more
NAME = "reactive"
NAVGROUND_NAME = "PopNavShiftReactive"  # the behaviour's navground type name


class ReactiveBehavior(core.Behavior, name=NAVGROUND_NAME):
    """The reactive sampling controller as a navground behaviour.

    Sensing fills :attr:`_state` (a GeometricState) through
    ``BoundedStateEstimation``; :attr:`mode` is the last decision ("go",
    "adjust", "stop") and :attr:`mode_counts` counts them (diagnostics).
    """

    def __init__(self, kinematics: core.Kinematics | None = None, radius: float = 0.0,
                 **params: Any) -> None:
        core.Behavior.__init__(self, kinematics, radius)
        self._state = core.GeometricState()
        self.params = resolve_params(NAME, PARAMS, params)
        self._constants: tuple | None = None
        self.mode = "go"
        self.mode_counts = dict.fromkeys(MODES, 0)

    def get_environment_state(self) -> core.GeometricState:
        return self._state

    def compute_cmd_internal(self, time_step: SupportsFloat) -> core.Twist2:
        goal = self.get_target_position(_ABSOLUTE)
        if goal is None:  # no target or already satisfied
            return _ZERO_TWIST
        if self._constants is None:
            # bounded sensing set walls and discs once, in prepare (its default
            # update_static_obstacles=False), so they are read once too
            self._constants = constants(self, self.params, float(time_step),
                                        static_arrays(self._state))
        peds, _ = neighbors_array(self._state)
        x, y = self.position.tolist()
        gx, gy = goal.tolist()
        v, w, mode = decide(x, y, float(self.orientation), gx, gy, self._constants, peds)
        self.mode = MODES[mode]
        self.mode_counts[self.mode] += 1
        return core.Twist2((v, 0.0), w, _RELATIVE)


def constants(behavior: core.Behavior, params: dict[str, Any], time_step: float,
              static: tuple[np.ndarray, np.ndarray]) -> tuple:
    """What :func:`._rollout.reactive_command` takes besides the pose, the goal and
    the neighbours, fixed during a run: its ``cfg`` array, read once from the
    robot's behaviour (a property read through the binding costs 0.2-1.3 us), and
    the walls and discs ``static``."""
    k = cast(core.kinematics.TwoWheelsDifferentialDriveKinematics, behavior.kinematics)
    wheel_max, axis = float(k.max_speed), float(k.wheel_axis)
    v_top = min(float(k.max_forward_speed), wheel_max, float(behavior.optimal_speed))
    cfg = {
        "speed": float(behavior.optimal_speed), "tol": float(behavior.target.position_tolerance),
        "v_top": v_top, "wheel_max": wheel_max, "axis": axis,
        "w_max": float(behavior.optimal_angular_speed), "rot_tau": float(behavior.rotation_tau),
        "radius": float(behavior.radius), "buffer": params["buffer"], "dt": time_step,
        "n_steps": max(1, round(params["rollout_time"] / time_step)),
        "n_v": params["n_speeds"], "n_w": params["n_turns"], "cap": CLEARANCE_CAP,
        "sight": params["sight_distance"], "w_progress": params["progress_weight"],
        "w_heading": params["heading_weight"], "w_clearance": params["clearance_weight"],
        "w_sight": params["sight_weight"],
    }
    return np.array([cfg[f] for f in REACTIVE_CFG], dtype=np.float64), static


def decide(x: float, y: float, theta: float, gx: float, gy: float, fixed: tuple,
           peds: np.ndarray) -> tuple[float, float, int]:
    """(v [m/s], w [rad/s], mode index) for the robot at (x, y, θ) heading to (gx, gy)
    among neighbours ``peds`` (N, 5); ``fixed`` from :func:`constants`."""
    cfg, (walls, discs) = fixed
    return reactive_command(x, y, theta, gx, gy, cfg, peds, walls, discs)


class ReactiveDriver:
    """The reactive controller on the stepping loop's fast path (see
    :class:`..LoopDriver`): the same kernel and the same float32 inputs as
    :class:`ReactiveBehavior`, so the same commands, without a Python behaviour
    inside navground's step. The robot runs a C++ ``DummyBehavior`` that is never
    asked for a command: each decision is applied with
    ``controller.follow_manual_cmd``, only when it changes."""

    sensing = False  # the loop senses the neighbours

    def __init__(self, params: dict[str, Any]) -> None:
        self.params = params
        self.mode_counts = dict.fromkeys(MODES, 0)

    def build(self, kinematics: core.Kinematics, radius: float, speed: float) -> core.Behavior:
        require_two_wheels(NAME, kinematics)
        behavior = core.behaviors.DummyBehavior(kinematics, radius)
        behavior.optimal_speed = speed
        return behavior

    def after_placement(self, behavior: core.Behavior, dt: float) -> None:
        """Nothing to initialise: no C++ ORCA state."""

    def start(self, robot: sim.Agent, world: sim.World, dt: float) -> None:
        behavior = cast(core.Behavior, robot.behavior)
        # decide()'s arguments, unpacked once: step() runs every control step
        self._cfg, (self._walls, self._discs) = constants(behavior, self.params, dt,
                                                          static_arrays(world))
        self._goal = np.array(cast(np.ndarray, behavior.target.position), dtype=np.float64)
        self._controller = robot.controller
        self._last: tuple[float, float] | None = None
        # one command object, refilled: navground copies it (building a Twist2 costs 1 us)
        self._cmd = core.Twist2((0.0, 0.0), 0.0, _RELATIVE)
        self._velocity = np.zeros(2)

    def step(self, step: int, pose: np.ndarray, peds: np.ndarray, ids: np.ndarray) -> None:
        v, w, mode = reactive_pose_command(pose, self._goal, self._cfg, peds, self._walls,
                                           self._discs)  # decide(), on the float32 pose
        self.mode_counts[MODES[mode]] += 1
        if (v, w) != self._last:
            cmd = self._cmd
            self._velocity[0] = v
            cmd.velocity = self._velocity  # type: ignore[assignment]  # the stub says float32
            cmd.angular_speed = w
            self._controller.follow_manual_cmd(cmd)
            self._last = (v, w)


_ABSOLUTE, _RELATIVE = core.Frame.absolute, core.Frame.relative  # enum lookups cost 0.1 us
_ZERO_TWIST = core.Twist2((0.0, 0.0), 0.0, _RELATIVE)


class Reactive:
    """Factory of :class:`ReactiveBehavior` (registered as ``reactive``); the
    stepping loop runs it as :class:`ReactiveDriver`."""

    name = NAME

    def __init__(self, **params: Any) -> None:
        self.params = resolve_params(self.name, PARAMS, params)

    def build(self, kinematics: core.Kinematics, radius: float, speed: float) -> core.Behavior:
        require_two_wheels(self.name, kinematics)
        behavior = ReactiveBehavior(kinematics, radius, **self.params)
        behavior.optimal_speed = speed
        return behavior

    def after_placement(self, behavior: core.Behavior, dt: float) -> None:
        """Nothing to initialise: the behaviour holds no C++ ORCA state."""

    def loop_driver(self) -> ReactiveDriver:
        return ReactiveDriver(self.params)

    def describe(self) -> dict[str, Any]:
        return {"controller": self.name, **self.params,
                "clearance_cap": CLEARANCE_CAP, "reversing": False}
