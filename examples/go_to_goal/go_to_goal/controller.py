"""A robot controller written from scratch on a bare navground ``Behavior``.

It drives straight at its goal and slows down near pedestrians — nothing else (no
avoidance): a floor to compare the baselines with, and the smallest controller that
shows the whole contract.

* PopNavShift builds it as ``GoToGoal(kinematics, radius)`` and sets the cell's robot
  speed as ``optimal_speed`` and the goal as ``target``.
* Sensing fills the state :meth:`get_environment_state` returns: a
  ``core.GeometricState`` whose ``neighbors`` are the pedestrians in range.
* :meth:`compute_cmd_internal` returns the command. On a bare ``Behavior``,
  ``cmd_twist_towards_velocity`` returns zero (its desired-velocity step is left to
  subclasses), so the command is built from its two public halves instead:
  ``twist_towards_velocity`` (turn towards a world-frame velocity) and
  ``feasible_twist`` (what the wheels can do).
"""

from __future__ import annotations

import math

import numpy as np
from navground import core


class GoToGoal(core.Behavior, name="GoToGoal"):
    """Straight to the goal at the optimal speed, scaled down near pedestrians."""

    def __init__(self, kinematics: core.Kinematics | None = None, radius: float = 0.0) -> None:
        core.Behavior.__init__(self, kinematics, radius)
        self._state = core.GeometricState()
        self._slow_distance = 1.5

    @property
    @core.register(1.5, "clearance [m] to the nearest pedestrian below which it slows down")
    def slow_distance(self) -> float:
        return self._slow_distance

    @slow_distance.setter
    def slow_distance(self, value: float) -> None:
        self._slow_distance = max(0.01, value)

    def get_environment_state(self) -> core.GeometricState:
        return self._state  # filled by the simulation's sensing

    def compute_cmd_internal(self, time_step: float) -> core.Twist2:
        goal = self.target.position
        if goal is None:
            return core.Twist2((0.0, 0.0), 0.0, frame=core.Frame.relative)
        x, y = self.position
        to_goal = np.asarray(goal, dtype=float) - (x, y)
        distance = float(np.hypot(*to_goal))
        if distance < 1e-3:
            return core.Twist2((0.0, 0.0), 0.0, frame=core.Frame.relative)
        clearance = min((math.hypot(n.position[0] - x, n.position[1] - y) - n.radius
                         - self.radius for n in self._state.neighbors), default=math.inf)
        speed = self.optimal_speed * min(1.0, max(0.0, clearance / self._slow_distance))
        velocity = (to_goal / distance * speed).astype(np.float32)
        return self.feasible_twist(self.twist_towards_velocity(velocity))
