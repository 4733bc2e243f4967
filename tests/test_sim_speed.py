"""The speed paths give the one-step-at-a-time results: quiet stretches (sim.quiet), their
rerun when a stretch was not quiet, and a worker's cached slot profiles (engine.worker)."""

import dataclasses
import gc
import json
import weakref

import pandas as pd
import pytest

import popnavshift.sim.loop as loop_module
from popnavshift.design.plan import Run
from popnavshift.engine.batches import Batch
from popnavshift.engine.worker import Context, run_batch
from popnavshift.episodes import assign_slots, get_episode
from popnavshift.sim.quiet import NotQuiet
from popnavshift.sim.run import simulate
from sim_helpers import Orca, Straight, members, one_pedestrian, rows

EPISODES = ("head_on-w2.4-d0.06-s1.0-v1", "sidewalk-w3.0-d0.12-s0.6-v2",
            "crossing-w1.8-d0.2-s1.0-v1", "obstruction-w4.2-d0.12-s0.6-v3",
            "bottleneck-w3.0-d0.06-s1.0-v1")
CONTROLLERS = {"none": lambda: None, "robot_orca": lambda: "robot_orca",
               "early_yield": lambda: "early_yield", "reactive": lambda: "reactive",
               "test_orca": Orca}


@pytest.fixture
def stretch_log(monkeypatch):
    """Counts the stretches the loop runs and the ones that were not quiet."""
    log = {"stretches": 0, "steps": 0, "not_quiet": 0}
    original = loop_module.StepLoop._stretch

    def counted(self, step, k, robot_in, robot_active):
        log["stretches"] += 1
        log["steps"] += k
        try:
            original(self, step, k, robot_in, robot_active)
        except NotQuiet:
            log["not_quiet"] += 1
            raise

    monkeypatch.setattr(loop_module.StepLoop, "_stretch", counted)
    return log


@pytest.mark.parametrize("backend", ["orca", "hl"])
def test_quiet_stretches_give_the_step_by_step_runs(backend, stretch_log):
    population = members("mixed", 30, 0.6)
    for episode in EPISODES:
        spec = get_episode(episode)
        slots = assign_slots(spec, population)
        for make in CONTROLLERS.values():
            fast = rows(simulate(spec, slots, make(), backend))
            slow = rows(simulate(spec, slots, make(), backend, stretches=False))
            assert json.dumps(fast) == json.dumps(slow), (episode, make())
    assert stretch_log["steps"] > 1000  # the shortcut was taken, and often


def test_a_stretch_that_was_not_quiet_reruns_the_run_step_by_step(monkeypatch, stretch_log):
    """A bound that promises too much (every stretch as long as allowed) must not
    change a single value: the run is simulated again step by step."""
    monkeypatch.setattr(loop_module, "quiet_steps", lambda *args: args[-1])
    spec = get_episode("crossing-w1.8-d0.2-s1.0-v1")
    slots = assign_slots(spec, members("mixed", 30, 0.6))
    for name in ("none", "robot_orca", "early_yield"):
        fast = rows(simulate(spec, slots, CONTROLLERS[name]()))
        slow = rows(simulate(spec, slots, CONTROLLERS[name](), stretches=False))
        assert json.dumps(fast) == json.dumps(slow), name
    assert stretch_log["not_quiet"] >= 3


def test_a_recorded_run_steps_every_step(stretch_log):
    spec = get_episode("head_on-w2.4-d0.06-s1.0-v1")
    result = simulate(spec, None, "robot_orca", record=True)
    assert stretch_log["stretches"] == 0
    assert result.trajectory is not None


def test_a_worker_batch_gives_the_runs_of_simulate_with_assigned_slots():
    """run_batch picks slot profiles from cached per-population arrays; the rows must
    be those of simulate() on assign_slots() tables, stepped one step at a time."""
    population = pd.concat([members("mixed", 30, 0.6), members("slow", 12, 0.6)])
    spec = get_episode("sidewalk-w1.8-d0.2-s1.0-v1")
    runs = tuple(Run(spec.id, pop, ctrl, "orca", "A", "main")
                 for pop in ("mixed", "slow") for ctrl in ("none", "robot_orca", "reactive"))
    context = Context(populations=population, episode_seed=0, specs={})
    _, run_table, ped_table, _ = run_batch(Batch(spec.id, "orca", "A", runs), context)
    for i, r in enumerate(runs):
        members_of = population[population["population"] == r.population]
        expected = simulate(spec, assign_slots(spec, members_of.sort_values("persona_id")),
                            None if r.controller == "none" else r.controller, stretches=False)
        got = run_table.iloc[i][list(expected.run)]
        assert got.equals(pd.Series(expected.run, dtype=object)), r
        peds = ped_table[(ped_table["population"] == r.population)
                         & (ped_table["controller"] == r.controller)].reset_index(drop=True)
        assert peds[list(expected.pedestrians.columns)].equals(expected.pedestrians)


def test_a_run_leaves_no_recording_alive(monkeypatch):
    """The stretches' recording callback must not keep a finished run's recording
    (and its world) alive through C++, out of the garbage collector's reach."""
    recordings = []
    execute = loop_module.StepLoop.execute

    def keep_a_weak_reference(self):
        try:
            return execute(self)
        finally:
            recordings.append(weakref.ref(self.rec))

    monkeypatch.setattr(loop_module.StepLoop, "execute", keep_a_weak_reference)
    spec = get_episode("head_on-w2.4-d0.06-s1.0-v1")
    for controller in ("robot_orca", None):
        simulate(spec, None, controller)
    gc.collect()
    assert len(recordings) == 2 and all(ref() is None for ref in recordings)


def test_a_wall_contact_inside_a_stretch_reruns_the_run(stretch_log):
    """A robot that drives into a wall far from everyone touches it inside a stretch:
    the collision record must catch it, and the run must come out as step by step."""
    spec = one_pedestrian(get_episode("sidewalk-w2.4-d0.06-s1.0-v1"))
    spec = dataclasses.replace(spec, robot_goal=(4.0, 5.0))  # beyond the wall at y = 1.2
    fast, slow = (simulate(spec, None, Straight(), stretches=s) for s in (True, False))
    assert fast.run["outcome"] == "world_collision"
    assert json.dumps(rows(fast)) == json.dumps(rows(slow))
    assert stretch_log["not_quiet"] == 1


def test_a_batch_simulates_runs_with_equal_inputs_once_and_gives_each_its_own_rows():
    """Two populations with the same profiles under other persona ids (and a third that
    differs): the twin's runs are copied, not simulated, and every row is the row of
    that run simulated on its own, in its own batch."""
    mixed = members("mixed", 30, 0.6)
    twin = mixed.assign(population="twin", persona_id=[f"t{i:02d}" for i in range(30)])
    population = pd.concat([mixed, twin, members("slow", 30, 0.6)])
    spec = get_episode("sidewalk-w1.8-d0.2-s1.0-v1")
    pops, ctrls = ("mixed", "twin", "slow"), ("none", "robot_orca", "reactive")
    runs = tuple(Run(spec.id, p, c, "orca", "A", "main") for p in pops for c in ctrls)
    context = Context(populations=population, episode_seed=0, specs={})
    _, run_table, ped_table, simulated = run_batch(Batch(spec.id, "orca", "A", runs), context)
    assert simulated == 6
    for p in pops:
        alone = tuple(r for r in runs if r.population == p)
        _, own_runs, own_peds, n = run_batch(Batch(spec.id, "orca", "A", alone), context)
        assert n == 3
        mine = run_table[run_table["population"] == p].reset_index(drop=True)
        assert mine.equals(own_runs)
        assert ped_table[ped_table["population"] == p].reset_index(drop=True).equals(own_peds)
    twin_ids = set(ped_table.loc[ped_table["population"] == "twin", "persona_id"])
    assert twin_ids and all(i.startswith("t") for i in twin_ids)
