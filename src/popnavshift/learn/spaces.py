"""PROVISIONAL (part B's stand-in until part A's spaces.py lands on this branch): the
observation and action configuration of PopNavShift policies."""

from __future__ import annotations

from navground import sim
from navground.learning.config import ControlActionConfig, DefaultObservationConfig

from ..sim.constants import ROBOT_SENSING_RANGE

N_NEIGHBOURS = 5


def sensor() -> sim.Sensor:
    """A new sensor for one robot: the nearest pedestrians within the sensing range."""
    return sim.state_estimations.DiscsStateEstimation(
        range=ROBOT_SENSING_RANGE, number=N_NEIGHBOURS, max_radius=1.0, max_speed=2.0,
        include_valid=True)


def observation_config() -> DefaultObservationConfig:
    return DefaultObservationConfig(flat=True, include_target_direction=True,
                                    include_target_distance=True, max_target_distance=30.0,
                                    include_velocity=True, include_angular_speed=True)


def action_config() -> ControlActionConfig:
    return ControlActionConfig()
