"""THE observation and action of a PopNavShift policy: what a learned robot sees and does.

One declaration, used by the Gymnasium environment (:mod:`.env`, training) and by a
policy run as a controller (``popnavshift evaluate policy.onnx``, inference), so a
policy sees at evaluation exactly what it saw in training. Both read navground-learning's
config classes (``DefaultObservationConfig``, ``ControlActionConfig``) through
:class:`PolicySpaces`, built once per robot behaviour (the scales come from its
kinematics: the cell's robot speed).

**Sensing.** The robot of every controller has the same bounded sensing
(:data:`popnavshift.sim.constants.ROBOT_SENSING_RANGE`, 6 m); a policy reads the
``core.GeometricState`` it fills, never the world.

**Observation** — one flat ``float32`` vector of :data:`OBSERVATION_SIZE` values in
[-1, 1] (navground-learning ``normalize=True``: a Box [lo, hi] maps linearly onto
[-1, 1]; the 0/1 masks stay 0/1). Fields:

=========================  =====  =============================================================
``ego_angular_speed``      1      [rad/s], Box ± the robot's max angular speed
                                  (2·speed / wheel axis)
``ego_target_direction``   2      unit vector to the goal, robot frame (Box ±1)
``ego_target_distance``    1      distance to the goal disc [m] (centre distance minus the
                                  0.3 m tolerance), capped at :data:`MAX_TARGET_DISTANCE`
                                  (Box [0, 25])
``ego_velocity``           1      forward speed [m/s], Box ± the cell's robot speed
``obstacles_position``     K×2    closest point of each of the K = :data:`N_OBSTACLES` nearest
                                  walls or static discs within 6 m, robot frame (x ahead,
                                  y left) [m], Box ±6 m; nearest first, zero when absent
``obstacles_valid``        K      1 for a present obstacle, else 0
``pedestrians_position``   N×2    centre of each of the N = :data:`N_PEDESTRIANS` nearest
                                  sensed pedestrians, robot frame [m], Box ±6 m; nearest
                                  (centre distance) first, zero when absent
``pedestrians_valid``      N      1 for a sensed pedestrian, else 0
``pedestrians_velocity``   N×2    their velocity in the robot frame [m/s], Box ±
                                  :data:`MAX_PEDESTRIAN_SPEED` (absolute velocity, rotated)
=========================  =====  =============================================================

(Gymnasium's ``Dict`` space orders the fields by name; :func:`observation_layout` gives
the order and sizes, 47 values in all.)

**Action** — ``ControlActionConfig`` velocity action for the two-wheel robot: a
``float32`` vector of 2 in [-1, 1], ``[v / max_speed, ω / max_angular_speed]`` (forward
speed and angular speed as fractions of the cell's caps), made feasible by the robot's
kinematics (navground keeps ω and cuts v; no reversing). The same action means the same
fraction of the caps in every cell.

Nothing here is random: the observation is a function of the sensed state alone.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, cast

import gymnasium as gym
import numpy as np
from navground import core
from navground.learning.config import ControlActionConfig, DefaultObservationConfig

from ..sim.constants import ROBOT_SENSING_RANGE
from ..sim.controllers._geometry import neighbors_array, static_arrays

N_PEDESTRIANS = 6  # nearest sensed pedestrians in an observation
N_OBSTACLES = 4  # nearest walls / static discs in an observation
MAX_PEDESTRIAN_SPEED = 2.0  # [m/s] velocity scale (preferred speeds are at most 1.8 m/s)
MAX_TARGET_DISTANCE = 25.0  # [m] distance scale (the robot travels 20 m)
RANGE = ROBOT_SENSING_RANGE  # [m]

#: the sensing part of the observation: name -> (shape, low, high, dtype)
SENSING: dict[str, tuple[tuple[int, ...], float, float, type]] = {
    "obstacles_position": ((N_OBSTACLES, 2), -RANGE, RANGE, np.float32),
    "obstacles_valid": ((N_OBSTACLES,), 0, 1, np.uint8),
    "pedestrians_position": ((N_PEDESTRIANS, 2), -RANGE, RANGE, np.float32),
    "pedestrians_valid": ((N_PEDESTRIANS,), 0, 1, np.uint8),
    "pedestrians_velocity": ((N_PEDESTRIANS, 2), -MAX_PEDESTRIAN_SPEED, MAX_PEDESTRIAN_SPEED,
                             np.float32),
}


def observation_config() -> DefaultObservationConfig:
    """navground-learning's observation config of every PopNavShift policy (unconfigured:
    :class:`PolicySpaces` completes it from the robot's kinematics)."""
    return DefaultObservationConfig(
        flat=True, normalize=True, dtype="float32",
        include_target_direction=True, include_target_distance=True,
        max_target_distance=MAX_TARGET_DISTANCE,
        include_velocity=True, include_angular_speed=True,
    )


def action_config() -> ControlActionConfig:
    """navground-learning's action config: body velocities as fractions of the caps."""
    return ControlActionConfig(dtype="float32", use_acceleration_action=False,
                               use_wheels=False, fix_orientation=False)


def sensing_space() -> gym.spaces.Dict:
    return gym.spaces.Dict({
        name: gym.spaces.Box(low, high, shape, dtype=dtype)
        for name, (shape, low, high, dtype) in SENSING.items()
    })


@dataclass
class _Buffer:
    """What navground-learning reads of a sensing buffer: its ``data``."""

    data: np.ndarray


class PolicySpaces:
    """The observation and action of one robot behaviour (its kinematics set the scales).

    ``observe(behavior, state)`` → the flat observation; ``command(action, behavior,
    dt)`` → the feasible ``Twist2`` the robot actuates; ``action(twist)`` → the action
    of a command (how a navground behaviour's command is written as an action, for
    imitation). ``observation_space`` and ``action_space`` are the Gymnasium spaces.
    """

    def __init__(self, behavior: core.Behavior) -> None:
        self.observation = copy.deepcopy(observation_config())
        self.observation.configure(behavior, sensing_space())
        self.actions = copy.deepcopy(action_config())
        self.actions.configure(behavior)
        self._buffers: dict[str, _Buffer] = {
            name: _Buffer(np.zeros(shape, dtype=dtype))
            for name, (shape, _, _, dtype) in SENSING.items()
        }

    @property
    def observation_space(self) -> gym.spaces.Box:
        space = self.observation.space
        assert isinstance(space, gym.spaces.Box)
        return space

    @property
    def action_space(self) -> gym.spaces.Box:
        space = self.actions.space
        assert isinstance(space, gym.spaces.Box)
        return space

    def observe(self, behavior: core.Behavior, state: core.GeometricState) -> np.ndarray:
        """The observation (:data:`OBSERVATION_SIZE`,) float32 of ``behavior`` (pose,
        twist, target) and its sensed ``state``."""
        fill_sensing(self._buffers, behavior, state)
        obs = self.observation.get_observation(  # it reads each buffer's data only
            behavior, cast("Mapping[str, core.Buffer]", self._buffers))
        return np.asarray(obs, dtype=np.float32)

    def command(self, action: Any, behavior: core.Behavior, dt: float) -> core.Twist2:
        """The feasible command (robot frame) of ``action``, clipped to [-1, 1] first."""
        act = np.clip(np.asarray(action, dtype=np.float32).reshape(-1), -1.0, 1.0)
        return behavior.feasible_twist(self.actions.get_cmd_from_action(act, behavior, dt))

    def action(self, cmd: core.Twist2, behavior: core.Behavior) -> np.ndarray:
        """The action of the command ``cmd`` of ``behavior`` (how a navground behaviour's
        command is written as an action, for imitation): ``command`` inverted, clipped."""
        velocity = cmd.velocity
        if cmd.frame == core.Frame.absolute:
            velocity = core.to_relative(velocity, behavior.pose)
        v = float(velocity[0]) / self.actions.max_speed
        w = float(cmd.angular_speed) / self.actions.max_angular_speed
        return np.clip(np.array([v, w], dtype=np.float32), -1.0, 1.0)


def fill_sensing(buffers: Mapping[str, _Buffer], behavior: core.Behavior,
                 state: core.GeometricState) -> None:
    """Write the sensing fields of :data:`SENSING` from a bounded-sensing ``state``."""
    x, y = (float(v) for v in behavior.position)
    theta = float(behavior.orientation)
    c, s = math.cos(theta), math.sin(theta)
    rot = np.array([[c, s], [-s, c]])  # world -> robot frame
    peds, _ = neighbors_array(state)
    pos, vel, valid = (buffers[k].data for k in ("pedestrians_position", "pedestrians_velocity",
                                                 "pedestrians_valid"))
    pos[:], vel[:], valid[:] = 0.0, 0.0, 0
    if len(peds):
        rel = peds[:, :2] - (x, y)
        order = np.argsort(np.hypot(rel[:, 0], rel[:, 1]), kind="stable")[:N_PEDESTRIANS]
        m = len(order)
        pos[:m] = np.clip(rel[order] @ rot.T, -RANGE, RANGE)
        vel[:m] = np.clip(peds[order, 2:4] @ rot.T, -MAX_PEDESTRIAN_SPEED, MAX_PEDESTRIAN_SPEED)
        valid[:m] = 1
    points = _closest_points(np.array((x, y)), *static_arrays(state))
    opos, ovalid = buffers["obstacles_position"].data, buffers["obstacles_valid"].data
    opos[:], ovalid[:] = 0.0, 0
    if len(points):
        rel = points - (x, y)
        dist = np.hypot(rel[:, 0], rel[:, 1])
        near = [i for i in np.argsort(dist, kind="stable") if dist[i] <= RANGE][:N_OBSTACLES]
        m = len(near)
        if m:
            opos[:m] = rel[near] @ rot.T
            ovalid[:m] = 1


def _closest_points(p: np.ndarray, walls: np.ndarray, discs: np.ndarray) -> np.ndarray:
    """(W + D, 2): the point of each wall segment (x1, y1, x2, y2) and of each disc's
    rim (x, y, r) closest to ``p``."""
    out = []
    if len(walls):
        a, ab = walls[:, 0:2], walls[:, 2:4] - walls[:, 0:2]
        t = np.clip(np.sum((p - a) * ab, axis=1) / np.maximum(np.sum(ab * ab, axis=1), 1e-12),
                    0.0, 1.0)
        out.append(a + t[:, None] * ab)
    if len(discs):
        d = p - discs[:, :2]
        n = np.maximum(np.hypot(d[:, 0], d[:, 1]), 1e-9)
        out.append(discs[:, :2] + d * (discs[:, 2] / n)[:, None])
    return np.concatenate(out) if out else np.zeros((0, 2))


def observation_layout() -> list[tuple[str, int]]:
    """(field, number of values) in the order of the flat observation."""
    cfg = observation_config()
    kin = core.kinematics.TwoWheelsDifferentialDriveKinematics(max_speed=1.0, wheel_axis=0.5)
    cfg.configure(core.Behavior(kin, 0.35), sensing_space())
    items = cfg._item_space  # the Dict space the flat observation flattens
    return [(k, int(np.prod(v.shape or ()))) for k, v in items.items()]


#: values in an observation: the sensing fields, then the ego fields (angular speed 1,
#: target direction 2, target distance 1, forward speed 1)
OBSERVATION_SIZE = sum(int(np.prod(shape)) for shape, *_ in SENSING.values()) + 5
ACTION_SIZE = 2  # forward speed, angular speed
