"""Robot controllers: contract, behaviour in tiny navground worlds, registry."""

from __future__ import annotations

import math
import random

import numpy as np
import pytest
from navground import core, sim

from popnavshift.errors import ConfigError, UnknownNameError
from popnavshift.sim.check import (
    ControllerContractError,
    check_controller,
    ped_agent,
    robot_agent,
)
from popnavshift.sim.controllers import CONTROLLERS
from popnavshift.sim.controllers.builtin import register_navground_types

DT = 0.1
GOAL = (20.0, 0.0)
FREE_RUN = 19.7  # [m] start to goal minus the 0.3 m tolerance


def corridor(width: float = 3.0) -> sim.World:
    world = sim.World()
    world.add_wall(sim.Wall((-2.0, -width / 2), (24.0, -width / 2)))
    world.add_wall(sim.Wall((-2.0, width / 2), (24.0, width / 2)))
    return world


def crowd(seed: int, width: float = 3.0, n: int = 8) -> sim.World:
    """Pedestrians walking both ways along a corridor (starts >= 0.7 m apart)."""
    rng = np.random.default_rng(seed)
    world, starts = corridor(width), []
    while len(starts) < n:
        x, y = rng.uniform(-1.0, 23.0), rng.uniform(-width / 2 + 0.35, width / 2 - 0.35)
        if math.hypot(x, y) > 1.5 and all(math.hypot(x - a, y - b) > 0.7 for a, b in starts):
            starts.append((x, y))
    for i, (x, y) in enumerate(starts):
        direction = 1.0 if i % 2 else -1.0
        world.add_agent(ped_agent((x, y), (x + 40 * direction, y), 1.2, i + 1))
    return world


def drive(world: sim.World, controller, speed: float, steps: int = 450, **params) -> dict:
    """Add the robot, run until arrival or ``steps``; the robot's record."""
    factory = CONTROLLERS.make(controller, **params)
    robot = robot_agent(factory, (0.0, 0.0), GOAL, speed, wheel_max=1.2 * speed)
    world.add_agent(robot)
    factory.after_placement(robot.behavior, DT)
    others = [a for a in world.agents if a is not robot]
    poses, speeds, phases, others_xy, collisions = [], [], [], [], 0
    arrival = None
    for step in range(steps):
        world.update(DT)
        poses.append((*robot.position, robot.orientation))
        speeds.append(float(np.linalg.norm(robot.velocity)))
        phases.append(getattr(robot.behavior, "phase", None))
        others_xy.append([tuple(a.position) for a in others])
        collisions += sum(robot in pair for pair in world.collisions)
        if math.dist(robot.position, GOAL) < 0.3:
            arrival = (step + 1) * DT
            break
    return {"poses": np.array(poses), "speeds": np.array(speeds), "phases": phases,
            "others": np.array(others_xy), "collisions": collisions, "arrival": arrival,
            "behavior": robot.behavior}


# ------------------------------------------------------------------ contract
@pytest.mark.parametrize("name", ["reactive", "early_yield", "robot_orca", "HRVO",
                                  "SocialForce"])
def test_controllers_pass_the_contract(name):
    check_controller(CONTROLLERS.make(name))


class _Infeasible(core.Behavior, name="PopNavShiftTestInfeasible"):
    def __init__(self, kinematics=None, radius=0.0):
        core.Behavior.__init__(self, kinematics, radius)

    def compute_cmd_internal(self, time_step):
        return core.Twist2((5.0, 0.0), 0.0, frame=core.Frame.relative)  # 5 m/s > limits


class _Jittery(_Infeasible, name="PopNavShiftTestJittery"):
    def compute_cmd_internal(self, time_step):
        return core.Twist2((random.uniform(0.0, 0.5), 0.0), 0.0, frame=core.Frame.relative)


class _Factory:
    def __init__(self, behavior_cls, shared=False):
        self.name, self._cls, self._shared = behavior_cls.__name__, behavior_cls, None
        self._share = shared

    def build(self, kinematics, radius, speed):
        if self._share and self._shared is not None:
            return self._shared
        behavior = self._cls(kinematics, radius)
        behavior.optimal_speed = speed
        self._shared = behavior
        return behavior

    def after_placement(self, behavior, dt):
        pass

    def describe(self):
        return {"controller": self.name}


@pytest.mark.parametrize("factory, message", [
    (_Factory(_Infeasible), "infeasible command"),
    (_Factory(_Jittery), "not deterministic"),
    (_Factory(_Jittery, shared=True), "new behaviour per robot"),
])
def test_check_controller_rejects_broken_factories(factory, message):
    with pytest.raises(ControllerContractError, match=message):
        check_controller(factory)


# ------------------------------------------------------------------ robot_orca
@pytest.mark.parametrize("speed", [0.6, 1.0])
def test_robot_orca_crosses_an_empty_corridor_at_its_cell_speed(speed):
    run = drive(corridor(), "robot_orca", speed)
    assert run["arrival"] is not None
    assert run["arrival"] == pytest.approx(FREE_RUN / speed, rel=0.1)


def test_robot_orca_options_reach_navground():
    # ORCABehavior has no Python attribute `effective_center`: assigning one
    # would silently do nothing, so the factory sets and reads back properties.
    kin = core.kinematics.TwoWheelsDifferentialDriveKinematics(max_speed=1.0, wheel_axis=0.5)
    behavior = CONTROLLERS.make("robot_orca", effective_center=True, time_horizon=4.0).build(
        kin, 0.35, 1.0)
    assert behavior.get("effective_center") is True
    assert behavior.time_horizon == pytest.approx(4.0)
    assert behavior.safety_margin == pytest.approx(0.12)


def test_robot_orca_passes_an_obstacle_exactly_on_its_line():
    world = corridor()
    world.add_obstacle(sim.Obstacle((8.0, 0.0), 0.25))  # plain ORCA stalls for good here
    run = drive(world, "robot_orca", 1.0)
    assert run["arrival"] is not None and run["collisions"] == 0


# ------------------------------------------------------------------ reactive
def test_reactive_goes_straight_when_nothing_is_in_the_way():
    run = drive(corridor(), "reactive", 1.0)
    assert run["arrival"] == pytest.approx(FREE_RUN, rel=0.02)
    assert np.abs(run["poses"][:, 1]).max() < 1e-3
    assert run["behavior"].mode_counts["adjust"] == 0


@pytest.mark.parametrize("speed", [0.6, 1.0])
def test_reactive_avoids_a_standing_pedestrian(speed):
    world = corridor()
    world.add_agent(ped_agent((8.0, 0.0), None, 0.0, 1))  # on the robot's line, zero speed
    run = drive(world, "reactive", speed)
    assert run["arrival"] is not None and run["collisions"] == 0
    assert np.abs(run["poses"][:, 1]).max() > 0.3  # it went around
    assert run["behavior"].mode_counts["adjust"] > 0


# ------------------------------------------------------------------ early_yield
def test_early_yield_waits_for_a_crossing_pedestrian_then_resumes():
    world = sim.World()
    world.add_agent(ped_agent((6.0, 10.0), (6.0, -10.0), 1.0, 1))  # would meet the robot at x=6
    run = drive(world, "early_yield", 0.6)
    waiting = np.array([p == "wait" for p in run["phases"]])
    assert waiting.sum() >= 10
    still = run["poses"][waiting, :2]
    assert run["speeds"][waiting].max() < 0.05
    assert np.ptp(still, axis=0).max() < 0.05  # position held while waiting
    crossing = int(np.argmax(run["others"][:, 0, 1] < 0.0))  # the pedestrian crosses y = 0
    assert run["poses"][crossing, 0] < 6.0 - 0.6  # ... with the robot still short of x = 6
    assert run["phases"][-1] == "go"
    assert run["arrival"] is not None and run["collisions"] == 0


def test_early_yield_ignores_a_pedestrian_walking_its_way():
    world = corridor()
    world.add_agent(ped_agent((3.0, 0.0), (40.0, 0.0), 0.3, 1))  # slow, ahead, same way
    run = drive(world, "early_yield", 1.0)
    assert run["behavior"].yields == 0


# ------------------------------------------------------------------ determinism
@pytest.mark.parametrize("name", ["reactive", "early_yield", "robot_orca"])
def test_same_world_twice_gives_identical_trajectories(name):
    first = drive(crowd(3), name, 1.0, steps=250)
    second = drive(crowd(3), name, 1.0, steps=250)
    np.testing.assert_array_equal(first["poses"], second["poses"])
    other = drive(crowd(4), name, 1.0, steps=250)
    n = min(len(first["poses"]), len(other["poses"]))
    assert not np.array_equal(first["poses"][:n], other["poses"][:n])


# ------------------------------------------------------------------ registry
def test_navground_types_are_controllers_with_checked_properties():
    kin = core.kinematics.TwoWheelsDifferentialDriveKinematics(max_speed=1.0, wheel_axis=0.5)
    behavior = CONTROLLERS.make("HRVO", safety_margin=0.1, max_neighbors=8).build(kin, 0.35, 0.6)
    assert behavior.get("max_neighbors") == 8
    assert behavior.safety_margin == pytest.approx(0.1)
    assert behavior.optimal_speed == pytest.approx(0.6)
    run = drive(corridor(), "SocialForce", 1.0)
    assert run["arrival"] is not None


def test_a_navground_type_defined_later_is_registered_on_demand():
    class _Late(_Infeasible, name="PopNavShiftTestLate"):
        pass

    assert "PopNavShiftTestLate" in register_navground_types()
    assert register_navground_types() == []
    assert "PopNavShiftTestLate" in CONTROLLERS


def test_our_own_behaviours_are_never_bare_controllers():
    """OWN_BEHAVIORS names the navground types of reactive.py and early_yield.py without
    importing them (listing the controllers imports no controller's code)."""
    from popnavshift.sim.controllers import builtin, early_yield, reactive

    assert {reactive.NAVGROUND_NAME, early_yield.NAVGROUND_NAME} == builtin.OWN_BEHAVIORS
    assert {reactive.NAVGROUND_NAME, early_yield.NAVGROUND_NAME} <= set(core.Behavior.types)
    register_navground_types()
    assert not builtin.OWN_BEHAVIORS & set(CONTROLLERS.names())


@pytest.mark.parametrize("name, close", [("reactiv", "reactive"), ("HRV0", "HRVO"),
                                         ("hrvo", "HRVO"), ("Reactive", "reactive"),
                                         ("early-yield", "early_yield")])
def test_unknown_controller_suggests_the_closest_names(name, close):
    with pytest.raises(UnknownNameError, match=f"did you mean.*'{close}'"):
        CONTROLLERS.make(name)


@pytest.mark.parametrize("name, params, message", [
    ("reactive", {"bufer": 0.1}, r"no parameter 'bufer'; allowed: .*buffer"),
    ("robot_orca", {"safety_margin": -0.1}, r"'safety_margin' must be >= 0.0, got -0.1"),
    ("early_yield", {"max_wait": "long"}, r"'max_wait' must be a finite float, got 'long'"),
    ("reactive", {"n_speeds": 2.5}, r"'n_speeds' must be an? int"),
    ("robot_orca", {"effective_center": 1}, r"'effective_center' must be an? bool"),
    ("reactive", {"rollout_time": float("nan")}, r"'rollout_time' must be a finite float"),
    ("HRVO", {"tau": 0.5}, r"no parameter 'tau'; allowed: .*max_neighbors"),
    ("HRVO", {"max_neighbors": "many"}, r"'max_neighbors' must be an? int"),
])
def test_bad_parameters_are_config_errors_naming_them(name, params, message):
    with pytest.raises(ConfigError, match=message):
        CONTROLLERS.make(name, **params)


def test_describe_lists_every_parameter():
    for name in ("reactive", "early_yield", "robot_orca"):
        described = CONTROLLERS.make(name).describe()
        assert described["controller"] == name
    assert CONTROLLERS.make("robot_orca").describe()["time_horizon"] == 2.0
    assert CONTROLLERS.make("early_yield").describe()["conflict_horizon"] == 4.5
    assert CONTROLLERS.make("reactive").describe()["buffer"] == 0.04


def test_a_behavior_without_a_geometric_state_gets_no_sensing():
    """navground's Dummy has no geometric state: bounded sensing would only make navground
    warn once per run (2,633 times over a paper-study card) that it cannot fill it."""
    from navground import core

    from popnavshift.sim.world import robot_sensing

    kin = core.kinematics.TwoWheelsDifferentialDriveKinematics(max_speed=1.0, wheel_axis=0.5)
    assert robot_sensing(core.behaviors.DummyBehavior(kin, 0.35)) == []
    assert len(robot_sensing(core.behaviors.HLBehavior(kin, 0.35))) == 1
    assert robot_sensing(core.behaviors.HLBehavior(kin, 0.35), wanted=False) == []
