"""Test robots, members and run rows the simulation tests share (test_sim_run.py,
test_sim_speed.py, and the subprocess of the cross-process determinism test)."""

import dataclasses

import numpy as np
import pandas as pd
from navground import core


class Straight:
    """A robot that drives straight to its goal at ``speed`` (default: the cell's)."""

    name = "straight"

    def __init__(self, speed: float | None = None) -> None:
        self.speed = speed

    def build(self, kinematics, radius, speed):
        b = core.behaviors.DummyBehavior(kinematics, radius)
        b.set("environment", "Geometric")
        b.optimal_speed = speed if self.speed is None else self.speed
        return b

    def after_placement(self, behavior, dt):
        pass

    def describe(self):
        return {}


class Orca:
    """A plain navground ORCA robot (stands in for the registered controllers)."""

    name = "test_orca"

    def build(self, kinematics, radius, speed):
        b = core.behaviors.ORCABehavior(kinematics, radius)
        b.horizon, b.time_horizon, b.safety_margin, b.optimal_speed = 5.0, 5.0, 0.12, speed
        return b

    def after_placement(self, behavior, dt):
        behavior.compute_cmd(dt)  # navground 0.7.0: initialise ORCABehavior::D

    def describe(self):
        return {}


def members(population: str, n: int, v0: float) -> pd.DataFrame:
    rng = np.random.default_rng(len(population))
    return pd.DataFrame({
        "population": population, "member": range(n), "persona_id": [f"q{i:02d}" for i in range(n)],
        "variant": "baseline", "mapping": "A", "speed_mps": v0 + 0.6 * rng.random(n),
        "clearance_m": 0.3 + 0.9 * rng.random(n), "avoidance_gain": 0.6 + 1.6 * rng.random(n),
        "yield_fraction": rng.random(n), "reaction_delay_s": 0.15 + rng.random(n),
        "detour_distance_m": 1.0 + 3.0 * rng.random(n), "gap_acceptance": rng.random(n),
    })


def one_pedestrian(spec, start=(23.5, 0.5)):
    """``spec`` with one pedestrian walking out of the scene right away, away from the robot."""
    goal = (26.0, start[1])
    return dataclasses.replace(spec, ped_starts=(start,), ped_goals=(goal,), ped_vias=(goal,),
                               ped_directions=((1.0, 0.0),), ped_exits=(24.0,), slot_draws=(0.1,))


CONTROLLERS_UNDER_TEST = {  # a test navground robot, and the paper's three (two are loop drivers)
    "test_orca": Orca, "reactive": lambda: "reactive", "early_yield": lambda: "early_yield",
    "robot_orca": lambda: "robot_orca"}


def rows(result) -> dict:
    """The run and pedestrian rows as JSON-able data (floats keep every bit via repr)."""
    return {"run": result.run, "pedestrians": result.pedestrians.to_dict("list")}
