"""The mistakes corpus of the adversarial pass after #12: each case is a command line a
careful user tried, run as a real process (forked, :mod:`forked_cli`, or spawned), with
its exit code and stderr: one validation before any stage, one error boundary, one
writer per folder, escaped terminal output."""

from __future__ import annotations

import errno
import json
import logging
import shutil
from pathlib import Path

import pandas as pd
import pytest

from cli_helpers import ONE_EPISODE, assert_one_line_error, cli, tiny_study
from forked_cli import run_cli
from llm_server import Reply, serve

ESC = "\x1b]0;owned\x07\x1b[31m"
EPISODE_ID = "head_on-w1.8-d0.06-s0.6-v1"


@pytest.fixture
def study(finished, tmp_path) -> Path:
    shutil.copytree(finished, tmp_path / "s")
    return tmp_path / "s"


def write_study(folder: Path, part: str = "", top: str = "", name: str = "tiny",
                populations: str = "[mixed]", controllers: str = "[robot_orca]") -> Path:
    path = folder / "s.yaml"
    path.write_text(f"name: {name}\npersonas: {{source: synthetic, n: 60}}\nmatched_n: 10\n{top}"
                    f"parts:\n  main:\n    populations: {populations}\n"
                    f"    controllers: {controllers}\n"
                    f"    episodes: {ONE_EPISODE}\n{part}")
    return path


# ---- 1. one validation: plan refuses what run would, before any stage ------------------
STUDY_MISTAKES = [
    ({"top": "seed: -1\n"}, "seed: Input should be greater than or equal to 0"),
    ({"part": "    seeds: [-1]\n"}, "parts.main.seeds.0"),
    ({"part": "    seeds: [1000000000000000000000000000000]\n"}, "less than or equal"),
    ({"part": "    seeds: [true]\n"}, "valid integer; got True"),
    ({"populations": "[]"}, "parts.main.populations: Tuple should have at least 1"),
    ({"part": "    null_design: {kind: sized}\n"}, "a sized null stands in for populations"),
    ({"top": "respondent: {name: openai, options: {model: m, temperature: .nan}}\n"},
     "respondent.options.temperature: nan is not a finite number"),
    ({"part": "    seeds: [1]\n"}, "parts.main.seeds: the report ranks controllers"),
    ({"controllers": "[]"}, "parts.main.controllers"),
    ({"populations": "[mixed, mixed]"}, "'mixed' is listed twice"),
    ({"controllers": "[reactive, reactive]"}, "'reactive' is listed twice"),
    ({"top": "seed: 1\nseed: 2\n"}, "key 'seed' appears twice (line 5)"),
    ({"name": "a" * 300}, "a study name is up to 100"),
    ({"populations": "[m\u0456xed]"}, "U+0456 at 2"),
    ({"top": "parts: {}\n", "populations": "[mixed]\nx: 1"}, "s.yaml"),
]


@pytest.mark.parametrize("change, needle", STUDY_MISTAKES)
def test_plan_refuses_what_run_would_in_one_line_naming_the_file(tmp_path, change, needle):
    path = write_study(tmp_path, **change)
    assert_one_line_error(run_cli("plan", str(path)), needle, "s.yaml")


@pytest.mark.parametrize("change, needle", [STUDY_MISTAKES[0], STUDY_MISTAKES[7]])
def test_run_refuses_it_before_any_stage(tmp_path, change, needle):
    out = tmp_path / "out"
    assert_one_line_error(cli("run", str(write_study(tmp_path, **change)), "--out", str(out)),
                          needle)
    assert not (out / "personas.parquet").exists()


def test_a_study_only_its_report_cannot_take_runs_with_no_report(tmp_path):
    path = write_study(tmp_path, part="    seeds: [1]\n")
    assert run_cli("plan", str(path), "--no-report").returncode == 0
    assert_one_line_error(run_cli("plan", str(path)), "--no-report")


def test_a_missing_executor_package_fails_before_any_stage(monkeypatch, tmp_path):
    import importlib.util

    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec",
                        lambda name, *a: None if name == "ray" else real(name, *a))
    out = tmp_path / "out"
    proc = run_cli("run", str(write_study(tmp_path)), "--out", str(out), "--executor", "ray")
    assert_one_line_error(proc, "ray")
    assert not (out / "personas.parquet").exists()


# ---- 7. only the populations a study runs must have members ----------------------------
def test_an_empty_population_the_study_does_not_run_does_not_block_it(tmp_path):
    small = "personas: {source: synthetic, n: 20}\nmatched_n: 4\n"
    path = write_study(tmp_path, populations="[homogeneous, mixed]")
    path.write_text(path.read_text().replace(
        "personas: {source: synthetic, n: 60}\nmatched_n: 10\n", small))
    out = tmp_path / "out"
    proc = run_cli("run", str(path), "--out", str(out), "--no-report", "-w", "1")
    assert proc.returncode == 0, proc.stderr
    built = set(pd.read_parquet(out / "populations.parquet")["population"])
    assert {"homogeneous", "mixed"} <= built and "high_time_pressure" not in built
    path.write_text(path.read_text().replace("[homogeneous, mixed]",
                                             "[homogeneous, high_time_pressure]"))
    assert_one_line_error(run_cli("run", str(path), "--out", str(out), "--no-report", "-w", "1"),
                          "population high_time_pressure has no members",
                          "time_pressure is Deadline or Emergency")


# ---- 2. one writer per folder; a folder of another study is refused ---------------------
def test_run_refuses_another_studys_folder_unless_forced(study, tmp_path):
    before = pd.read_parquet(study / "runs.parquet")
    other = write_study(tmp_path, name="other", populations="[homogeneous]")
    args = ("run", str(other), "--out", str(study), "--no-report", "-w", "1")
    assert_one_line_error(run_cli(*args), "holds the results of study 'tiny'", "--force")
    pd.testing.assert_frame_equal(pd.read_parquet(study / "runs.parquet"), before)
    assert run_cli(*args, "--force").returncode == 0
    assert json.loads((study / "study.json").read_text())["study"] == "other"


def test_run_refuses_a_folder_that_is_not_a_study(tmp_path):
    home = tmp_path / "home"
    home.mkdir()
    (home / "notes.txt").write_text("mine")
    assert_one_line_error(run_cli("run", "quick", "--out", str(home)), "holds no PopNavShift")
    assert sorted(p.name for p in home.iterdir() if p.name != ".lock") == ["notes.txt"]


def test_a_command_without_force_does_not_offer_it(tmp_path):
    from popnavshift.design.study import load_study
    from popnavshift.engine.ownership import claim_folder
    from popnavshift.errors import ConfigError

    (tmp_path / "notes.txt").write_text("mine")
    with pytest.raises(ConfigError) as err:
        claim_folder(tmp_path, load_study("quick"), force=None, option="--study-dir")
    assert "--study-dir" in str(err.value) and "--force" not in str(err.value)
    claim_folder(tmp_path, load_study("quick"), force=True)  # forced: marked as quick's
    assert json.loads((tmp_path / "study.json").read_text())["study"] == "quick"


def test_report_takes_the_folder_lock(study):
    from popnavshift.engine.lock import study_lock

    with study_lock(study):  # a spawned process: a forked one would inherit the lock
        assert_one_line_error(cli("report", str(study)), "in use")


def test_run_holds_the_lock_while_it_writes_the_report(study, tmp_path, monkeypatch):
    import popnavshift.report.build as build
    from popnavshift.engine import lock

    seen = tmp_path / "held"

    def fake_report(folder, **_):
        seen.write_text(str(Path(folder).resolve() in lock._HELD))
        return Path(folder) / "report" / "index.html"

    monkeypatch.setattr(build, "build_report", fake_report)
    monkeypatch.setattr(build, "report_is_current", lambda *a: "forced")
    proc = run_cli("run", str(tiny_study(study.parent)), "--out", str(study), "-w", "1")
    assert proc.returncode == 0, proc.stderr
    assert seen.read_text() == "True"


def test_leftover_temporary_files_are_removed_by_the_next_run(study):
    leftovers = [study / ".runs.parquet.abc123.tmp", study / "shards" / ".x.parquet.q.tmp"]
    for path in leftovers:
        path.parent.mkdir(exist_ok=True)
        path.write_bytes(b"half a table")
    proc = run_cli("run", str(tiny_study(study.parent)), "--out", str(study), "--no-report")
    assert proc.returncode == 0, proc.stderr
    assert not any(p.exists() for p in leftovers)


# ---- 3. the operating system's refusals are one line ------------------------------------
@pytest.mark.parametrize("code, needle", [(errno.ENOSPC, "No space left"),
                                          (errno.EACCES, "Permission denied"),
                                          (errno.EROFS, "Read-only")])
def test_os_errors_anywhere_are_one_line(tmp_path, monkeypatch, code, needle):
    import os

    import popnavshift.pipeline as pipeline

    def refuse(*_a, **_k):
        raise OSError(code, os.strerror(code), str(tmp_path / "out" / "personas.parquet"))

    monkeypatch.setattr(pipeline, "write_parquet", refuse)
    assert_one_line_error(run_cli("personas", "--n", "5", "--out", str(tmp_path / "out")),
                          needle, "personas.parquet")


@pytest.mark.parametrize("args, needles", [
    (("personas", "--missing", "bogus"), ("--missing", "'require', 'fill' or 'error'")),
    (("personas", "--only-source", "gss", "--only-source", "gss"), ("--sources", "twice")),
])
def test_stage_commands_refuse_what_a_study_file_refuses(tmp_path, args, needles):
    """The stage commands build the study file's own models (pipeline.PersonaSource): the
    same value is refused the same way, before anything is written."""
    out = tmp_path / "out"
    assert_one_line_error(run_cli(*args, "--out", str(out)), *needles)
    assert not (out / "personas.parquet").exists()


def test_a_lock_file_that_cannot_be_opened_is_one_line(study):
    (study / ".lock").unlink(missing_ok=True)
    (study / ".lock").mkdir()  # root writes anywhere: a folder in its place cannot be opened
    assert_one_line_error(run_cli("report", str(study)), ".lock", "Is a directory")


def test_replay_onto_a_folder_is_refused_before_simulating(study, tmp_path):
    assert_one_line_error(run_cli("replay", "-e", EPISODE_ID, "--out", str(tmp_path),
                                  "--dir", str(study)), "it is a folder")


def test_a_persona_folder_that_cannot_be_read_is_one_line(tmp_path, monkeypatch):
    import popnavshift.personas.load as load

    def refuse(*_a, **_k):
        raise PermissionError(errno.EACCES, "Permission denied", str(tmp_path / "release"))

    monkeypatch.setattr(load, "read_release", refuse)
    (tmp_path / "release").mkdir()
    assert_one_line_error(run_cli("personas", "--source", str(tmp_path / "release"),
                                  "--out", str(tmp_path / "out")), "Permission denied")


# ---- 4. plan --from is guarded ----------------------------------------------------------
def test_plan_from_a_folder_that_is_not_a_pilot(tmp_path):
    (tmp_path / "empty").mkdir()
    (tmp_path / "f.txt").write_text("x")
    assert_one_line_error(run_cli("plan", "quick", "--from", str(tmp_path / "nothere")),
                          "no such folder")
    assert_one_line_error(run_cli("plan", "quick", "--from", str(tmp_path / "empty")),
                          "holds no PopNavShift study")
    assert_one_line_error(run_cli("plan", "quick", "--from", str(tmp_path / "f.txt")),
                          "is a file")


POWER_HEAD = ("comparison,metric,rule,excess,verdict,limit,seed_sets_needed,nulls_needed,"
              "runs_needed,minutes_needed\n")


def test_plan_from_a_damaged_or_hostile_power_table(study):
    tables = study / "report" / "tables"
    tables.mkdir(parents=True)
    (tables / "evidence_power.csv").write_text(POWER_HEAD + "x,m,r,abc,v,l,1,2,3,4\n")
    assert_one_line_error(run_cli("plan", "quick", "--from", str(study)), "damaged")
    (tables / "evidence_power.csv").write_text('a,"b\n')
    assert_one_line_error(run_cli("plan", "quick", "--from", str(study)), "damaged")
    (tables / "evidence_power.csv").write_text(POWER_HEAD + f"[bold]{ESC},m,r,0.1,v,l,1,2,3,4\n")
    proc = run_cli("plan", "quick", "--from", str(study))
    assert proc.returncode == 0, proc.stderr
    assert "[bold]" in proc.stdout and "\x1b" not in proc.stdout and "\\x1b" in proc.stdout


# ---- 5. LLM waits are bounded and said ------------------------------------------------
def test_a_retry_after_beyond_the_cap_stops_and_a_deadline_holds(caplog, monkeypatch):
    from popnavshift.responses.llm import retries

    naps: list[float] = []
    now = [0.0]

    def nap(seconds: float) -> None:  # the clock moves only while a retry waits
        naps.append(seconds)
        now[0] += seconds

    monkeypatch.setattr(retries.time, "sleep", nap)
    monkeypatch.setattr(retries.time, "monotonic", lambda: now[0])
    policy = retries.RetryPolicy(max_retries=50)

    def limited(timeout):
        raise retries.RetryableError("HTTP 429", retry_after=3600)

    with pytest.raises(retries.TransportFailure, match="asks to wait 3600 s") as err:
        retries.send_with_retries(limited, policy, retries.RateLimiter(None))
    assert err.value.fatal and naps == []  # every record would wait an hour: stop now

    def within(timeout):
        raise retries.RetryableError("HTTP 429", retry_after=60)

    with (caplog.at_level(logging.WARNING, "popnavshift"),
          pytest.raises(retries.DeadlineReached, match="before a retry after HTTP 429")):
        retries.send_with_retries(within, policy, retries.RateLimiter(None),
                                  retries.Clock(end=200.0, seconds=200.0))
    assert naps == [60.0, 60.0, 60.0]  # a fourth wait would end past 200 s: not begun
    assert "HTTP 429" in caplog.text and "retry 1/50 in 60.00 s" in caplog.text


def test_probe_stops_at_its_deadline(tmp_path):
    assert cli("personas", "--n", "4", "--out", str(tmp_path)).returncode == 0
    with serve() as server:
        server.responder = lambda rec: Reply(status=429, headers={"Retry-After": "3"})
        proc = cli("probe", "--respondent", "openai", "--base-url", server.openai_url,
                   "--model", "m", "--api-key-env", "none", "--matched-n", "1",
                   "--out", str(tmp_path), "--max-retries", "20", "--max-retry-after", "5",
                   "--deadline", "2", "--concurrency", "1", "--max-failures", "1")
    assert proc.returncode == 2, proc.stderr
    # the first wait (3 s) would pass the deadline: it stops at once, nothing written
    assert "HTTP 429" in proc.stderr and "deadline of 2 s was reached" in proc.stderr
    assert not (tmp_path / "responses.parquet").exists()
    assert "Traceback" not in proc.stderr


def test_a_hanging_server_is_announced_within_seconds(tmp_path):
    assert cli("personas", "--n", "4", "--out", str(tmp_path)).returncode == 0
    with serve() as server:
        server.enqueue_models(Reply(delay=6))  # its model list hangs past the notice (5 s)
        proc = cli("probe", "--respondent", "openai", "--base-url", server.openai_url,
                   "--model", "m", "--api-key-env", "none", "--matched-n", "1",
                   "--out", str(tmp_path), "--timeout", "5.5")
    assert "waiting for openai server" in proc.stderr and "no answer after 5 s" in proc.stderr
    assert proc.returncode == 0, proc.stderr  # it answers in the end: the run goes on


# ---- 6. terminal escapes: data never drives the terminal -------------------------------
@pytest.mark.parametrize("bad_id", [f"p{ESC}1", "p\x00x", "   "])
def test_persona_ids_that_are_not_printable_text_are_refused(tmp_path, random_personas, bad_id):
    people = random_personas(10).drop(columns="source")
    people.loc[3, "persona_id"] = bad_id
    people.to_csv(tmp_path / "people.csv", index=False)
    proc = run_cli("personas", "--source", str(tmp_path / "people.csv"), "--n", "10",
                   "--out", str(tmp_path / "out"))
    assert "\x1b" not in proc.stderr and "\x00" not in proc.stderr
    assert_one_line_error(proc, "persona id")


def test_show_prompt_escapes_the_persona_id(study):
    proc = run_cli("show-prompt", f"syn{ESC}", "--study", str(study))
    assert "\x1b" not in proc.stderr and "\\x1b" in proc.stderr
    assert_one_line_error(proc, "no persona")


def test_printable_writes_control_and_invisible_characters_as_codes():
    from popnavshift.cli.app import printable, say

    assert printable("a\x1b[31mb\x00\u202e\n") == "a\\x1b[31mb\\x00\\u202e\\x0a"
    assert printable("line 1\nline\x07 2", lines=True) == "line 1\nline\\x07 2"
    assert printable("café – ok") == "café – ok"
    assert say("[bold]x\x1b") == "\\[bold]x\\x1b"


# ---- 9. damaged folders say how to recover ---------------------------------------------
def test_a_damaged_manifest_is_rewritten_by_the_next_run(study):
    (study / "manifest.json").write_text("{not json")
    assert_one_line_error(run_cli("report", str(study)), "manifest.json is damaged",
                          "popnavshift run")
    proc = run_cli("run", str(tiny_study(study.parent)), "--out", str(study), "--no-report")
    assert proc.returncode == 0 and "nothing to do" not in proc.stderr, proc.stderr
    assert json.loads((study / "manifest.json").read_text())["study"] == "tiny"


def test_stage_stamps_of_the_wrong_shape_are_one_line(study):
    (study / "stages.json").write_text('{"runs": 5}')
    proc = run_cli("run", str(tiny_study(study.parent)), "--out", str(study), "--no-report")
    assert_one_line_error(proc, "stages.json is damaged", "delete it")


def test_show_prompt_on_a_damaged_responses_table_is_one_line(study):
    (study / "responses.parquet").write_bytes(b"not parquet")
    assert_one_line_error(run_cli("show-prompt", "syn-000001", "--study", str(study)),
                          "responses.parquet", "not a readable Parquet file")


def test_describe_a_damaged_table_is_one_line(study):
    (study / "runs.parquet").write_bytes(b"not parquet")
    assert_one_line_error(run_cli("describe", str(study), "runs"), "runs.parquet is damaged")


# ---- 10. episodes and plan -----------------------------------------------------------------
def test_episodes_prints_its_table_on_stdout_and_filters_its_json():
    proc = run_cli("episodes", "--scene", "head_on")
    assert proc.returncode == 0 and "head_on-w1.8-d0.06-s0.6-v1" in proc.stdout
    assert "sidewalk" not in proc.stdout and not proc.stderr.strip()
    counts = json.loads(run_cli("episodes", "--scene", "head_on", "--json").stdout)
    assert counts["cells"] == 8 and counts["by_scene"] == {"head_on": 24}
    assert_one_line_error(run_cli("episodes", "--scene", "bogus"), "unknown scene 'bogus'")


def test_plan_prints_its_counts_on_stdout():
    proc = run_cli("plan", "quick")
    assert proc.returncode == 0 and "robot runs" in proc.stdout and not proc.stderr.strip()


def test_too_few_personas_hints_the_cli_flags(tmp_path, random_personas):
    random_personas(5).drop(columns="source").to_csv(tmp_path / "p.csv", index=False)
    proc = run_cli("personas", "--source", str(tmp_path / "p.csv"), "--n", "50",
                   "--out", str(tmp_path / "out"))
    assert_one_line_error(proc, "--n", "--missing fill")
    assert "n=None" not in proc.stderr
