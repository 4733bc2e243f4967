"""``popnavshift evaluate``: the example controller's card on the quick study, in one
command; cached runs reused; controller errors recorded; the card's tables."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import popnavshift.cli.evaluate  # noqa: F401  (registers `evaluate`, as MAIN does)
from example_controller import EXAMPLE, USER_MODULE, install_example
from forked_cli import run_cli
from popnavshift.design.study import load_study
from popnavshift.errors import ConfigError
from popnavshift.evaluate import card_tables, evaluate, make_card
from popnavshift.evaluate.card import population_gaps, worst_run
from popnavshift.evaluate.robustness import robustness_tables
from popnavshift.tables import check_table

CLASS_SPEC = "slow_near_peds.controller:SlowNearPeds"
#: `evaluate` is registered by importing popnavshift.cli.evaluate; importing it here too
#: keeps this test independent of popnavshift.cli's import line.
MAIN = "import popnavshift.cli.evaluate; from popnavshift.cli import main; main()"


def cli(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(EXAMPLE), *sys.path])}
    return subprocess.run([sys.executable, "-c", MAIN, *args], capture_output=True, text=True,
                          cwd=cwd, env=env, timeout=600)


@pytest.fixture(scope="module")
def first_and_second(tmp_path_factory):
    """One command twice: the first builds the quick study's baselines and the example
    controller's runs, the second (another --n-boot: the card is made again) reuses all
    of them."""
    root = tmp_path_factory.mktemp("evaluate")
    args = ("evaluate", CLASS_SPEC, "--study", "quick", "--study-dir", "study-quick")
    first = cli(*args, "--n-boot", "199", cwd=root)
    second = cli(*args, "--n-boot", "200", cwd=root)
    return root, first, second


@pytest.fixture(scope="module")
def user_path(tmp_path_factory):
    """The example, a user module and an installed example (dist-info) on sys.path."""
    root = tmp_path_factory.mktemp("user")
    (root / "user_ctrls.py").write_text(USER_MODULE)
    install_example(root / "site")
    with pytest.MonkeyPatch.context() as mp:
        for p in (root, root / "site", EXAMPLE):
            mp.syspath_prepend(str(p))
        yield root


@pytest.mark.slow  # runs and evaluates a study (the quick one, or a small one)
def test_one_command_writes_the_card_and_the_second_reuses_every_run(first_and_second):
    root, first, second = first_and_second
    assert first.returncode == 0, first.stderr
    assert "baseline study quick" in first.stderr and "160 executed" in first.stderr
    assert "0 runs reused, 40 to run" in first.stderr
    assert second.returncode == 0, second.stderr
    assert "reused 200 runs, executed 0" in second.stderr
    out = root / "study-quick" / "evaluate"
    (folder,) = out.iterdir()
    assert (folder / "card.html").stat().st_size > 5_000
    assert (folder / "card.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.slow  # runs and evaluates a study (the quick one, or a small one)
def test_the_card_shows_every_section(first_and_second):
    root, _, _ = first_and_second
    (folder,) = (root / "study-quick" / "evaluate").iterdir()
    html = (folder / "card.html").read_text()
    for needle in ("Population robustness card", CLASS_SPEC, "Outcomes",
                   "Robustness: how often its orderings reverse", "beside its own null",
                   "Safety: each failure, the same rule", "95% CI", "Per population",
                   "Where it does worst", "Worst run", "<svg", "reproduces the stored run",
                   "matched_deadline", "robot_orca", "early_yield", "reactive"):
        assert needle in html, needle
    assert "<script" not in html
    runs = check_table(pd.read_parquet(folder / "runs.parquet"), "runs")
    assert len(runs) == 40 and set(runs["controller"]) == {CLASS_SPEC}
    meta = json.loads((folder / "evaluation.json").read_text())
    assert meta["counts"] == {"runs": 200, "controller_runs": 40, "controller_errors": 0}
    assert meta["contract_check"] == "passed"


@pytest.mark.slow  # runs and evaluates a study (the quick one, or a small one)
def test_an_entry_point_name_runs_the_same_controller(first_and_second, user_path):
    root, _, _ = first_and_second
    logs: list[str] = []
    ev = evaluate("slow_near_peds", load_study("quick"), root / "study-quick", workers=2,
                  show_progress=False, log=logs.append)
    assert "baseline study quick (" in logs[1] and "160 runs reused, 0 executed" in logs[1]
    assert ev.executed == 40 and ev.reused == 160
    (class_folder,) = [p for p in (root / "study-quick" / "evaluate").iterdir()
                       if p != ev.out]
    # the run id hashes the controller id, run_inputs its code stamp (its description)
    ids = ["controller", "run_id", "run_inputs"]
    by_class = pd.read_parquet(class_folder / "runs.parquet").drop(columns=ids)
    by_name = pd.read_parquet(ev.out / "runs.parquet").drop(columns=ids)
    pd.testing.assert_frame_equal(by_name, by_class)  # same class, same runs


@pytest.mark.slow  # runs and evaluates a study (the quick one, or a small one)
def test_a_controller_that_raises_is_recorded_and_the_card_says_so(first_and_second, user_path):
    root, _, _ = first_and_second
    ev = evaluate("user_ctrls:RaisesNearPeds", load_study("quick"), root / "study-quick",
                  root / "raises", workers=2, show_progress=False)
    assert ev.check.startswith("raised RuntimeError in the contract check")
    own = ev.runs[ev.runs["controller"] == "user_ctrls:RaisesNearPeds"]
    errors = own[own["outcome"] == "controller_error"]
    assert len(own) == 40 and 0 < len(errors) < 40  # the study went on
    assert errors["error"].str.contains("a pedestrian is too close").all()
    assert own.loc[own["outcome"] != "controller_error", "error"].isna().all()
    html_path, _ = make_card(ev, n_boot=100)
    html = html_path.read_text()
    assert "Controller errors" in html and f"in {len(errors)} of its 40 runs" in html


def test_bad_controllers_are_one_line_errors_before_anything_runs(tmp_path):
    for spec, needle in (("no_such_pkg_xyz.ctrl:Mine", "cannot import no_such_pkg_xyz.ctrl"),
                         ("collections:OrderedDict", "not a navground Behavior")):
        proc = run_cli("evaluate", spec, "--study-dir", "s", cwd=tmp_path)  # forked
        assert proc.returncode == 2, proc.stderr
        lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
        assert len(lines) == 1 and needle in lines[0], proc.stderr
    assert not (tmp_path / "s" / "stages.json").exists()


@pytest.mark.slow  # runs and evaluates a study (the quick one, or a small one)
def test_the_bootstrap_seed_is_the_only_randomness(first_and_second):
    root, _, _ = first_and_second
    ev_runs = pd.concat([pd.read_parquet(root / "study-quick" / "runs.parquet"),
                         pd.read_parquet(next((root / "study-quick" / "evaluate").iterdir())
                                         / "runs.parquet")])
    peds = pd.concat([pd.read_parquet(root / "study-quick" / "pedestrians.parquet"),
                      pd.read_parquet(next((root / "study-quick" / "evaluate").iterdir())
                                      / "pedestrians.parquet")])
    ctrl = next(c for c in ev_runs["controller"].unique() if c.startswith("slow_near_peds"))
    base = ("reactive", "early_yield", "robot_orca")

    rob = robustness_tables(ev_runs, peds, ctrl, base, {}, ["homogeneous"], n_boot=20)

    def cis(seed):
        card = card_tables(ev_runs, peds, ctrl, base, rob, rng=np.random.default_rng(seed),
                           n_boot=200)
        return card.safety_differences[["low", "high"]].to_numpy(float)

    np.testing.assert_array_equal(cis(1), cis(1))
    assert not np.array_equal(cis(1), cis(2), equal_nan=True)


# ---- the card's pure functions on tiny tables --------------------------------------------
def _cells(values: dict[tuple[str, str], tuple[float, float]]) -> pd.DataFrame:
    """(population, controller) → (metric value [s], success share)."""
    rows = [{"backend": "orca", "mapping": "A", "cell": "c1", "population": p, "controller": c,
             "robot_time": v, "mean_delay": v, "worst_decile": v, "success_share": ok}
            for (p, c), (v, ok) in values.items()]
    return pd.DataFrame(rows)


def test_population_gaps_put_failures_first_then_the_largest_gap_to_the_best_baseline():
    cells = _cells({("p1", "new"): (2.0, 1.0), ("p1", "b1"): (1.0, 1.0), ("p1", "b2"): (1.5, 1),
                    ("p2", "new"): (1.0, 1.0), ("p2", "b1"): (3.0, 1.0), ("p2", "b2"): (2.0, 1),
                    ("p3", "new"): (1.0, 0.5), ("p3", "b1"): (1.0, 1.0), ("p3", "b2"): (1.0, 1)})
    gaps = population_gaps(cells, "new", ("b1", "b2"))
    assert gaps["population"].tolist() == ["p3", "p1", "p2"]
    assert gaps["mean_delay"].tolist() == [0.0, 1.0, -1.0]
    assert gaps["success_pct"].tolist() == [50.0, 100.0, 100.0]


def test_worst_run_prefers_a_collision_then_the_largest_tail():
    key = {"population": "p", "controller": "new", "backend": "orca", "mapping": "A"}
    runs = pd.DataFrame([{**key, "episode": e, "outcome": o, "robot_time": t}
                         for e, o, t in (("e1", "success", 20.0), ("e2", "timeout", 45.0),
                                         ("e3", "pedestrian_collision", 45.0))])
    paired = pd.DataFrame([{**key, "episode": e, "delay": d}
                           for e, d in (("e1", 9.0), ("e2", 1.0), ("e3", 0.5))])
    assert worst_run(runs, paired, "new")["episode"] == "e3"
    ok = runs.assign(outcome="success")
    assert worst_run(ok, paired, "new")["episode"] == "e1"
    assert worst_run(ok, paired.iloc[:0], "new") is None


def test_an_edited_controller_module_gets_a_new_stamp(tmp_path, monkeypatch):
    from popnavshift.engine.stamps import controller_stamp, run_code_stamp, simulator_stamp
    from popnavshift.sim.controllers import CONTROLLERS

    module = tmp_path / "stamped_ctrl.py"
    module.write_text("from slow_near_peds.controller import SlowNearPeds\n\n\n"
                      "class Stamped(SlowNearPeds, name='TestStamped'):\n    pass\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.syspath_prepend(str(EXAMPLE))
    factory = CONTROLLERS.make("stamped_ctrl:Stamped")
    before = controller_stamp(factory)
    assert controller_stamp(CONTROLLERS.make("stamped_ctrl:Stamped")) == before
    assert controller_stamp(CONTROLLERS.make("slow_near_peds.controller:SlowNearPeds",
                                              slow_distance=3.0)) != before
    run_stamp = run_code_stamp("stamped_ctrl:Stamped")  # the simulator's code and its own
    assert run_stamp != run_code_stamp("robot_orca") and run_code_stamp("none") == simulator_stamp()
    module.write_text(module.read_text() + "# edited\n")
    assert controller_stamp(factory) != before
    assert run_code_stamp("stamped_ctrl:Stamped") != run_stamp


@pytest.mark.slow  # runs and evaluates a study (the quick one, or a small one)
def test_a_study_without_no_robot_runs_or_a_baseline_gets_them_run_once(tmp_path):
    from popnavshift.design.study import study_from_dict

    study = study_from_dict({
        "name": "lean", "personas": {"n": 300}, "matched_n": 40, "mappings": ["A"],
        "parts": {"main": {
            "populations": ["mixed", "matched_base"], "controllers": ["robot_orca"],
            "baseline": False,
            "episodes": {"scenes": ["head_on"], "widths": [1.8, 4.2], "densities": [0.06],
                         "robot_speeds": [1.0], "variants": [1]}}}})
    logs: list[str] = []
    ev = evaluate("HL", study, tmp_path / "lean", baselines=("robot_orca", "reactive"),
                  workers=1, show_progress=False, log=logs.append)
    assert "HL, none, reactive on main: 0 runs reused, 12 to run" in logs
    assert ev.counts == {"runs": 16, "controller_runs": 4, "controller_errors": 0}
    again = evaluate("HL", study, tmp_path / "lean", baselines=("robot_orca", "reactive"),
                     workers=1, show_progress=False)
    assert again.executed == 0 and again.reused == 16
    with pytest.raises(ConfigError, match="unknown controller 'reactiv'"):
        evaluate("HL", study, tmp_path / "lean", baselines=("reactiv",), show_progress=False)


@pytest.mark.slow  # runs and evaluates a study (the quick one, or a small one)
def test_a_study_that_adds_the_evaluated_controller_reuses_its_runs(tmp_path):
    """`evaluate` and `run` share one batch executor and one batch id: the runs an
    evaluation made are the study's batches once the study plans them."""
    from popnavshift.design.study import study_from_dict
    from popnavshift.engine.runner import run_study

    part = {"populations": ["mixed", "matched_base"], "controllers": ["robot_orca"],
            "baseline": False,
            "episodes": {"scenes": ["head_on"], "widths": [1.8, 4.2], "densities": [0.06],
                         "robot_speeds": [1.0], "variants": [1]}}
    config = {"name": "lean", "personas": {"n": 300}, "matched_n": 40, "mappings": ["A"],
              "parts": {"main": part}}
    evaluate("HL", study_from_dict(config), tmp_path / "lean", baselines=("robot_orca",),
             workers=1, show_progress=False)
    grown = {**config, "parts": {"main": {**part, "controllers": ["robot_orca", "HL"],
                                          "baseline": True}}}
    report = run_study(study_from_dict(grown), tmp_path / "lean", workers=1,
                       show_progress=False)
    assert report.planned == 12 and report.executed == 0 and report.reused == 12


@pytest.mark.slow  # runs and evaluates a study (the quick one, or a small one)
def test_a_controller_written_from_scratch_on_a_bare_behavior_moves(first_and_second):
    """The docs' from-scratch example (examples/go_to_goal) evaluated on the quick study,
    reusing the baselines the first fixture built: the robot reaches its goal."""
    root, first, _ = first_and_second
    assert first.returncode == 0, first.stderr
    scratch = Path(__file__).resolve().parents[1] / "examples" / "go_to_goal"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(scratch), *sys.path])}
    proc = subprocess.run([sys.executable, "-c", MAIN, "evaluate",
                           "go_to_goal.controller:GoToGoal", "--study", "quick", "--study-dir",
                           "study-quick", "--n-boot", "100"], capture_output=True, text=True,
                          cwd=root, env=env, timeout=600)
    assert proc.returncode == 0, proc.stderr
    card = next((root / "study-quick" / "evaluate").glob("go_to_goal*"))
    runs = pd.read_parquet(card / "runs.parquet")
    assert len(runs) == 40 and (runs["outcome"] == "success").mean() > 0.3
    assert json.loads((card / "card.json").read_text())["verdict"]["robustness"]["label"]


@pytest.mark.slow  # runs and evaluates a study (the quick one, or a small one)
def test_load_reaches_the_evaluated_controllers_runs(first_and_second):
    import popnavshift

    root, first, _ = first_and_second
    assert first.returncode == 0, first.stderr
    runs = popnavshift.load(root / "study-quick", part="main")
    assert CLASS_SPEC in set(runs["controller"]) and (runs["part"] == "main").all()
    alone = popnavshift.load(root / "study-quick", part="main", evaluated=False)
    assert CLASS_SPEC not in set(alone["controller"])
    extra = runs[~runs["run_id"].isin(alone["run_id"])]  # the evaluated controllers' runs
    assert CLASS_SPEC in set(extra["controller"])
    assert not set(extra["controller"]) & set(alone["controller"])
    assert not runs.duplicated("run_id").any()


@pytest.mark.slow  # runs and evaluates a study (the quick one, or a small one)
def test_results_and_cards_as_dataframes_from_python(first_and_second):
    import popnavshift

    root, first, _ = first_and_second
    assert first.returncode == 0, first.stderr
    cards = popnavshift.cards(root / "study-quick")
    card = next(v for k, v in cards.items() if k.startswith("slow_near_peds"))
    assert card["verdict"]["safety"]["label"] and isinstance(card["safety_rates"], pd.DataFrame)
    with pytest.raises(popnavshift.errors.InputError, match="popnavshift report"):
        popnavshift.results(root / "nowhere")
