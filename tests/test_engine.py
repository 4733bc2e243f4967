"""Study engine: plans, resume after a crash, corrupt shards, executors, study files."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import pytest
import yaml

from engine_helpers import TINY, tables, with_controllers
from popnavshift.design.plan import count_runs, plan_study
from popnavshift.design.study import load_study, study_from_dict
from popnavshift.engine.batches import batches
from popnavshift.engine.runner import run_study
from popnavshift.errors import ConfigError, UnknownNameError


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """The tiny study run once, uninterrupted, in this process."""
    folder = tmp_path_factory.mktemp("ref")
    report = run_study(study_from_dict(TINY), folder, workers=1, show_progress=False)
    assert report.executed == report.planned == 6 * 3 * 3
    return folder


def test_paper_plans_the_main_grid_exactly():
    from popnavshift.episodes.specs import all_episodes

    study = load_study("paper")
    counts = count_runs(study, all_episodes(0))
    assert counts["main"]["robot_runs"] == 7488 and counts["main"]["no_robot_runs"] == 2496
    pair = 2496  # the matched pair on the main grid: 312 episodes × 2 populations × 4
    sets = 1 + len(study.parts["matched"].seeds)  # the main grid's draw and the extra ones
    assert study.parts["swap_null"].seeds == study.parts["matched"].seeds  # same design
    perms = study.parts["swap_null"].null_design.replicates
    sized = study.parts["sized_null"].null_design.replicates
    # the verdicts rest on the spread between replicates (a prediction t on P − 1 df):
    # 9 each, the design docs/analysis.md §8 chose by measurement
    assert perms >= 9 and sized >= 9
    assert counts["matched"]["total"] == sets * pair
    assert counts["swap_null"]["total"] == perms * sets * pair
    assert counts["sized_null"]["total"] == sized * 7 * 1248  # 7 populations besides mixed
    extra = sum(counts[p]["total"] for p in ("matched", "swap_null", "sized_null", "mapping",
                                              "structure", "backend", "respondent", "noise"))
    assert counts["distinct"]["total"] < 9984 + extra  # parts share identical runs
    assert counts["distinct"]["total"] == (
        9984 + (sets - 1) * pair + perms * sets * pair + sized * 7 * 1248
        + (1536 - 384) + (1440 - 240) + (384 - 192) + 2496 + sets * 2496)


def test_benchmark_replicated_study_is_the_paper_study_without_its_nulls():
    """benchmarks/replicated_noswap.yaml (throughput against code that predates the
    nulls, issue #15) plans every part of the paper study but the two nulls, run for run."""
    from popnavshift.episodes.specs import all_episodes

    path = Path(__file__).resolve().parent.parent / "benchmarks" / "replicated_noswap.yaml"
    bench, paper = load_study(str(path)), load_study("paper")
    nulls = {"swap_null", "sized_null"}
    assert set(bench.parts) == set(paper.parts) - nulls
    assert all(bench.parts[p] == paper.parts[p] for p in bench.parts)
    mine, theirs = plan_study(bench, all_episodes(0)), plan_study(paper, all_episodes(0))
    assert {r.key for r in mine} == {r.key for r in theirs if r.part not in nulls}


def test_batches_group_runs_by_episode_and_have_stable_ids():
    from popnavshift.episodes.specs import all_episodes

    runs = plan_study(study_from_dict(TINY), all_episodes(0))
    bs = batches(runs)
    assert len(bs) == 6 and all(len(b.runs) == 9 for b in bs)
    assert [b.id for b in bs] == [b.id for b in batches(runs)]
    assert len({b.id for b in bs}) == 6


def test_rerunning_a_finished_study_does_nothing(reference):
    before = {p: p.stat().st_mtime_ns for p in reference.glob("*.parquet")}
    report = run_study(study_from_dict(TINY), reference, workers=1, show_progress=False)
    assert report.nothing_to_do and report.executed == 0 and report.reused == report.planned
    assert {p: p.stat().st_mtime_ns for p in reference.glob("*.parquet")} == before


def _run_in_subprocess(folder: Path, workers: int) -> subprocess.Popen:
    code = (
        "import sys, yaml\n"
        "from pathlib import Path\n"
        "from popnavshift.design.study import study_from_dict\n"
        "from popnavshift.engine.runner import run_study\n"
        "if __name__ == '__main__':\n"
        "    run_study(study_from_dict(yaml.safe_load(open(sys.argv[1]))), Path(sys.argv[2]),\n"
        f"              workers={workers}, show_progress=False)\n"
    )
    spec = folder.parent / f"{folder.name}.yaml"
    spec.write_text(yaml.safe_dump(TINY))
    script = folder.parent / f"{folder.name}.py"
    script.write_text(code)
    return subprocess.Popen(
        [sys.executable, str(script), str(spec), str(folder)], start_new_session=True
    )


def test_resume_after_kill_9_gives_identical_tables(tmp_path, reference):
    folder = tmp_path / "crash"
    proc = _run_in_subprocess(folder, workers=1)
    shards = folder / "shards" / "runs"
    deadline = time.time() + 120
    while time.time() < deadline and proc.poll() is None:
        if shards.exists() and len(list(shards.glob("*.parquet"))) >= 2:
            os.killpg(proc.pid, signal.SIGKILL)  # power loss: no cleanup at all
            break
        time.sleep(0.01)
    proc.wait()
    done_before = len(list(shards.glob("*.parquet")))
    assert 2 <= done_before < 6, "the crash should land mid-study"
    assert not (folder / "runs.parquet").exists()
    report = run_study(study_from_dict(TINY), folder, workers=1, show_progress=False)
    assert report.reused == 9 * done_before and report.executed == 9 * (6 - done_before)
    for ours, ref in zip(tables(folder), tables(reference), strict=True):
        pd.testing.assert_frame_equal(ours, ref)


def test_corrupt_partial_and_foreign_shards_are_redone_never_merged(tmp_path, reference):
    import shutil

    folder = tmp_path / "corrupt"
    shutil.copytree(reference, folder)
    (folder / "runs.parquet").unlink()
    runs_shards = sorted((folder / "shards" / "runs").glob("*.parquet"))
    peds_shards = sorted((folder / "shards" / "peds").glob("*.parquet"))
    data = runs_shards[0].read_bytes()
    runs_shards[0].write_bytes(data[: len(data) // 2])  # truncated
    peds_shards[1].unlink()  # half a batch
    runs_shards[2].write_bytes(runs_shards[3].read_bytes())  # another batch's content
    (folder / "shards" / "runs" / ".leftover.parquet.123.tmp").write_bytes(b"partial")
    report = run_study(study_from_dict(TINY), folder, workers=1, show_progress=False)
    assert report.executed == 27 and report.reused == 27
    for ours, ref in zip(tables(folder), tables(reference), strict=True):
        pd.testing.assert_frame_equal(ours, ref)


def test_worker_processes_give_identical_tables(tmp_path, reference):
    folder = tmp_path / "mp"
    run_study(study_from_dict(TINY), folder, workers=2, show_progress=False)
    for ours, ref in zip(tables(folder), tables(reference), strict=True):
        pd.testing.assert_frame_equal(ours, ref)


_ABANDON = """
import sys, time
from popnavshift.engine.executors import run_local

gen = run_local([0.0, 60.0, 60.0, 60.0], None, workers=2, task=time.sleep)
next(gen)  # the first batch is done; two 60 s ones are running
gen.close()  # what Ctrl-C or any exception in the consumer does to the generator
"""


def test_an_interrupted_pool_abandons_its_running_batches_at_once():
    """Ctrl-C or an error must not hold the exit for as long as the batches in flight
    run (the pool's manager thread is joined at interpreter exit): their workers end."""
    t0 = time.monotonic()
    subprocess.run([sys.executable, "-c", _ABANDON], check=True, timeout=90)
    assert time.monotonic() - t0 < 30


def test_ray_executor_gives_identical_tables(tmp_path, reference):
    pytest.importorskip("ray", reason="the ray extra is not installed")
    folder = tmp_path / "ray"
    run_study(study_from_dict(TINY), folder, workers=2, executor_name="ray", show_progress=False)
    for ours, ref in zip(tables(folder), tables(reference), strict=True):
        pd.testing.assert_frame_equal(ours, ref)
    manifest = (folder / "manifest.json").read_text()
    assert '"executor": "ray"' in manifest


def test_manifest_records_provenance(reference):
    import json

    m = json.loads((reference / "manifest.json").read_text())
    assert m["study"] == "tiny" and len(m["config_hash"]) == 16
    assert m["versions"]["navground"].startswith("0.7")
    assert m["probe_set"] and m["respondent"]["respondent"] == "rule"
    assert m["tables"]["runs"] == 54


@pytest.mark.parametrize(
    "mutate, needle",
    [
        (lambda d: d["parts"]["main"].update(populations=["mixd"]), "did you mean 'mixed'"),
        (lambda d: d.update(seeed=1), "seeed"),
        (lambda d: d["personas"].update(n=-5), "personas.n"),
        (lambda d: d["parts"]["main"].update(backends="orca"), "parts.main.backends"),
    ],
)
def test_bad_study_files_name_the_key(tmp_path, mutate, needle):
    data = yaml.safe_load(yaml.safe_dump(TINY))
    mutate(data)
    path = tmp_path / "s.yaml"
    path.write_text(yaml.safe_dump(data))
    with pytest.raises((ConfigError, UnknownNameError), match=needle):
        load_study(path)


def test_unknown_builtin_study_and_bad_yaml(tmp_path):
    with pytest.raises(UnknownNameError, match="did you mean 'paper'"):
        load_study("papr")
    bad = tmp_path / "bad.yaml"
    bad.write_text("name: x\nparts: [\n")
    with pytest.raises(ConfigError, match="not valid YAML at line"):
        load_study(bad)


def test_changed_inputs_never_reuse_old_shards(tmp_path, reference):
    import shutil

    folder = tmp_path / "changed"
    shutil.copytree(reference, folder)
    other = yaml.safe_load(yaml.safe_dump(TINY))
    other["personas"]["n"] = 250  # other personas → other populations → other runs
    report = run_study(study_from_dict(other), folder, workers=1, show_progress=False)
    assert report.reused == 0 and report.executed == 54
    assert "personas" in report.stages_run


def test_a_part_repeats_on_extra_seed_sets_and_the_report_shows_the_spread(tmp_path):
    from popnavshift.analysis.study_robustness import seed_spread
    from popnavshift.episodes.specs import get_episode
    from popnavshift.read.folder import open_study

    data = yaml.safe_load(yaml.safe_dump(TINY))
    data["parts"]["main"]["episodes"]["scenes"] = ["sidewalk", "bottleneck"]
    data["parts"]["main"]["seeds"] = [0, 5]  # the study's own seed is not repeated
    study = study_from_dict(data)
    from popnavshift.episodes.specs import all_episodes

    assert count_runs(study, all_episodes(0))["main"]["total"] == 2 * 4 * 3 * 3
    folder = tmp_path / "seeds"
    run_study(study, folder, workers=1, show_progress=False)
    runs = pd.read_parquet(folder / "runs.parquet")
    extra = runs[runs.episode.str.endswith("@s5")]
    assert len(extra) == len(runs) / 2
    first = extra.episode.iloc[0]
    assert get_episode(first).ped_starts != get_episode(first.split("@")[0]).ped_starts
    spread = seed_spread(open_study(folder), n_boot=20)
    assert sorted(spread.seed_set.unique()) == [0, 5]
    assert set(spread.metric) == {"robot_time", "mean_delay", "worst_decile"}
    with pytest.raises(ConfigError, match="seed set"):
        get_episode("sidewalk-w1.8-d0.12-s0.6-v1@sx")


def test_adding_a_controller_runs_that_controller_alone(tmp_path, reference):
    folder = tmp_path / "grow"
    first = run_study(study_from_dict(with_controllers("robot_orca")), folder, workers=1,
                      show_progress=False)
    assert first.executed == 6 * 3 * 2  # robot_orca and the no-robot baseline
    second = run_study(study_from_dict(TINY), folder, workers=1, show_progress=False)
    assert second.executed == 6 * 3 and second.reused == 6 * 3 * 2  # reactive only
    for ours, ref in zip(tables(folder), tables(reference), strict=True):
        pd.testing.assert_frame_equal(ours, ref)
    # dropping it again runs nothing and leaves the tables of the smaller study
    third = run_study(study_from_dict(with_controllers("robot_orca")), folder, workers=1,
                      show_progress=False)
    assert third.executed == 0 and not third.nothing_to_do  # its tables were rewritten
    runs, peds = tables(folder)
    assert set(runs["controller"]) == {"none", "robot_orca"} and len(runs) == 36
    assert set(peds["controller"]) == {"none", "robot_orca"}


def test_edited_controller_code_reruns_that_controllers_runs(tmp_path, reference, monkeypatch):
    import shutil

    from popnavshift.engine import stamps

    folder = tmp_path / "edited"
    shutil.copytree(reference, folder)
    stamp = stamps.run_code_stamp
    monkeypatch.setattr(stamps, "run_code_stamp",
                        lambda c: stamp(c) + ("-edited" if c == "reactive" else ""))
    report = run_study(study_from_dict(TINY), folder, workers=1, show_progress=False)
    assert report.executed == 6 * 3 and report.reused == 6 * 3 * 2
    runs, ref_runs = tables(folder)[0], tables(reference)[0]
    # the edited controller's runs have new inputs (its code), the others the same
    changed = runs["run_inputs"] != ref_runs["run_inputs"]
    assert set(runs.loc[changed, "controller"]) == {"reactive"}
    assert changed.sum() == 6 * 3
    for ours, ref in zip(tables(folder), tables(reference), strict=True):
        # same code really, so the same rows
        pd.testing.assert_frame_equal(ours.drop(columns="run_inputs", errors="ignore"),
                                      ref.drop(columns="run_inputs", errors="ignore"))


@pytest.mark.parametrize("larger", ["paper-large", "paper-xl", "paper-nulls", "paper-xl-nulls"])
def test_every_run_of_paper_is_a_run_of_each_larger_built_in_study(larger):
    """docs/method.md tells a user to grow `make run`'s folder into a larger built-in study
    (only the new runs simulated): that holds only if the larger study plans every run of
    `paper`, from the same personas, respondents and seed."""
    from popnavshift.episodes.specs import all_episodes

    paper, big = load_study("paper"), load_study(larger)
    assert big.model_dump(exclude={"name", "description", "parts"}) == paper.model_dump(
        exclude={"name", "description", "parts"})
    mine = {r.key for r in plan_study(big, all_episodes(0))}
    assert {r.key for r in plan_study(paper, all_episodes(0))} < mine
    for smaller in {"paper-xl": ["paper-large"],  # grown from their folders too
                    "paper-xl-nulls": ["paper-large", "paper-xl"]}.get(larger, []):
        assert {r.key for r in plan_study(load_study(smaller), all_episodes(0))} < mine
