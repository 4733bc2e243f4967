"""The Gymnasium environment (popnavshift.learn.env) and the policy spaces (learn.spaces):
an episode of the environment is the study's run of the same id, pedestrian for
pedestrian; the observation is what the docstring says; the same seed and actions give
the same episode."""

from __future__ import annotations

import math
from pathlib import Path

import gymnasium as gym
import numpy as np
import pandas as pd
import pytest
from navground import core

from forked_cli import run_cli
from popnavshift.engine.rebuild import rebuild_run
from popnavshift.errors import ConfigError
from popnavshift.learn import spaces
from popnavshift.learn.env import ENV_ID, PopNavShiftEnv, make_env
from popnavshift.pipeline import read_table

# two crowded episodes (7 and 5 pedestrians, walls, a bottleneck and a disc), a C++
# controller and a Python one (the sampling controller, whose loop driver the study uses)
STUDY = """\
name: learnenv
personas: {source: synthetic, n: 60}
matched_n: 10
parts:
  main:
    populations: [mixed, high_caution]
    controllers: [robot_orca, reactive]
    backends: [orca]
    episodes: {ids: [bottleneck-w1.8-d0.2-s1.0-v1, obstruction-w1.8-d0.12-s0.6-v2]}
"""


@pytest.fixture(scope="module")
def study(tmp_path_factory) -> tuple[Path, Path]:
    """(study file, its finished folder)."""
    root = tmp_path_factory.mktemp("learnenv")
    path = root / "learnenv.yaml"
    path.write_text(STUDY)
    proc = run_cli("run", str(path), "--out", str(root / "s"), "--no-report", "-w", "1")
    assert proc.returncode == 0, proc.stderr
    return path, root / "s"


def _play(env: PopNavShiftEnv, episode: str, policy=None):
    """Run one episode with ``policy(obs, info)`` (None: the expert acts); the
    observations, rewards and the last step's info."""
    obs, info = env.reset(options={"episode": episode})
    observations, rewards = [obs], []
    while True:
        obs, reward, terminated, truncated, info = env.step(
            None if policy is None else policy(obs, info))
        observations.append(obs)
        rewards.append(reward)
        if terminated or truncated:
            return np.array(observations), np.array(rewards), info


def _same(a, b) -> bool:
    """Equal, bit for bit (NaN equals NaN)."""
    return bool(a == b) or (isinstance(a, float) and math.isnan(a) and math.isnan(b))


def test_an_episode_is_the_studys_run_of_that_id(study):
    path, folder = study
    runs = read_table(folder / "runs.parquet", "runs")
    peds = read_table(folder / "pedestrians.parquet", "pedestrians")
    pops = read_table(folder / "populations.parquet", "populations")
    robot_runs = runs[runs["controller"] != "none"]
    assert len(robot_runs) == 8
    envs: dict[tuple[str, str], PopNavShiftEnv] = {}
    for row in robot_runs.itertuples():
        key = (row.population, row.controller)
        if key not in envs:
            envs[key] = make_env(str(path), row.population, folder=folder,
                                 expert=row.controller, record=True)
        _, rewards, info = _play(envs[key], row.episode)
        got = info["run"]
        want = runs.loc[row.Index]
        for k in got.keys() - {"controller"}:
            assert _same(got[k], want[k]), (row.episode, row.controller, k, got[k], want[k])
        assert got["outcome"] == info["outcome"] == want["outcome"]
        # its pedestrians, slot by slot
        stored = peds[(peds["run_id"] == row.run_id)].sort_values("slot")
        mine = pd.DataFrame(info["pedestrians"])
        for column in mine.columns.drop(["controller"]):
            assert all(map(_same, mine[column].tolist(), stored[column].tolist())), column
        # and the trajectories of every agent, step by step, as the study rebuilds the run
        key_row = {"episode": row.episode, "population": row.population,
                   "controller": row.controller, "backend": row.backend, "mapping": row.mapping}
        again = rebuild_run(key_row, pops, 0, record=True).trajectory
        assert again is not None and info["trajectory"].keys() == again.keys()
        for name, value in again.items():
            np.testing.assert_array_equal(np.asarray(info["trajectory"][name]),
                                          np.asarray(value), err_msg=name)
        assert len(rewards) >= 1
        if got["outcome"] == "success":
            assert info["is_success"] and rewards.sum() > 10.0
    for env in envs.values():
        env.close()
    outcomes = set(robot_runs["outcome"])
    assert len(robot_runs["episode"].unique()) == 2 and outcomes  # both episodes compared


def test_same_seed_and_actions_give_the_same_episode(study):
    path, folder = study
    rng_actions = [np.random.default_rng(7).uniform(-0.2, 1.0, (500, 2)).astype(np.float32)
                   for _ in range(2)]
    played = []
    for actions in rng_actions:
        env = gym.make(ENV_ID, study=str(path), population="mixed", folder=folder,
                       max_episode_steps=None)
        obs, info = env.reset(seed=3)
        episode = info["episode"]
        out = [obs]
        for k in range(500):
            obs, reward, terminated, truncated, info = env.step(actions[k])
            out.append(np.append(obs, reward))
            if terminated or truncated:
                break
        played.append((episode, np.concatenate(out), info.get("run")))
        env.close()
    (e1, o1, r1), (e2, o2, r2) = played
    assert e1 == e2
    np.testing.assert_array_equal(o1, o2)
    assert r1 is not None and r1 == pytest.approx(r2, nan_ok=True)
    # another seed draws the episodes in another order: some seed picks the other one
    env = make_env(str(path), "mixed", folder=folder)
    picked = {env.reset(seed=s)[1]["episode"] for s in range(8)}
    env.close()
    assert picked == set(env.episode_ids) and len(picked) == 2


def test_a_policy_drives_the_robot_and_the_observation_stays_in_its_space(study):
    path, folder = study
    env = make_env(str(path), "high_caution", folder=folder)
    assert env.observation_space.shape == (spaces.OBSERVATION_SIZE,)
    assert env.action_space.shape == (spaces.ACTION_SIZE,)

    def forward(obs, info):  # straight ahead at half speed: hits something or arrives
        return np.array([0.5, 0.0], np.float32)

    observations, rewards, info = _play(env, "bottleneck-w1.8-d0.2-s1.0-v1", forward)
    assert info["outcome"] in {"success", "pedestrian_collision", "world_collision", "timeout"}
    assert info["run"]["controller"] == "gym:robot_orca"
    for obs in observations[:-1]:
        assert env.observation_space.contains(obs), obs
    # a robot told to go straight at half speed moves at about half the cell's speed
    run = info["run"]
    assert 0.45 < run["robot_path_length"] / run["outcome_time"] < 0.55
    expert = info["navground_action"]
    assert expert.shape == (2,)
    with pytest.raises(gym.error.ResetNeeded):
        env.step(np.zeros(2))
    env.reset(seed=0)
    with pytest.raises(ValueError, match="2 finite numbers"):
        env.step(np.array([np.nan, 0.0]))
    env.close()  # abandons the running episode


def test_bad_arguments_name_what_is_wrong(study):
    path, folder = study
    with pytest.raises(ConfigError, match="no population 'mixd'"):
        make_env(str(path), "mixd", folder=folder)
    with pytest.raises(ConfigError, match="not in part 'main'"):
        make_env(str(path), "mixed", folder=folder, episodes=["sidewalk-w1.8-d0.06-s1.0-v1"])
    with pytest.raises(ConfigError, match="no part 'other'"):
        make_env(str(path), "mixed", folder=folder, part="other")


def _robot(theta: float, speed: float = 1.0) -> core.Behavior:
    kin = core.kinematics.TwoWheelsDifferentialDriveKinematics(max_speed=speed, wheel_axis=0.5)
    behavior = core.behaviors.ORCABehavior(kin, 0.35)
    behavior.pose = core.Pose2((2.0, 0.0), theta)
    behavior.target = core.Target.Point((22.0, 0.0), 0.3)
    return behavior


def _fields(obs: np.ndarray) -> dict[str, np.ndarray]:
    out, i = {}, 0
    for name, size in spaces.observation_layout():
        out[name] = obs[i:i + size]
        i += size
    assert i == spaces.OBSERVATION_SIZE == obs.size
    return out


@pytest.mark.parametrize("theta", [0.0, math.pi / 2])
def test_the_observation_is_the_documented_one(theta):
    behavior = _robot(theta)
    state = behavior.environment_state
    state.neighbors = [core.Neighbor((4.0, 1.0), 0.25, (-1.0, 0.0), 1),   # 2.24 m
                       core.Neighbor((2.5, 0.0), 0.25, (0.0, 0.5), 2),    # 0.5 m
                       core.Neighbor((9.0, 0.0), 0.25, (0.0, 0.0), 3)]    # 7 m: not sensed
    state.line_obstacles = [core.LineSegment((-5.0, -0.9), (30.0, -0.9))]
    state.static_obstacles = [core.Disc((2.0, 3.0), 0.4)]
    ps = spaces.PolicySpaces(behavior)
    f = _fields(ps.observe(behavior, state))
    c, s = math.cos(theta), math.sin(theta)

    def robot_frame(x, y):
        return np.array([c * x + s * y, -s * x + c * y])

    np.testing.assert_allclose(f["pedestrians_position"],
                               np.concatenate([robot_frame(0.5, 0.0), robot_frame(2.0, 1.0),
                                               robot_frame(6.0, 0.0), np.zeros(6)]) / 6,
                               atol=1e-6)  # the 7 m one is clipped to the box, still valid
    np.testing.assert_array_equal(f["pedestrians_valid"], [1, 1, 1, 0, 0, 0])
    np.testing.assert_allclose(f["pedestrians_velocity"][:4],
                               np.concatenate([robot_frame(0.0, 0.5),
                                               robot_frame(-1.0, 0.0)]) / 2, atol=1e-6)
    np.testing.assert_allclose(f["obstacles_position"],
                               np.concatenate([robot_frame(0.0, -0.9), robot_frame(0.0, 2.6),
                                               [0, 0, 0, 0]]) / 6, atol=1e-6)
    np.testing.assert_array_equal(f["obstacles_valid"], [1, 1, 0, 0])
    np.testing.assert_allclose(f["ego_target_direction"], robot_frame(1.0, 0.0), atol=1e-6)
    np.testing.assert_allclose(f["ego_target_distance"], [19.7 / 25 * 2 - 1], atol=1e-6)
    np.testing.assert_array_equal(f["ego_velocity"], [0.0])
    assert ps.observation_space.contains(ps.observe(behavior, state))


def test_an_action_is_a_fraction_of_the_cells_caps():
    behavior = _robot(0.0, speed=0.6)
    ps = spaces.PolicySpaces(behavior)
    cmd = ps.command([0.5, -0.25], behavior, 0.1)
    assert cmd.velocity[0] == pytest.approx(0.3) and cmd.angular_speed == pytest.approx(
        -0.25 * 2 * 0.6 / 0.5)
    np.testing.assert_allclose(ps.action(cmd, behavior), [0.5, -0.25], atol=1e-6)
    # outside [-1, 1] is clipped; navground keeps the turn and cuts the speed
    full = ps.command([3.0, 1.0], behavior, 0.1)
    assert full.angular_speed == pytest.approx(2.4) and full.velocity[0] == pytest.approx(0.0)


def _linear_onnx(path: Path) -> None:
    """A tiny ONNX policy: action = clip(W · observation + b) with fixed weights that
    head towards the goal and away from the nearest pedestrian (no training, no torch)."""
    import onnx
    from onnx import TensorProto, helper

    layout = dict(spaces.observation_layout())
    offset = {name: sum(size for n, size in spaces.observation_layout()[:i])
              for i, (name, _) in enumerate(spaces.observation_layout())}
    assert sum(layout.values()) == spaces.OBSERVATION_SIZE
    w = np.zeros((spaces.OBSERVATION_SIZE, 2), np.float32)
    w[offset["ego_target_direction"], 0] = 0.8   # forward when the goal is ahead
    w[offset["ego_target_direction"] + 1, 1] = 1.5  # turn towards it
    w[offset["pedestrians_position"] + 1, 1] = -0.6  # turn away from the nearest one
    b = np.array([0.1, 0.0], np.float32)
    graph = helper.make_graph(
        [helper.make_node("MatMul", ["observation", "W"], ["xw"]),
         helper.make_node("Add", ["xw", "b"], ["raw"]),
         helper.make_node("Clip", ["raw", "lo", "hi"], ["action"])],
        "linear", [helper.make_tensor_value_info("observation", TensorProto.FLOAT, ["n", 47])],
        [helper.make_tensor_value_info("action", TensorProto.FLOAT, ["n", 2])],
        [helper.make_tensor("W", TensorProto.FLOAT, w.shape, w.flatten()),
         helper.make_tensor("b", TensorProto.FLOAT, b.shape, b),
         helper.make_tensor("lo", TensorProto.FLOAT, [], [-1.0]),
         helper.make_tensor("hi", TensorProto.FLOAT, [], [1.0])])
    onnx.save(helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)]), path)


def test_a_policy_in_the_environment_is_the_policy_as_a_studys_controller(study, tmp_path):
    """Training and evaluation see the same robot: an ONNX policy driving the environment
    gives the run that `popnavshift evaluate policy.onnx` simulates (part B's controller,
    popnavshift.learn.policy), outcome and metrics bit for bit."""
    import onnxruntime as ort

    import popnavshift.learn.policy  # noqa: F401  (a failed import is a failure, not a skip)
    from popnavshift.controller_ids import policy_id
    from popnavshift.episodes.specs import get_episode
    from popnavshift.sim.run import simulate
    from popnavshift.sim.slots import profiles_of_members

    path, folder = study
    onnx_path = tmp_path / "linear.onnx"
    _linear_onnx(onnx_path)
    options = ort.SessionOptions()
    options.intra_op_num_threads = options.inter_op_num_threads = 1
    session = ort.InferenceSession(str(onnx_path), options, providers=["CPUExecutionProvider"])

    def policy(obs, info):
        return session.run(["action"], {"observation": obs[None]})[0][0]

    env = make_env(str(path), "mixed", folder=folder)
    outcomes = set()
    for episode in env.episode_ids:
        _, _, info = _play(env, episode, policy)
        spec = get_episode(episode, seed=0)
        ref = simulate(spec, profiles_of_members(spec, *env.members),
                       policy_id(str(onnx_path)), "orca").run
        for k in ref.keys() - {"controller"}:
            assert _same(info["run"][k], ref[k]), (episode, k, info["run"][k], ref[k])
        outcomes.add(info["outcome"])
    env.close()
    assert outcomes  # both episodes ran to an outcome


def test_the_environment_adds_no_navground_behaviour_type():
    """The leaderboard lists navground's registered behaviours: the environment's robot
    behaviour runs only inside the environment and must not be one of them."""
    import subprocess
    import sys

    code = ("from navground import core; a = set(core.Behavior.types); "
            "import popnavshift.learn.env; print(sorted(set(core.Behavior.types) - a))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout
    assert out.strip() == "[]"


def test_gymnasiums_own_checker_passes(study):
    from gymnasium.utils.env_checker import check_env

    path, folder = study
    env = make_env(str(path), "mixed", folder=folder)
    check_env(env, skip_render_check=True)  # spaces, reset(seed) determinism, step API
    env.close()
