"""simulate(): outcomes, metrics, matched initial states, input errors and determinism."""

import dataclasses
import json
import subprocess
import sys

import numpy as np
import pandas as pd
import pytest

from popnavshift.episodes import assign_slots, get_episode
from popnavshift.errors import ConfigError, InputError, UnknownNameError
from popnavshift.sim.run import simulate
from sim_helpers import CONTROLLERS_UNDER_TEST, Orca, Straight, members, one_pedestrian, rows


def test_initial_states_are_identical_across_populations_controllers_and_no_robot():
    spec = get_episode("crossing-w3.0-d0.2-s1.0-v2")
    runs = [
        simulate(spec, assign_slots(spec, members("slow", 30, 0.6)), None, record=True),
        simulate(spec, assign_slots(spec, members("fast", 30, 1.2)), Orca(), record=True),
        simulate(spec, None, Straight(), "hl", record=True),
    ]
    first = runs[0].trajectory["ped_pose"][0]
    assert np.allclose(first[:, :2], np.array(spec.ped_starts), atol=1e-5)
    for r in runs[1:]:
        np.testing.assert_array_equal(r.trajectory["ped_pose"][0], first)
    assert runs[0].trajectory["robot_pose"] is None
    assert runs[1].trajectory["robot_pose"][0, :2] == pytest.approx(spec.robot_start)


def test_the_analysis_time_limit_is_the_simulators():
    """The burden counts a blocked pedestrian at tables.TIME_LIMIT (the analysis may not
    import the simulator), which must be the limit the runs stop at."""
    from popnavshift import tables
    from popnavshift.sim import constants

    assert tables.TIME_LIMIT == constants.TIME_LIMIT


def test_a_no_robot_run_has_zero_added_delay_against_itself():
    spec = get_episode("bottleneck-w2.4-d0.12-s0.6-v1")
    slots = assign_slots(spec, members("mixed", 40, 0.6))
    a, b = simulate(spec, slots, None), simulate(spec, slots, "none")
    assert a.run["controller"] == "none" and a.run["outcome"] == "none"
    delay = b.pedestrians.travel_time - a.pedestrians.travel_time
    assert a.pedestrians.arrived.all() and (delay == 0.0).all()
    assert np.isnan(a.pedestrians.min_robot_clearance).all()
    assert np.isnan(a.run["robot_time"]) and a.run["ped_collisions"] == 0


def test_a_free_robot_succeeds_in_its_nominal_time():
    spec = one_pedestrian(get_episode("sidewalk-w2.4-d0.06-s0.6-v1"))
    result = simulate(spec, None, Straight(), record=True)
    run = result.run
    assert run["outcome"] == "success"
    assert run["robot_time"] == pytest.approx((20.0 - 0.3) / 0.6, abs=0.05)
    assert run["robot_path_length"] == pytest.approx(19.7, abs=0.02)
    assert run["robot_stop_time"] <= 0.1 and run["steps"] < 450
    robot = result.trajectory["robot_pose"]  # the run ended when the robot arrived
    assert np.linalg.norm(robot[-1, :2] - np.array(spec.robot_goal)) <= 0.3
    assert np.linalg.norm(robot[-2, :2] - np.array(spec.robot_goal)) > 0.3


def test_a_robot_driven_into_a_wall_is_a_world_collision_and_stops_in_place():
    spec = one_pedestrian(get_episode("sidewalk-w2.4-d0.06-s1.0-v1"))
    spec = dataclasses.replace(spec, robot_goal=(4.0, 5.0))  # beyond the wall at y = 1.2
    result = simulate(spec, None, Straight(), record=True)
    run = result.run
    assert run["outcome"] == "world_collision"
    assert run["world_collisions"] == 1 and run["ped_collisions"] == 0
    assert run["robot_time"] == 45.0 and run["outcome_time"] < 3.0
    robot = result.trajectory["robot_pose"][:, :2]
    after = robot[int(round(run["outcome_time"] / 0.1)):]
    assert np.ptp(after, axis=0).max() < 0.02


def test_a_robot_driven_into_a_pedestrian_is_a_pedestrian_collision():
    # a 1 m corridor: nobody can pass, the robot ignores the stopped pedestrian ahead
    base = get_episode("head_on-w1.8-d0.06-s1.0-v1")
    narrow = ((-6.0, 0.5, 30.0, 0.5), (-6.0, -0.5, 30.0, -0.5))
    spec = dataclasses.replace(base, walls=narrow, ped_starts=((10.0, 0.0),),
                               ped_goals=((-2.0, 0.0),), ped_vias=((-2.0, 0.0),))
    slots = pd.DataFrame([{"persona_id": "p", "speed_mps": 0.6, "clearance_m": 0.6,
                           "avoidance_gain": 1.0, "yield_fraction": 1.0, "reaction_delay_s": 0.15,
                           "detour_distance_m": 4.0, "gap_acceptance": 0.0}])
    result = simulate(spec, slots, Straight(), record=True)
    run = result.run
    assert run["outcome"] == "pedestrian_collision"
    assert run["ped_collisions"] >= 1 and run["world_collisions"] == 0
    # navground pushes overlapping agents apart within the step: contact reads as ≈ 0
    assert run["robot_min_clearance"] < 0.01
    assert result.pedestrians.min_robot_clearance[0] < 0.01


def test_a_robot_that_never_arrives_times_out_at_45_s():
    spec = get_episode("obstruction-w3.0-d0.12-s0.6-v1")
    run = simulate(spec, None, Straight(speed=0.0)).run
    assert run["outcome"] == "timeout" and run["robot_time"] == 45.0
    assert run["steps"] == 450 and run["robot_stop_time"] == pytest.approx(45.0)
    assert run["robot_path_length"] == pytest.approx(0.0, abs=1e-6)


def test_rows_have_one_pedestrian_per_slot_with_its_profile():
    spec = get_episode("sidewalk-w3.0-d0.2-s1.0-v3")
    slots = assign_slots(spec, members("mixed", 25, 0.9))
    result = simulate(spec, slots, Orca())
    peds = result.pedestrians
    assert len(peds) == spec.n_peds and peds.slot.tolist() == list(range(spec.n_peds))
    assert peds.persona_id.tolist() == slots.persona_id.tolist()
    np.testing.assert_array_equal(peds.speed_mps.to_numpy(), slots.speed_mps.to_numpy())
    arrived = peds[peds.arrived]
    assert (arrived.walk_distance >= arrived.walk_distance - arrived.detour).all()
    assert (arrived.detour > -1e-6).all() and (arrived.travel_time > 0).all()
    assert result.run["controller"] == "test_orca" and result.run["backend"] == "orca"
    assert result.run["peds_arrived"] == int(peds.arrived.sum())


def test_bad_inputs_raise_errors_that_name_the_problem():
    spec = get_episode("head_on-w2.4-d0.06-s1.0-v1")
    good = pd.DataFrame([{"persona_id": "p", "speed_mps": 1.0, "clearance_m": 0.5,
                          "avoidance_gain": 1.0, "yield_fraction": 0.5, "reaction_delay_s": 0.5,
                          "detour_distance_m": 2.0, "gap_acceptance": 0.5}])
    with pytest.raises(UnknownNameError, match="backend"):
        simulate(spec, good, None, "orcaa")
    with pytest.raises(UnknownNameError, match="controller"):
        simulate(spec, good, "no_such_controller")
    with pytest.raises(ConfigError, match="controller"):
        simulate(spec, good, 42)
    with pytest.raises(InputError, match="reaction_delay_s"):
        simulate(spec, good.assign(reaction_delay_s=3.0), None)
    with pytest.raises(InputError, match="speed_mps = nan at slot 0"):
        simulate(spec, good.assign(speed_mps=np.nan), None)
    with pytest.raises(InputError, match="expected 1 rows"):
        simulate(spec, pd.concat([good, good]), None)
    with pytest.raises(InputError, match="missing column"):
        simulate(spec, good.drop(columns="gap_acceptance"), None)


SCRIPT = """
import json, sys
sys.path.insert(0, {tests!r})
from sim_helpers import CONTROLLERS_UNDER_TEST, members, rows
from popnavshift.episodes import assign_slots, get_episode
from popnavshift.sim.run import simulate
spec = get_episode({episode!r})
slots = assign_slots(spec, members("mixed", 30, 0.6))
print(json.dumps({{name: rows(simulate(spec, slots, make()))
                  for name, make in CONTROLLERS_UNDER_TEST.items()}}))
"""
def test_runs_are_bit_identical_in_one_process_and_across_processes():
    episode = "obstruction-w2.4-d0.2-s1.0-v2"
    spec = get_episode(episode)
    slots = assign_slots(spec, members("mixed", 30, 0.6))
    first = {name: rows(simulate(spec, slots, make()))
             for name, make in CONTROLLERS_UNDER_TEST.items()}
    simulate(get_episode("sidewalk-w4.2-d0.2-s0.6-v1"), None, Orca())  # other state in between
    simulate(get_episode("crossing-w1.8-d0.2-s1.0-v1"), None, "early_yield")
    again = {name: rows(simulate(spec, slots, make()))
             for name, make in CONTROLLERS_UNDER_TEST.items()}
    assert json.dumps(again) == json.dumps(first)
    tests = str(__import__("pathlib").Path(__file__).parent)
    out = subprocess.run([sys.executable, "-c", SCRIPT.format(tests=tests, episode=episode)],
                         capture_output=True, text=True, check=True, timeout=120)
    assert out.stdout.strip() == json.dumps(first)


def test_the_metrics_computed_are_the_ones_the_tables_declare():
    """A metric is declared once in tables.py and computed in sim/metrics.py: a run's
    row and pedestrian columns carry exactly the declared metrics, in their order."""
    from popnavshift.sim.run import failed_result
    from popnavshift.tables import PEDESTRIAN_METRICS, PEDESTRIANS, ROBOT_METRICS, RUNS

    spec = get_episode("head_on-w2.4-d0.06-s1.0-v1")
    robot_names = [c.name for c in ROBOT_METRICS]
    ped_names = [c.name for c in PEDESTRIAN_METRICS]
    for result in (simulate(spec, None, "robot_orca"), simulate(spec, None, None),
                   failed_result(spec, "robot_orca", "orca")):
        assert set(result.run) <= set(RUNS.names)
        assert [k for k in result.run if k in robot_names] == robot_names
        assert set(result.ped_columns) <= set(PEDESTRIANS.names)
        assert [k for k in result.ped_columns if k in ped_names] == ped_names
