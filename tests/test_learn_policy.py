"""Learned policies as controllers (popnavshift.learn.policy): a tiny ONNX policy made here
(a linear map from the observation to an action heading for the goal) runs as a controller
through the contract check, in a study with one and two worker processes (bit-identical
runs), and gets a card from ``popnavshift evaluate policy.onnx``; its id changes with the
file; a bad file is one line and exit 2."""

from __future__ import annotations

import hashlib
import importlib.util
import json
import zipfile
from pathlib import Path

# navground-learning and onnxruntime are in the dev extra: without them these tests fail
# (an import error), they are not skipped; only the SB3 test skips without torch
import navground.learning  # noqa: E402, F401
import numpy as np
import onnxruntime  # noqa: E402, F401
import pytest

from cli_helpers import assert_one_line_error, cli  # noqa: E402
from policy_helpers import goal_policy, goal_weights, linear_onnx, observation_layout  # noqa: E402
from popnavshift.controller_ids import (  # noqa: E402
    parse_controller_id,
    policy_id,
    policy_label,
)
from popnavshift.episodes.specs import get_episode  # noqa: E402
from popnavshift.errors import ConfigError  # noqa: E402
from popnavshift.evaluate.card_files import slug  # noqa: E402
from popnavshift.sim.check import check_controller  # noqa: E402
from popnavshift.sim.controllers import CONTROLLERS  # noqa: E402
from popnavshift.sim.run import simulate  # noqa: E402

HEAD_ON = "head_on-w1.8-d0.06-s0.6-v1"  # three pedestrians, the robot at 0.6 m/s
EPISODES = (HEAD_ON, "crossing-w1.8-d0.2-s1.0-v1")  # two batches: both workers run one
HAS_SB3 = (importlib.util.find_spec("torch") is not None
           and importlib.util.find_spec("stable_baselines3") is not None)


@pytest.fixture(scope="module")
def policy(tmp_path_factory) -> Path:
    return goal_policy(tmp_path_factory.mktemp("policy") / "goal.onnx")


def test_a_policy_file_is_named_by_its_absolute_path_and_content_hash(tmp_path, monkeypatch):
    path = goal_policy(tmp_path / "goal.onnx")
    monkeypatch.chdir(tmp_path)
    identity = policy_id("goal.onnx")
    name, params = parse_controller_id(identity)
    assert name == "policy" and params["file"] == str(path.resolve())
    assert params["sha256"] == hashlib.sha256(path.read_bytes()).hexdigest()[:16]
    assert policy_label(identity) == f"goal.onnx (sha256 {params['sha256']})"
    assert slug(identity).startswith(f"policy-goal.onnx-{params['sha256']}-")
    goal_policy(path, forward=0.5)  # another policy in the same file: another controller
    assert policy_id("goal.onnx") != identity


def test_an_id_whose_file_changed_since_is_refused(tmp_path):
    path = goal_policy(tmp_path / "goal.onnx")
    identity = policy_id(str(path))
    CONTROLLERS.make(identity)
    goal_policy(path, turn=0.5)
    with pytest.raises(ConfigError, match="has changed"):
        CONTROLLERS.make(identity)
    path.unlink()
    with pytest.raises(ConfigError, match="does not exist"):
        CONTROLLERS.make(identity)


def test_the_policy_passes_the_contract_check(policy):
    factory = CONTROLLERS.make(policy_id(str(policy)))
    check_controller(factory)  # raises at the first broken rule
    assert factory.describe()["sha256"] == hashlib.sha256(policy.read_bytes()).hexdigest()


def test_the_policy_drives_the_robot_and_the_same_run_twice_is_identical(policy, tmp_path):
    """The goal-seeking policy reaches the goal of a head-on corridor; a policy that outputs
    zero does not move (so the actions do reach the robot)."""
    spec = get_episode(HEAD_ON)
    first = simulate(spec, None, policy_id(str(policy)), record=True)
    second = simulate(spec, None, policy_id(str(policy)), record=True)
    assert first.run["outcome"] == "success", first.run
    assert first.run == second.run
    assert np.array_equal(first.trajectory["robot_pose"], second.trajectory["robot_pose"],
                          equal_nan=True)
    n_obs, n_act, _ = observation_layout()
    still = linear_onnx(tmp_path / "still.onnx", np.zeros((n_obs, n_act), np.float32),
                        np.zeros(n_act, np.float32))
    idle = simulate(spec, None, policy_id(str(still)))
    assert idle.run["outcome"] != "success" and idle.run["robot_path_length"] < 0.01


def test_navground_learnings_behaviours_are_not_leaderboard_rows():
    import navground.learning.behaviors  # noqa: F401  (registers Policy, GroupPolicy)

    from popnavshift.evaluate.leaderboard import navground_controllers

    assert not {"Policy", "GroupPolicy"} & set(navground_controllers())


TINY = """\
name: tiny
personas: {{source: synthetic, n: 60}}
matched_n: 10
parts:
  main:
    populations: [mixed]
    controllers: [robot_orca, '{policy}']
    backends: [orca]
    mapping: A
    episodes: {{ids: [{episodes}]}}
"""


@pytest.mark.slow  # two small studies
def test_a_study_with_the_policy_gives_the_same_runs_with_one_and_two_workers(policy,
                                                                             tmp_path):
    study = tmp_path / "tiny.yaml"
    study.write_text(TINY.format(policy=policy_id(str(policy)), episodes=", ".join(EPISODES)))
    for out, workers in (("one", "1"), ("two", "2")):
        proc = cli("run", str(study), "--out", str(tmp_path / out), "--no-report", "-w", workers)
        assert proc.returncode == 0, proc.stderr
    one, two = ((tmp_path / out / "runs.parquet").read_bytes() for out in ("one", "two"))
    assert one == two
    import pandas as pd

    runs = pd.read_parquet(tmp_path / "one" / "runs.parquet")
    own = runs[runs["controller"] == policy_id(str(policy))]
    assert len(own) == len(EPISODES) and (own["outcome"] != "controller_error").all()


@pytest.mark.slow  # a tiny study and the policy's card
def test_evaluate_policy_onnx_gives_its_card(policy, finished, tmp_path):
    import shutil

    folder = tmp_path / "s"
    shutil.copytree(finished, folder)
    shutil.copy(finished.parent / "tiny.yaml", tmp_path / "tiny.yaml")
    proc = cli("evaluate", str(policy), "--study", str(tmp_path / "tiny.yaml"), "-d",
               str(folder), "--baselines", "robot_orca", "--n-boot", "20", "-w", "2")
    assert proc.returncode == 0, proc.stderr
    assert "contract check passed" in proc.stderr
    sha = hashlib.sha256(policy.read_bytes()).hexdigest()
    (card,) = (folder / "evaluate").iterdir()
    assert card.name.startswith(f"policy-goal.onnx-{sha[:16]}")
    record = json.loads((card / "evaluation.json").read_text())
    assert record["description"]["file"] == "goal.onnx"
    assert record["description"]["sha256"] == sha
    html = (card / "card.html").read_text()
    assert "goal.onnx" in html and sha[:16] in html
    again = cli("evaluate", str(policy), "--study", str(tmp_path / "tiny.yaml"), "-d",
                str(folder), "--baselines", "robot_orca", "--n-boot", "20")
    assert again.returncode == 0 and "card is current, reused" in again.stderr
    page = tmp_path / "side" / "compare.html"
    side = cli("compare", str(policy), "--study", str(tmp_path / "tiny.yaml"),
               "-d", str(folder), "--baselines", "robot_orca", "--n-boot", "20", "-o",
               str(page))
    assert side.returncode == 0, side.stderr
    label = f"goal.onnx (sha256 {sha[:16]})"  # a page names the file, not this machine's path
    for suffix in (".md", ".tex", ".html"):
        text = page.with_suffix(suffix).read_text()
        assert label.replace("_", "\\_") in text or label in text, suffix
        assert str(policy.parent) not in text, suffix
    assert str(policy) in page.with_suffix(".csv").read_text()  # the CSV keeps the id


def _wrong_input(folder: Path) -> Path:
    w, b = goal_weights()
    return linear_onnx(folder / "wrong_input.onnx", w[:7], b)


def _wrong_output(folder: Path) -> Path:
    n_obs, _, _ = observation_layout()
    return linear_onnx(folder / "wrong_output.onnx", np.zeros((n_obs, 3), np.float32),
                       np.zeros(3, np.float32))


def _text(name: str):
    def make(folder: Path) -> Path:
        (folder / name).write_text("not a model\n")
        return folder / name
    return make


def _zip_without_data(folder: Path) -> Path:
    with zipfile.ZipFile(folder / "model.zip", "w") as archive:
        archive.writestr("policy.pth", b"")
    return folder / "model.zip"


BAD = {
    "missing": (lambda folder: folder / "missing.onnx", "does not exist"),
    "not_onnx": (_text("notes.onnx"), "is not an ONNX model"),
    "wrong_input": (_wrong_input, "observes"),
    "wrong_output": (_wrong_output, "a PopNavShift action is 2"),
    "zip": (_zip_without_data, "not a Stable-Baselines3 model zip" if HAS_SB3
            else "pip install -e '.[learn]'"),
    "not_zip": (_text("model.zip"), "not a Stable-Baselines3 model zip" if HAS_SB3
                else "pip install -e '.[learn]'"),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_a_bad_policy_file_is_one_line_and_exit_2(case, tmp_path):
    make, needle = BAD[case]
    path = make(tmp_path)
    proc = cli("evaluate", str(path), "--study", "quick", "-d", str(tmp_path / "study"))
    assert_one_line_error(proc, needle, path.name)
    assert not (tmp_path / "study").exists()  # refused before any folder is made


@pytest.mark.parametrize("name", ["policy", 'policy{"file":"/tmp/x.onnx"}'])
def test_the_bare_policy_name_says_how_to_name_a_policy(name):
    with pytest.raises(ConfigError, match="needs its file and hash.*evaluate policy.onnx"):
        CONTROLLERS.make(name)


@pytest.mark.parametrize("command", ["compare", "leaderboard"])
def test_compare_and_the_leaderboard_take_policy_files_and_refuse_a_bad_one(command, policy,
                                                                          tmp_path):
    from popnavshift.design.study import load_study
    from popnavshift.evaluate.leaderboard import leaderboard_controllers

    assert policy_id(str(policy)) in leaderboard_controllers(load_study("quick"), [str(policy)])
    bad = _text("notes.onnx")(tmp_path)
    proc = cli(command, str(policy), str(bad), "--study", "quick", "-d", str(tmp_path / "s"))
    assert_one_line_error(proc, "is not an ONNX model", "notes.onnx")
    assert not (tmp_path / "s").exists()


@pytest.mark.skipif(not HAS_SB3, reason="torch and stable-baselines3 are not installed "
                    "(pip install -e '.[learn]'): the Stable-Baselines3 zip is not tested")
def test_a_stable_baselines3_zip_runs_deterministically(tmp_path):
    import gymnasium as gym
    from stable_baselines3 import PPO

    n_obs, n_act, _ = observation_layout()

    class Spaces(gym.Env):
        observation_space = gym.spaces.Box(-np.inf, np.inf, (n_obs,), np.float32)
        action_space = gym.spaces.Box(-1, 1, (n_act,), np.float32)

    model = PPO("MlpPolicy", Spaces(), seed=0, device="cpu")
    model.save(tmp_path / "model.zip")
    identity = policy_id(str(tmp_path / "model.zip"))
    check_controller(CONTROLLERS.make(identity))
    runs = [simulate(get_episode(HEAD_ON), None, identity).run for _ in range(2)]
    assert runs[0] == runs[1]
