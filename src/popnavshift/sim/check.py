"""``check_controller``: an executable contract check, in the spirit of
Gymnasium's ``check_env``.

It builds tiny navground worlds the way the episode builder does (same robot
radius, wheel axis, sensing and call order) and raises
:class:`ControllerContractError` at the first broken rule:

1. the factory has a ``name``, ``build``, ``after_placement`` and a
   JSON-serialisable ``describe()``;
2. ``build`` returns a fresh ``core.Behavior`` per call, with the cell speed
   as optimal speed;
3. every command is finite and feasible for the kinematics
   (``kinematics.feasible(cmd) == cmd``), at both robot speeds;
4. the same world twice gives bitwise-identical robot trajectories;
5. a factory that offers ``loop_driver()`` (the stepping loop's fast path, see
   :class:`..LoopDriver`) gives, on :data:`DRIVER_EPISODES`, the same robot
   trajectories with its driver as with its navground behaviour.

:func:`robot_agent` and :func:`ped_agent` are the builders it uses; tests reuse
them for their own tiny worlds.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence

import numpy as np
from navground import core, sim

from ..episodes.specs import get_episode
from ..errors import ConfigError
from .constants import (
    PED_RADIUS,
    ROBOT_GOAL_TOLERANCE,
    ROBOT_RADIUS,
    WHEEL_AXIS,
)
from .controllers import ControllerFactory
from .run import simulate
from .world import robot_sensing

ROBOT_SPEEDS = (0.6, 1.0)  # [m/s] the cell speeds of SPEC §6
_CMD_TOL = 1e-4  # [m/s], [rad/s] float32 slack on feasibility


class ControllerContractError(ConfigError):
    """A controller factory breaks the contract of :mod:`..controllers`."""


def robot_agent(factory: ControllerFactory, start: Sequence[float], goal: Sequence[float],
                speed: float, *, wheel_max: float | None = None) -> sim.Agent:
    """The robot as the episode builder makes it (id 0, bounded sensing, 2WDiff
    with ``max_forward_speed = speed``), heading to ``goal``. The caller adds it
    to a world, then calls ``factory.after_placement(agent.behavior, dt)``."""
    kin = core.kinematics.TwoWheelsDifferentialDriveKinematics(
        max_speed=wheel_max if wheel_max is not None else speed, wheel_axis=WHEEL_AXIS)
    kin.max_forward_speed = speed
    behavior = factory.build(kin, ROBOT_RADIUS, speed)
    agent = sim.Agent(ROBOT_RADIUS, behavior, kinematics=kin,
                      state_estimations=robot_sensing(behavior))
    agent.id = 0
    heading = math.atan2(goal[1] - start[1], goal[0] - start[0])
    agent.pose = core.Pose2(tuple(start), heading)
    behavior.target = core.Target.Point(tuple(goal), ROBOT_GOAL_TOLERANCE)
    return agent


def ped_agent(start: Sequence[float], goal: Sequence[float] | None, speed: float,
              ped_id: int) -> sim.Agent:
    """A Ped-ORCA pedestrian (4.5 m horizon, tau 3 s / 1 s, notes §1); with
    ``goal=None`` or ``speed=0`` it stands still."""
    kin = core.kinematics.OmnidirectionalKinematics(max_speed=1.8, max_angular_speed=10.0)
    behavior = core.behaviors.ORCABehavior(kin, PED_RADIUS)
    behavior.horizon, behavior.time_horizon, behavior.static_time_horizon = 4.5, 3.0, 1.0
    behavior.safety_margin = 0.05
    behavior.heading_behavior = core.Behavior.Heading.velocity
    behavior.optimal_speed = speed
    agent = sim.Agent(PED_RADIUS, behavior, kinematics=kin, state_estimations=[
        sim.state_estimations.BoundedStateEstimation(range=4.5)])
    agent.id, agent.type = ped_id, "ped"
    heading = 0.0 if goal is None else math.atan2(goal[1] - start[1], goal[0] - start[0])
    agent.pose = core.Pose2(tuple(start), heading)
    behavior.target = (core.Target.Point(tuple(goal), 0.3) if goal is not None and speed > 0
                       else core.Target.Stop())
    return agent


def _tiny_world(factory: ControllerFactory, speed: float, dt: float) -> sim.World:
    """A 3 m corridor with a disc, one oncoming, one crossing, one standing pedestrian."""
    world = sim.World()
    world.add_wall(sim.Wall((-2.0, -1.5), (12.0, -1.5)))
    world.add_wall(sim.Wall((-2.0, 1.5), (12.0, 1.5)))
    world.add_obstacle(sim.Obstacle((6.0, -1.0), 0.3))
    world.add_agent(ped_agent((7.0, 0.2), (-2.0, 0.2), 1.2, 1))
    world.add_agent(ped_agent((3.5, 1.2), (3.5, -8.0), 0.8, 2))
    world.add_agent(ped_agent((9.0, 0.6), None, 0.0, 3))
    robot = robot_agent(factory, (0.0, 0.0), (10.0, 0.0), speed, wheel_max=1.2 * speed)
    world.add_agent(robot)
    assert robot.behavior is not None
    factory.after_placement(robot.behavior, dt)
    return world


def _run(factory: ControllerFactory, speed: float, dt: float, steps: int) -> np.ndarray:
    """Robot poses (steps, 3); checks each command on the way."""
    world = _tiny_world(factory, speed, dt)
    robot = next(a for a in world.agents if a.id == 0)
    kin = robot.kinematics
    assert kin is not None
    poses = np.empty((steps, 3))
    for step in range(steps):
        world.update(dt)
        cmd = robot.get_last_cmd(core.Frame.relative)
        values = (*cmd.velocity, cmd.angular_speed)
        if not all(math.isfinite(v) for v in values):
            raise ControllerContractError(
                f"controller {factory.name!r}: non-finite command {values} at step {step}")
        ok = kin.feasible(cmd)
        if max(abs(a - b) for a, b in zip(values, (*ok.velocity, ok.angular_speed),
                                          strict=True)) > _CMD_TOL:
            raise ControllerContractError(
                f"controller {factory.name!r}: infeasible command (v, w) = {values} at step "
                f"{step} (kinematics allows {(*ok.velocity, ok.angular_speed)})",
                hint="clip with behavior.feasible_twist or sample within the limits")
        poses[step] = (*robot.position, robot.orientation)
    return poses


def _check_interface(factory: ControllerFactory) -> None:
    for attr in ("name", "build", "after_placement", "describe"):
        if not hasattr(factory, attr):
            raise ControllerContractError(f"controller factory {factory!r} has no {attr!r}")
    if not isinstance(factory.name, str) or not factory.name:
        raise ControllerContractError(f"controller name must be a non-empty str, got "
                                      f"{factory.name!r}")
    description = factory.describe()
    try:
        json.dumps(description)
    except TypeError as exc:
        raise ControllerContractError(
            f"controller {factory.name!r}: describe() is not JSON-serialisable: {exc}") from None
    if not isinstance(description, dict):
        raise ControllerContractError(f"controller {factory.name!r}: describe() must be a dict")


def _check_build(factory: ControllerFactory) -> None:
    behaviors = []
    for _ in range(2):
        kin = core.kinematics.TwoWheelsDifferentialDriveKinematics(max_speed=1.0,
                                                                   wheel_axis=WHEEL_AXIS)
        behavior = factory.build(kin, ROBOT_RADIUS, 0.6)
        if not isinstance(behavior, core.Behavior):
            raise ControllerContractError(
                f"controller {factory.name!r}: build returned {type(behavior).__name__}, "
                "not a navground core.Behavior")
        if abs(behavior.optimal_speed - 0.6) > 1e-6:
            raise ControllerContractError(
                f"controller {factory.name!r}: optimal_speed {behavior.optimal_speed} is not "
                "the cell speed 0.6 passed to build")
        behaviors.append(behavior)
    if behaviors[0] is behaviors[1]:
        raise ControllerContractError(
            f"controller {factory.name!r}: build must return a new behaviour per robot")


def check_controller(factory: ControllerFactory, *, dt: float = 0.1, steps: int = 80) -> None:
    """Raise :class:`ControllerContractError` if ``factory`` breaks the contract.

    Runs ``steps`` steps of ``dt`` [s] twice at each robot speed of SPEC §6.
    """
    _check_interface(factory)
    _check_build(factory)
    check_loop_driver(factory)
    for speed in ROBOT_SPEEDS:
        first = _run(factory, speed, dt, steps)
        second = _run(factory, speed, dt, steps)
        if not np.array_equal(first, second):
            step = int(np.argmax(np.any(first != second, axis=1)))
            raise ControllerContractError(
                f"controller {factory.name!r} is not deterministic: the same world twice "
                f"diverges at step {step} (speed {speed} m/s)",
                hint="keep no global or cross-run state; seed any randomness from the world")


#: a narrow crossing, a bottleneck and a sidewalk at both robot speeds, with
#: mid-range pedestrians: the driver must adjust, yield or pass there
DRIVER_EPISODES = ("crossing-w1.8-d0.2-s1.0-v1", "bottleneck-w2.4-d0.12-s0.6-v2",
                   "sidewalk-w1.8-d0.2-s1.0-v3")


class BehaviourOnly:
    """``factory`` without its ``loop_driver``: navground runs its behaviour."""

    def __init__(self, factory: ControllerFactory) -> None:
        self.factory, self.name = factory, factory.name

    def build(self, kinematics: core.Kinematics, radius: float, speed: float) -> core.Behavior:
        return self.factory.build(kinematics, radius, speed)

    def after_placement(self, behavior: core.Behavior, dt: float) -> None:
        self.factory.after_placement(behavior, dt)

    def describe(self) -> dict:
        return self.factory.describe()


def check_loop_driver(factory: ControllerFactory) -> None:
    """Rule 5: raise :class:`ControllerContractError` where the factory's loop driver
    and its behaviour part ways (the first step at which the robot's poses differ)."""
    if not callable(getattr(factory, "loop_driver", None)):
        return
    for episode in DRIVER_EPISODES:
        spec = get_episode(episode)
        fast = simulate(spec, None, factory, record=True).trajectory
        slow = simulate(spec, None, BehaviourOnly(factory), record=True).trajectory
        assert fast is not None and slow is not None
        a, b = fast["robot_pose"], slow["robot_pose"]
        if a.shape != b.shape or not np.array_equal(a, b, equal_nan=True):
            n = min(len(a), len(b))
            differs = ~np.all((a[:n] == b[:n]) | (np.isnan(a[:n]) & np.isnan(b[:n])), axis=1)
            step = int(np.argmax(differs)) if differs.any() else n
            raise ControllerContractError(
                f"controller {factory.name!r}: its loop driver and its behaviour part ways "
                f"in {episode} at step {step}",
                hint="the driver must decide from the same inputs as the behaviour "
                     "(see LoopDriver); or drop loop_driver() and run the behaviour")
