"""Pedestrian backends: the navground behaviour that moves a pedestrian (SPEC §6).

Registry :data:`BACKENDS`: ``orca`` (omnidirectional ORCA, 4.5 m horizon) and
``hl`` (Human-like, 5 m horizon). Both get their preferred speed and target from
the response layer (:mod:`.pedestrians`) only; no Task is attached.
:func:`make_pedestrian` builds the agent the same way for every backend.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields
from typing import Any, Protocol

from navground import core, sim

from ..registry import Registry
from .constants import PED_GOAL_TOLERANCE


class PedestrianBackend(Protocol):
    """Builds one pedestrian's navground behaviour; ``horizon`` [m] is also its sensing range."""

    @property
    def name(self) -> str: ...

    @property
    def horizon(self) -> float: ...

    def behavior(self, kinematics: core.Kinematics, radius: float) -> core.Behavior: ...

    def describe(self) -> dict[str, Any]: ...


def _configured(behavior: core.Behavior, backend: Any) -> core.Behavior:
    """``behavior`` with every field of the ``backend`` dataclass but its name set on it
    (the fields are named as navground's behaviour properties), in field order."""
    for field in fields(backend):  # not asdict: this runs for every pedestrian of every run
        if field.name != "name":
            setattr(behavior, field.name, getattr(backend, field.name))
    return behavior


@dataclass(frozen=True)
class ORCABackend:
    """Ped-ORCA: navground ORCA on omnidirectional kinematics."""

    name: str = "orca"
    horizon: float = 4.5  # [m]; also the sensing range of the pedestrian
    time_horizon: float = 3.0  # [s] vs agents (navground default 10 s is very timid)
    static_time_horizon: float = 1.0  # [s] vs walls and obstacles
    safety_margin: float = 0.05  # [m]

    def behavior(self, kinematics: core.Kinematics, radius: float) -> core.Behavior:
        return _configured(core.behaviors.ORCABehavior(kinematics, radius), self)

    def describe(self) -> dict[str, Any]:
        return asdict(self)


@dataclass(frozen=True)
class HLBackend:
    """Ped-HL: navground's Human-like behaviour (Guzzi et al. 2013)."""

    name: str = "hl"
    horizon: float = 5.0  # [m]
    tau: float = 0.5  # [s] velocity relaxation time
    eta: float = 0.5  # [s] speed ≤ free distance / eta
    aperture: float = math.pi / 2  # [rad] search ± this around the heading
    resolution: int = 61  # directions sampled over 2·aperture
    safety_margin: float = 0.05  # [m]

    def behavior(self, kinematics: core.Kinematics, radius: float) -> core.Behavior:
        return _configured(core.behaviors.HLBehavior(kinematics, radius), self)

    def describe(self) -> dict[str, Any]:
        return asdict(self)


BACKENDS: Registry[PedestrianBackend] = Registry(
    "backend", requires=("behavior", "describe"), noun="pedestrian backend",
    hint="a backend class has name, horizon, behavior(kinematics, radius) and describe()")
BACKENDS.register("orca", ORCABackend)
BACKENDS.register("hl", HLBackend)


def make_pedestrian(
    backend: PedestrianBackend,
    position: tuple[float, float],
    target: tuple[float, float],
    speed: float,
    radius: float,
    agent_id: int,
) -> sim.Agent:
    """A pedestrian agent already walking towards ``target`` at ``speed`` [m/s].

    It gets its own kinematics (max speed = ``speed``) and starts with that velocity,
    so backends with a velocity relaxation (HL) do not spend the first second
    accelerating.
    """
    kin = core.kinematics.OmnidirectionalKinematics(max_speed=speed, max_angular_speed=10.0)
    b = backend.behavior(kin, radius)
    b.optimal_speed = speed
    b.heading_behavior = core.Behavior.Heading.velocity
    se = sim.state_estimations.BoundedStateEstimation(range=backend.horizon)
    agent = sim.Agent(radius=radius, behavior=b, kinematics=kin, state_estimations=[se])
    heading = math.atan2(target[1] - position[1], target[0] - position[0])
    agent.pose = core.Pose2(position, heading)
    velocity = (speed * math.cos(heading), speed * math.sin(heading))
    agent.twist = core.Twist2(velocity, 0.0, frame=core.Frame.absolute)
    agent.last_cmd = agent.twist  # HL relaxes from the last command
    agent.id = agent_id
    agent.type = "pedestrian"
    b.target = core.Target.Point(target, PED_GOAL_TOLERANCE)
    return agent
