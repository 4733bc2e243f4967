"""Loop drivers: the fast path of ``reactive`` and ``early_yield`` gives the runs of
their navground behaviours, bit for bit."""

from __future__ import annotations

import numpy as np
import pytest
from navground import core

from popnavshift.episodes import assign_slots, get_episode
from popnavshift.sim.bench import synthetic_population
from popnavshift.sim.check import (
    BehaviourOnly,
    ControllerContractError,
    check_controller,
)
from popnavshift.sim.controllers import CONTROLLERS
from popnavshift.sim.controllers.reactive import ReactiveDriver
from popnavshift.sim.run import simulate

# narrow and dense, where the robot adjusts, yields and collides; a wide one; one pedestrian
EPISODES = ("bottleneck-w2.4-d0.12-s1.0-v2", "crossing-w1.8-d0.2-s0.6-v1",
            "sidewalk-w1.8-d0.2-s1.0-v3", "obstruction-w3.0-d0.12-s1.0-v1",
            "sidewalk-w4.2-d0.06-s0.6-v2", "head_on-w1.8-d0.06-s1.0-v1")


class Watched(BehaviourOnly):
    """The factory itself, loop driver included, keeping the drivers it makes."""

    def __init__(self, factory) -> None:
        super().__init__(factory)
        self.drivers = []

    def loop_driver(self):
        self.drivers.append(self.factory.loop_driver())
        return self.drivers[-1]


def same(a, b) -> bool:
    return a == b or (isinstance(a, float) and np.isnan(a) and np.isnan(b))


@pytest.mark.parametrize("name", ["reactive", "early_yield"])
@pytest.mark.parametrize("backend", ["orca", "hl"])
def test_a_loop_driver_gives_the_run_of_its_navground_behaviour(name, backend):
    population = synthetic_population(0)
    watched = Watched(CONTROLLERS.make(name))
    outcomes = set()
    for episode in EPISODES:
        spec = get_episode(episode)
        slots = assign_slots(spec, population)
        fast = simulate(spec, slots, watched, backend, record=True)
        slow = simulate(spec, slots, BehaviourOnly(CONTROLLERS.make(name)), backend, record=True)
        assert all(same(fast.run[k], slow.run[k]) for k in fast.run), (episode, fast.run, slow.run)
        assert fast.pedestrians.equals(slow.pedestrians), episode
        np.testing.assert_array_equal(fast.trajectory["robot_pose"], slow.trajectory["robot_pose"])
        np.testing.assert_array_equal(fast.trajectory["ped_pose"], slow.trajectory["ped_pose"])
        outcomes.add(fast.run["outcome"])
    # the sample exercises the drivers' decisions, not only driving straight
    if name == "reactive":
        assert sum(d.mode_counts["adjust"] for d in watched.drivers) > 20
    else:
        assert sum(d.machine.yields for d in watched.drivers) >= 3
    assert "success" in outcomes


def test_a_reactive_driver_robot_senses_nothing_itself():
    """The reactive driver's robot has no navground sensing (the loop senses for it)."""
    from popnavshift.sim.backends import BACKENDS
    from popnavshift.sim.world import build_world

    spec = get_episode(EPISODES[0])
    driver = CONTROLLERS.make("reactive").loop_driver()
    sw = build_world(spec, np.full(spec.n_peds, 1.2), driver, BACKENDS.make("orca"))
    assert sw.robot is not None and list(sw.robot.state_estimations) == []
    yielding = CONTROLLERS.make("early_yield").loop_driver()
    sw = build_world(spec, np.full(spec.n_peds, 1.2), yielding, BACKENDS.make("orca"))
    assert sw.robot is not None and len(sw.robot.state_estimations) == 1


class BrokenDriver(ReactiveDriver):
    """The reactive driver, raising at the 5th step."""

    def step(self, step, pose, peds, ids):
        if step == 5:
            raise RuntimeError("driver broke")
        super().step(step, pose, peds, ids)


class Raising(Watched):
    def loop_driver(self):
        return BrokenDriver(self.factory.params)


def test_a_raising_driver_is_the_controllers_error_with_the_time():
    from popnavshift.sim.run import ControllerError

    spec = get_episode(EPISODES[0])
    with pytest.raises(ControllerError, match=r"'reactive' raised RuntimeError at t = 0\.4 s"):
        simulate(spec, None, Raising(CONTROLLERS.make("reactive")))


class Drifting(ReactiveDriver):
    """A driver that decides like the behaviour but turns a little more."""

    def step(self, step, pose, peds, ids):
        super().step(step, pose, peds, ids)
        if self._last is not None:
            v, w = self._last
            self._controller.follow_manual_cmd(core.Twist2((v, 0.0), w + 0.01,
                                                            core.Frame.relative))


class DriftingFactory(Watched):
    def loop_driver(self):
        return Drifting(self.factory.params)


def test_the_contract_check_compares_a_driver_with_its_behaviour():
    check_controller(CONTROLLERS.make("reactive"))
    check_controller(CONTROLLERS.make("early_yield"))
    with pytest.raises(ControllerContractError, match="loop driver and its behaviour part ways"):
        check_controller(DriftingFactory(CONTROLLERS.make("reactive")))
