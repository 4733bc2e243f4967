"""Robot controllers: the contract and the registry.

Every controller drives the same robot: a differential-drive disk of radius
:data:`ROBOT_RADIUS` with :data:`WHEEL_AXIS`, the cell's robot speed as its
optimal speed, the same goal, limits and sensing range. A controller is a
factory registered by name in :data:`CONTROLLERS` (the built-ins in
:mod:`.builtin`; ids, plug-ins and ``make`` in :mod:`.registry`)::

    CONTROLLERS.make('robot_orca{"time_horizon":4.0}')

A factory is called as ``factory(**params)`` and returns a
:class:`ControllerFactory`-like object with

* ``build(kinematics, radius, speed) -> core.Behavior`` — a configured behaviour
  (no pose/target yet);
* ``after_placement(behavior, dt)`` — called once after the world set the
  robot's pose and target and before the first step (e.g. navground 0.7.0's
  uninitialised ``ORCABehavior::D`` workaround, see docs/method.md).

Optionally, ``loop_driver() -> LoopDriver`` puts the controller on the stepping
loop's fast path (:class:`LoopDriver`): navground then never calls Python for
the robot. The built-in ``reactive`` and ``early_yield`` use it; their
behaviours stay the reference (a test checks that both give the same runs) and
the way to use them in plain navground.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Protocol

from . import builtin  # noqa: F401  (registers the built-in controllers)
from .registry import CONTROLLERS

if TYPE_CHECKING:
    import numpy as np
    from navground import core, sim

    from ..constants import ROBOT_GOAL_TOLERANCE as ROBOT_GOAL_TOLERANCE
    from ..constants import ROBOT_RADIUS as ROBOT_RADIUS
    from ..constants import ROBOT_SENSING_RANGE as ROBOT_SENSING_RANGE
    from ..constants import WHEEL_AXIS as WHEEL_AXIS

#: the robot every controller drives: declared in sim/constants.py, re-exported for
#: plug-ins, read from there on first use (sim/constants.py loads the episode grid: a
#: command that only lists the controllers must not)
_ROBOT = frozenset({"ROBOT_GOAL_TOLERANCE", "ROBOT_RADIUS", "ROBOT_SENSING_RANGE",
                    "WHEEL_AXIS"})


def __getattr__(name: str) -> Any:
    if name in _ROBOT:
        from .. import constants

        return getattr(constants, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


class ControllerFactory(Protocol):
    name: str

    def build(
        self, kinematics: core.Kinematics, radius: float, speed: float
    ) -> core.Behavior: ...

    def after_placement(self, behavior: core.Behavior, dt: float) -> None: ...

    def describe(self) -> dict[str, Any]: ...


class LoopDriver(Protocol):
    """A controller computed by the stepping loop (:mod:`popnavshift.sim.loop`).

    A Python behaviour costs ~30 us per step inside navground's update (the
    C++→Python call, then reading the sensed neighbours through the binding); the
    loop already holds every pose and twist as arrays. A driver builds a C++
    behaviour for the robot, then once per control step gets what bounded
    sensing would give and acts on the robot only when its decision changes
    (``robot.controller.follow_manual_cmd``, a new target, ...).

    * ``sensing`` — whether the robot keeps navground's bounded sensing (its C++
      behaviour uses it);
    * ``build`` / ``after_placement`` — as for a factory;
    * ``start(robot, world, dt)`` — once the world is built, before the first step;
    * ``step(step, pose, peds, ids)`` — before navground step ``step`` (from 1):
      the robot's ``pose`` (x, y, θ), the sensed neighbours ``peds`` (N, 5: x, y,
      vx, vy, radius) and their slots ``ids`` (N,), as float32 values of the
      state navground's own sensing reads at that step. The arrays are the loop's
      buffers, refilled every step: copy what must outlive the call.
    * ``quiet() -> bool`` (optional) — True when a step with nobody sensed would
      change nothing; then the loop may let navground run such steps without
      calling :meth:`step` (:mod:`popnavshift.sim.quiet`). A driver without it
      is called every step.
    """

    sensing: bool

    def build(
        self, kinematics: core.Kinematics, radius: float, speed: float
    ) -> core.Behavior: ...

    def after_placement(self, behavior: core.Behavior, dt: float) -> None: ...

    def start(self, robot: sim.Agent, world: sim.World, dt: float) -> None: ...

    def step(self, step: int, pose: np.ndarray, peds: np.ndarray, ids: np.ndarray) -> None: ...


__all__ = ["CONTROLLERS", "ControllerFactory", "LoopDriver", "ROBOT_GOAL_TOLERANCE",
           "ROBOT_RADIUS", "ROBOT_SENSING_RANGE", "WHEEL_AXIS"]
