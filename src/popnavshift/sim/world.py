"""Build a navground World from an episode spec, slot profiles, a controller and a backend.

Agents are added pedestrians first (agent index = slot, navground id = slot + 1),
then the robot (navground id 0) when there is one, so pedestrian indices are the
same in every run of an episode. Entity uids are reset before building, so the
same run always gets the same uids.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import cast

import numpy as np
from navground import core, sim

from ..episodes.specs import EpisodeSpec
from .backends import PedestrianBackend, make_pedestrian
from .constants import (
    DT,
    PED_RADIUS,
    ROBOT_GOAL_TOLERANCE,
    ROBOT_RADIUS,
    ROBOT_SENSING_RANGE,
    WHEEL_AXIS,
)


@dataclass
class SimWorld:
    """A built world and the handles the stepping loop needs."""

    world: sim.World
    peds: list[sim.Agent]
    ped_behaviors: list[core.Behavior]
    robot: sim.Agent | None
    robot_behavior: core.Behavior | None


def build_world(
    spec: EpisodeSpec,
    speeds: np.ndarray,
    controller,
    backend: PedestrianBackend,
) -> SimWorld:
    """The world of ``spec`` with pedestrians at preferred ``speeds`` (n,) [m/s].

    ``controller`` is a ControllerFactory, a LoopDriver or None (no robot). Its behaviour is built
    with 2WDiff kinematics whose wheel max speed is the cell's robot speed, so the
    forward speed cap is exactly that speed (angular cap 2·speed/axis).
    """
    sim.Entity.reset_uid()
    world = sim.World()
    for x1, y1, x2, y2 in spec.walls:
        world.add_wall(sim.Wall((x1, y1), (x2, y2)))
    for x, y, r in spec.obstacles:
        world.add_obstacle(sim.Obstacle((x, y), r))
    peds = []
    for k, (start, via) in enumerate(zip(spec.ped_starts, spec.ped_vias, strict=True)):
        agent = make_pedestrian(backend, start, via, float(speeds[k]), PED_RADIUS, k + 1)
        world.add_agent(agent)
        peds.append(agent)
    robot = behavior = None
    if controller is not None:
        robot, behavior = _make_robot(spec, controller)
        world.add_agent(robot)
        controller.after_placement(behavior, DT)
    return SimWorld(world, peds, [cast(core.Behavior, a.behavior) for a in peds], robot, behavior)


def _make_robot(spec: EpisodeSpec, controller) -> tuple[sim.Agent, core.Behavior]:
    speed = spec.robot_speed
    kin = core.kinematics.TwoWheelsDifferentialDriveKinematics(
        max_speed=speed, wheel_axis=WHEEL_AXIS
    )
    behavior = controller.build(kin, ROBOT_RADIUS, speed)
    # a loop driver without sensing senses through the loop (controllers.LoopDriver)
    sensing = robot_sensing(behavior, getattr(controller, "sensing", True))
    robot = sim.Agent(
        radius=ROBOT_RADIUS, behavior=behavior, kinematics=kin, state_estimations=sensing
    )
    (sx, sy), (gx, gy) = spec.robot_start, spec.robot_goal
    pose = core.Pose2((sx, sy), math.atan2(gy - sy, gx - sx))
    robot.pose = pose
    behavior.pose = pose  # Agent.update re-syncs it; set here for after_placement
    robot.id = 0
    robot.type = "robot"
    behavior.target = core.Target.Point((gx, gy), ROBOT_GOAL_TOLERANCE)
    return robot, behavior


def robot_sensing(behavior: core.Behavior, wanted: bool = True) -> list:
    """The robot's state estimation: bounded sensing within ``ROBOT_SENSING_RANGE`` — unless
    not ``wanted``, or the behaviour has no geometric state to fill (navground's Dummy):
    attaching it then would only make navground warn once per run that it cannot."""
    if not wanted or not isinstance(behavior.environment_state, core.GeometricState):
        return []
    return [sim.state_estimations.BoundedStateEstimation(range=ROBOT_SENSING_RANGE)]


def remove_agent(agent: sim.Agent, slot: int) -> None:
    """Take ``agent`` out of the simulation (navground 0.7.0 cannot remove agents).

    It is teleported far away (10 m apart from other removed agents, beyond every
    sensing range), stops and no longer collides.
    """
    agent.ignore_collisions = True
    agent.pose = core.Pose2((1000.0 + 10.0 * slot, 1000.0), 0.0)
    if agent.behavior is not None:
        agent.behavior.target = core.Target.Stop()


def stop_agent(agent: sim.Agent) -> None:
    """Freeze ``agent`` in place: zero wheel speed cap and a Stop target.

    A zero kinematic cap stops any behaviour, Python controllers included, since
    navground clamps every command to the kinematics before actuating it.
    """
    if agent.behavior is not None:
        agent.behavior.target = core.Target.Stop()
    if agent.kinematics is not None:
        agent.kinematics.max_speed = 0.0
