"""Pedestrian backends and the robot-conditioned response layer (SPEC §6)."""

import dataclasses

import numpy as np
import pandas as pd
import pytest
from navground import core

from popnavshift.episodes import get_episode
from popnavshift.sim.backends import BACKENDS
from popnavshift.sim.pedestrians import (
    FLAG_DETOURING,
    FLAG_REACTING,
    FLAG_YIELDING,
    SENSE_RANGE,
    _waypoint,
    effective_clearance,
)
from popnavshift.sim.run import simulate


class Straight:
    """A robot that drives straight to its goal and ignores everybody (DummyBehavior)."""

    name = "straight"

    def build(self, kinematics, radius, speed):
        b = core.behaviors.DummyBehavior(kinematics, radius)
        b.set("environment", "Geometric")
        b.optimal_speed = speed
        return b

    def after_placement(self, behavior, dt):
        pass

    def describe(self):
        return {}


def profile(n: int = 1, **kw) -> pd.DataFrame:
    row = {"persona_id": "p", "speed_mps": 1.2, "clearance_m": 0.6, "avoidance_gain": 1.4,
           "yield_fraction": 0.5, "reaction_delay_s": 0.5, "detour_distance_m": 2.5,
           "gap_acceptance": 0.5}
    row.update(kw)
    return pd.DataFrame([row] * n)


def lone(spec, start, direction):
    """``spec`` with one pedestrian at ``start`` walking along ``direction`` (±1 on x)."""
    exit_ = 24.0 if direction > 0 else 0.0
    goal = (exit_ + 2.0 * direction, start[1])
    return dataclasses.replace(
        spec, ped_starts=(start,), ped_goals=(goal,), ped_vias=(goal,),
        ped_directions=((float(direction), 0.0),), ped_exits=(exit_ * direction,),
        slot_draws=(0.5,),
    )


def speeds(result, k: int = 0) -> np.ndarray:
    xy = result.trajectory["ped_pose"][:, k, :2]
    v = np.linalg.norm(np.diff(xy, axis=0), axis=1) / 0.1
    return v[~np.isnan(v)]


def test_backends_are_registered_by_name():
    assert BACKENDS.names() == ["hl", "orca"]
    assert BACKENDS.make("orca").horizon == 4.5 and BACKENDS.make("hl").horizon == 5.0


@pytest.mark.parametrize("backend", ["orca", "hl"])
@pytest.mark.parametrize("v", [0.6, 1.3, 1.8])
def test_a_lone_pedestrian_walks_at_its_preferred_speed(backend, v):
    spec = lone(get_episode("sidewalk-w1.8-d0.06-s0.6-v1"), (1.0, 0.3), +1)
    result = simulate(spec, profile(speed_mps=v), None, backend, record=True)
    assert speeds(result) == pytest.approx(v, abs=1e-3)
    assert result.pedestrians.travel_time[0] == pytest.approx(23.0 / v, abs=1e-3)
    assert result.pedestrians.detour[0] == pytest.approx(0.0, abs=1e-3)


@pytest.mark.parametrize("backend", ["orca", "hl"])
def test_high_yielding_slows_for_a_robot_on_a_collision_course_low_yielding_does_not(backend):
    spec = get_episode("head_on-w2.4-d0.06-s0.6-v1")
    forward = {}
    for y in (0.0, 1.0):
        slow = profile(yield_fraction=y, reaction_delay_s=0.15, detour_distance_m=1.5,
                       gap_acceptance=0.0)
        result = simulate(spec, slow, Straight(), backend, record=True)
        tr = result.trajectory
        ped, robot = tr["ped_pose"][:, 0, :2], tr["robot_pose"][:, :2]
        step_v = np.diff(ped, axis=0) / 0.1 @ np.array(spec.ped_directions[0])
        dist = np.linalg.norm(ped - robot, axis=1)[:-1]
        approaching = (dist > 2.0) & (dist < 5.0)  # between the sensing range and L
        forward[y] = step_v[approaching].min()
        flags = np.bitwise_or.reduce(tr["ped_flags"][:, 0])
        assert flags & FLAG_REACTING and flags & FLAG_DETOURING
        assert bool(flags & FLAG_YIELDING) == (y == 1.0)
    assert forward[0.0] > 0.7 * 1.2
    assert forward[1.0] < 0.4 * 1.2


def test_reaction_starts_after_the_delay_once_the_robot_is_in_range():
    spec = get_episode("head_on-w3.0-d0.06-s0.6-v2")
    first = {}
    for tau in (0.15, 1.2):
        tr = simulate(spec, profile(reaction_delay_s=tau), Straight(), "orca",
                      record=True).trajectory
        dist = np.linalg.norm(tr["ped_pose"][:, 0, :2] - tr["robot_pose"][:, :2], axis=1)
        in_range = int(np.argmax(dist <= SENSE_RANGE))
        reacting = int(np.argmax(tr["ped_flags"][:, 0] & FLAG_REACTING))
        assert reacting * 0.1 >= in_range * 0.1 + tau - 1e-9
        first[tau] = reacting
    assert first[1.2] > first[0.15]


def test_without_a_robot_only_the_preferred_speed_matters():
    spec = get_episode("sidewalk-w2.4-d0.2-s1.0-v1")
    calm = simulate(spec, profile(spec.n_peds, yield_fraction=0.0, clearance_m=0.3,
                                  avoidance_gain=0.6, detour_distance_m=1.0,
                                  gap_acceptance=1.0), None)
    wary = simulate(spec, profile(spec.n_peds, yield_fraction=1.0, clearance_m=1.2,
                                  avoidance_gain=2.2, detour_distance_m=4.0,
                                  gap_acceptance=0.0), None)
    pd.testing.assert_series_equal(calm.pedestrians.travel_time, wary.pedestrians.travel_time)
    faster = simulate(spec, profile(spec.n_peds, speed_mps=1.6), None)
    assert faster.pedestrians.travel_time.mean() < calm.pedestrians.travel_time.mean()


def test_effective_clearance_shrinks_with_gap_acceptance():
    d, g = np.array([1.0, 1.0, 0.4]), np.array([0.0, 1.0, 0.5])
    assert effective_clearance(d, g) == pytest.approx([1.0, 0.65, 0.4 * (1 - 0.175)])


def test_waypoint_takes_the_passing_side_unless_a_wall_or_obstacle_blocks_it():
    walls = np.array([[-6.0, 1.2, 30.0, 1.2], [-6.0, -1.2, 30.0, -1.2]])
    no_obstacles = np.zeros((0, 3))
    out = np.zeros(2)
    # walking +x, passing side +1 = left (+y): free in the middle of the corridor
    _waypoint(5.0, 0.0, 1.0, 0.0, 1, 0.8, 0.35, walls, no_obstacles, out)
    assert out == pytest.approx([6.5, 0.8])
    # next to the left wall the same side is blocked: switch to the right
    _waypoint(5.0, 0.7, 1.0, 0.0, 1, 0.8, 0.35, walls, no_obstacles, out)
    assert out == pytest.approx([6.5, -0.1])
    # an obstacle on the right side, walking −x (right is +y): step to the left (−y)
    obstacle = np.array([[3.5, 0.8, 0.4]])
    _waypoint(5.0, 0.0, -1.0, 0.0, -1, 0.8, 0.35, walls, obstacle, out)
    assert out == pytest.approx([3.5, -0.8])
