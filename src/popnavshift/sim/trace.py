"""What the stepping loop records of a run, and the replay arrays drawn from it.

:class:`Trace` holds positions per step (agent n is the robot), exits, the robot's
outcome and contact counts; :mod:`.metrics` computes every metric from it and
:meth:`Trace.trajectory` gives the replay arrays.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..episodes.specs import EpisodeSpec
from .constants import DT, PED_RADIUS, ROBOT_RADIUS


@dataclass
class Trace:
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
    contact_speed: float = float("nan")  # the robot's speed at the contact ending its run [m/s]
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

