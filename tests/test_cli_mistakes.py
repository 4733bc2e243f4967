"""Issue #12: every documented command works and every mistake gets one clear line.

Each test is a case an adversarial user found; real processes, exit codes, stderr. A
command runs forked (:mod:`forked_cli`: no interpreter start-up) unless the test process
holds something a fork would inherit (a server thread, the folder's lock) or the test is
about the process itself (the terminal width, its workers): then it is spawned.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import pytest

from cli_helpers import assert_one_line_error, cli, tiny_study
from forked_cli import run_cli
from llm_server import Reply, serve


@pytest.fixture
def study(finished, tmp_path) -> Path:
    shutil.copytree(finished, tmp_path / "s")
    return tmp_path / "s"


def rerun(folder: Path, *extra: str, command=run_cli):
    return command("run", str(tiny_study(folder.parent)), "--out", str(folder), "--no-report",
                   "-w", "1", *extra)


# ---- 1. rich markup: user and error text is shown verbatim ----------------------------
def test_episodes_lists_the_grid():
    # a wide terminal shows every column, the bracketed unit verbatim (not as markup)
    proc = subprocess.run([sys.executable, "-m", "popnavshift", "episodes", "--scene", "head_on"],
                          capture_output=True, text=True, timeout=120,
                          env={**os.environ, "COLUMNS": "120"})
    assert proc.returncode == 0, proc.stderr
    assert "[/m²]" in proc.stdout and "episodes shown" in proc.stdout  # the output: stdout


@pytest.mark.parametrize("name", ["data[v2].csv", "[/x].csv"])
def test_bracketed_names_are_shown_verbatim(tmp_path, name):
    proc = run_cli("personas", "--source", name, "--out", str(tmp_path))
    assert_one_line_error(proc, f"'{name}'")


def test_install_hints_keep_their_extras():
    code = "from popnavshift.cli import fail; fail(\"pip install 'popnavshift[gemini]' [/x]\")"
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert_one_line_error(proc, "pip install 'popnavshift[gemini]' [/x]")


# ---- 2. usage mistakes: one line, exit 2 ----------------------------------------------
@pytest.mark.parametrize(
    "args, needle",
    [
        (["run", "quick", "--workers", "abc"], "--workers"),
        (["run", "quick", "--workers", "0"], "--workers"),
        (["run", "quick", "--workers", "100000"], "--workers"),
        (["run", "quick", "--workers", str(4 * (os.cpu_count() or 1) + 1)], "per CPU"),
        (["evaluate", "reactive", "--workers", "0"], "--workers"),
        (["run", "quick", "--nope"], "--nope"),
        (["bogus"], "bogus"),
        (["personas", "--seed", "-1"], "--seed"),
        (["report", ".", "--n-boot", "-1"], "--n-boot"),
        (["probe", "--temperature", "nan"], "--temperature"),
        (["probe", "--temperature", "-0.5"], "--temperature"),
        (["probe", "--rate-limit", "0"], "--rate-limit"),
        (["probe", "--max-tokens", "0"], "--max-tokens"),
    ],
)
def test_usage_mistakes_are_one_line_and_exit_2(tmp_path, args, needle):
    proc = run_cli(*args, cwd=tmp_path)
    assert_one_line_error(proc, needle)
    assert not any(tmp_path.iterdir())  # nothing was started


# ---- 3. LLM failures are loud and fast ------------------------------------------------
def probe_args(folder: Path, url: str, *extra: str) -> list[str]:
    return ["probe", "--respondent", "openai", "--base-url", url, "--model", "test-model",
            "--api-key-env", "none", "--matched-n", "2", "--out", str(folder), *extra]


@pytest.fixture
def personas(tmp_path) -> Path:
    assert run_cli("personas", "--n", "12", "--out", str(tmp_path)).returncode == 0
    return tmp_path


def test_an_unreachable_server_fails_after_the_readiness_wait(personas):
    with serve() as gone:
        url = gone.openai_url
    started = time.monotonic()
    proc = cli(*probe_args(personas, url, "--ready-timeout", "1"))
    assert_one_line_error(proc, "not ready after waiting 1 s", "connection error")
    assert time.monotonic() - started < 60
    assert not (personas / "responses.parquet").exists()


def test_a_failing_server_trips_the_breaker(personas):
    with serve() as server:
        server.responder = lambda rec: Reply(status=500)
        proc = cli(*probe_args(personas, server.openai_url, "--max-retries", "1",
                               "--max-failures", "3", "--concurrency", "1"))
        assert_one_line_error(proc, "3 records in a row failed", "HTTP 500")
        assert server.calls == 3 * 2  # 14 records, stopped after the third


def test_no_valid_record_is_an_error_not_a_success(personas):
    with serve() as server:
        server.responder = lambda rec: Reply(text="Sure! {actions: slow")
        proc = cli(*probe_args(personas, server.openai_url, "--max-reasks", "0"))
    assert_one_line_error(proc, "no valid response in 14 records", "responses_invalid.parquet")
    assert len(pd.read_parquet(personas / "responses_invalid.parquet")) == 14
    assert not (personas / "responses.parquet").exists()


def test_verbose_shows_retries(personas):
    with serve() as server:
        server.enqueue(Reply(status=503))
        proc = cli("-v", *probe_args(personas, server.openai_url, "--concurrency", "1"))
    assert proc.returncode == 0, proc.stderr
    assert "HTTP 503; retry 1/" in proc.stderr


def test_limits_reach_the_server_and_the_served_model_is_recorded(tmp_path):
    with serve() as server:
        server.responder = lambda rec: Reply(model="test-model-2026-01-01")
        options = (f"{{base_url: '{server.openai_url}', model: test-model, api_key_env: null, "
                   "max_tokens: 321, max_reasks: 0}")
        respondent = f"respondent: {{name: openai, options: {options}}}\n"
        proc = cli("run", str(tiny_study(tmp_path, n=30, respondent=respondent)),
                   "--out", str(tmp_path / "s"), "--no-report", "-w", "1")
        assert proc.returncode == 0, proc.stderr
        assert {r.body["max_tokens"] for r in server.requests} == {321}
    responses = pd.read_parquet(tmp_path / "s" / "responses.parquet")
    assert set(responses.model) == {"test-model"}
    assert set(responses.served_model) == {"test-model-2026-01-01"}
    manifest = json.loads((tmp_path / "s" / "manifest.json").read_text())
    assert manifest["respondent"]["served_models"] == ["test-model-2026-01-01"]
    assert manifest["respondent"]["max_tokens"] == 321


def test_probe_takes_the_llm_limits_on_the_command_line(personas):
    with serve() as server:
        proc = cli(*probe_args(personas, server.openai_url, "--max-tokens", "123",
                               "--timeout", "9", "--max-retries", "0", "--max-reasks", "1"))
        assert proc.returncode == 0, proc.stderr
        assert {r.body["max_tokens"] for r in server.requests} == {123}


# ---- 4. secrets never reach the terminal, the logs or the cache -----------------------
@pytest.mark.parametrize("secret", ["sk-test-abcdef0123456789", "plain-secret-value-42"])
def test_a_key_echoed_by_the_server_is_redacted(personas, monkeypatch, secret):
    monkeypatch.setenv("POPNAV_TEST_KEY", secret)
    body = json.dumps({"error": {"message": f"Incorrect API key: Bearer {secret}; "
                                            "also Bearer other-token-123"}}).encode()
    with serve() as server:
        server.responder = lambda rec: Reply(status=401, raw=body)
        args = probe_args(personas, server.openai_url)
        args[args.index("none")] = "POPNAV_TEST_KEY"
        proc = cli(*args)
        verbose = cli("-v", *args)  # the log and the traceback too
    assert_one_line_error(proc, "HTTP 401", "Bearer ***")
    assert verbose.returncode == 2 and "HTTP 401" in verbose.stderr
    for out in (proc.stderr, proc.stdout, verbose.stderr, verbose.stdout):
        assert secret not in out and "other-token-123" not in out
    with sqlite3.connect(personas / "cache" / "llm.sqlite") as db:
        stored = " ".join(str(row) for row in db.execute("SELECT * FROM failures"))
    assert "HTTP 401" in stored and secret not in stored


# ---- 5. stages are keyed on input content ---------------------------------------------
def test_editing_the_persona_file_reruns_its_stages(tmp_path):
    from popnavshift.personas.synthetic import generate_personas

    csv = tmp_path / "people.csv"
    people = generate_personas(40, seed=0).drop(columns="source")
    people.to_csv(csv, index=False)
    yaml = tiny_study(tmp_path, source=str(csv), n=40)
    out = tmp_path / "s"
    assert run_cli("run", str(yaml), "--out", str(out), "--no-report", "-w", "1").returncode == 0
    before = pd.read_parquet(out / "responses.parquet")
    people.loc[people.index, "risk_tolerance"] = people["risk_tolerance"].iloc[::-1].to_numpy()
    people.to_csv(csv, index=False)  # same path, new content
    proc = run_cli("run", str(yaml), "--out", str(out), "--no-report", "-w", "1")
    assert proc.returncode == 0, proc.stderr
    assert "nothing to do" not in proc.stderr
    after = pd.read_parquet(out / "responses.parquet")
    assert not before.equals(after)
    personas = pd.read_parquet(out / "personas.parquet").set_index("persona_id")
    edited = people.set_index("persona_id")["risk_tolerance"]
    assert (personas.loc[edited.index, "risk_tolerance"] == edited).all()


# ---- 6. study grids are checked at plan time ------------------------------------------
@pytest.mark.parametrize(
    "change, needles",
    [
        ({"episodes": "{scenes: [sidewalk], widths: [4.0]}"},
         ["width 4.0 is not in the grid", "did you mean 4.2"]),
        ({"episodes": "{scenes: [head_on], densities: [0.2]}"},
         ["density 0.2", "did you mean 0.06"]),
        ({"episodes": "{robot_speeds: [1.1]}"}, ["robot speed 1.1", "did you mean 1.0"]),
        ({"episodes": "{scenes: []}"}, ["match no episode"]),
        ({"episodes": "{ids: []}"}, ["match no episode"]),
        ({"controller": "reactiv"}, ["unknown controller 'reactiv'", "did you mean 'reactive'"]),
        ({"backend": "orka"}, ["unknown backend 'orka'", "did you mean 'orca'"]),
        ({"mapping": "E"}, ["unknown mapping (part main) 'E'"]),
        ({"mapping": "A~shufle"}, ["'A~shufle'", "did you mean 'A~shuffle'"]),
    ],
)
def test_plan_rejects_a_study_that_cannot_run(tmp_path, change, needles):
    assert_one_line_error(run_cli("plan", str(tiny_study(tmp_path, **change))), *needles)


@pytest.mark.parametrize("change", [{"episodes": "{widths: [4.0]}"}, {"controller": "reactiv"},
                                    {"backend": "orka"}, {"mapping": "E"}])
def test_run_rejects_it_before_any_stage(tmp_path, change):
    out = tmp_path / "s"
    proc = run_cli("run", str(tiny_study(tmp_path, **change)), "--out", str(out))
    assert_one_line_error(proc, "did you mean" if "mapping" not in change else "mapping")
    assert not (out / "personas.parquet").exists()  # failed before any stage


def test_a_misspelt_respondent_option_fails_before_the_persona_stage(tmp_path):
    yaml = tiny_study(tmp_path, respondent="respondent: {name: openai, options: {modle: x}}\n")
    out = tmp_path / "s"
    assert_one_line_error(run_cli("run", str(yaml), "--out", str(out)), "'modle'", "'model'")
    assert not (out / "personas.parquet").exists()


# ---- 7. a damaged study folder is repaired or refused cleanly -------------------------
def truncate(path: Path) -> None:
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])


@pytest.mark.parametrize("table", ["runs.parquet", "pedestrians.parquet"])
def test_a_truncated_run_table_is_rebuilt_from_its_shards(study, table):
    intact = pd.read_parquet(study / table)
    truncate(study / table)
    proc = rerun(study)
    assert proc.returncode == 0, proc.stderr
    assert "0 runs executed" in proc.stderr  # rebuilt from the shards, nothing simulated
    pd.testing.assert_frame_equal(pd.read_parquet(study / table), intact)


@pytest.mark.parametrize("table", ["populations.parquet", "episodes.parquet"])
def test_a_damaged_stage_table_is_made_again(study, table):
    intact = pd.read_parquet(study / table)
    truncate(study / table)
    proc = rerun(study)
    assert proc.returncode == 0, proc.stderr
    pd.testing.assert_frame_equal(pd.read_parquet(study / table), intact)


@pytest.mark.parametrize("damage", ["truncate", "garbage"])
def test_report_refuses_a_damaged_table_in_one_line(study, damage):
    path = study / "pedestrians.parquet"
    truncate(path) if damage == "truncate" else path.write_bytes(b"not parquet at all")
    assert_one_line_error(run_cli("report", str(study)), "pedestrians.parquet", "damaged")


@pytest.mark.parametrize("table", ["runs.parquet", "pedestrians.parquet"])
def test_report_on_a_folder_without_its_run_tables_is_one_line_before_any_progress(
        study, table, tmp_path):
    """Found by the option fuzzer: a report's progress line ("report: reading the study")
    came before the error when stderr is not a terminal."""
    folder = tmp_path / "partial"
    shutil.copytree(study, folder)
    (folder / table).unlink()
    assert_one_line_error(run_cli("report", str(folder)), table, "not found")


def test_a_corrupt_stages_file_is_one_line(study):
    (study / "stages.json").write_text('{"personas": "abc", ')
    assert_one_line_error(rerun(study), "stages.json", "damaged")
    (study / "stages.json").write_text("[1, 2]")
    assert_one_line_error(rerun(study), "stages.json")


def test_a_read_only_output_folder_is_one_line(tmp_path):
    if os.geteuid() == 0:  # root writes anywhere a permission allows; sysfs refuses
        target = Path("/sys/kernel")
        if not target.is_dir():
            pytest.skip("no read-only folder available to root")
    else:
        target = tmp_path / "ro"
        target.mkdir()
        target.chmod(0o555)
    assert_one_line_error(run_cli("run", "quick", "--out", str(target)), str(target), "writable")
    assert_one_line_error(run_cli("personas", "--out", str(target / "sub")), "writable")


# ---- 8. one command per folder; workers die with their parent -------------------------
def test_a_second_run_on_a_locked_folder_names_the_holder(study):
    from popnavshift.engine.lock import study_lock

    with study_lock(study):  # spawned processes: a forked one would inherit the lock
        assert_one_line_error(rerun(study, command=cli), "in use", f"pid {os.getpid()}")
        for stage in ("personas", "probe", "profiles", "populations"):
            assert_one_line_error(cli(stage, "--out", str(study)), "in use")
    assert rerun(study).returncode == 0  # released


def _children(pid: int) -> list[int]:
    found = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
            cmdline = (stat.parent / "cmdline").read_bytes()
        except OSError:
            continue
        if int(fields[1]) == pid and b"spawn_main" in cmdline:
            found.append(int(stat.parent.name))
    return found


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="needs /proc")
def test_workers_exit_when_the_main_process_is_killed(tmp_path):
    main = subprocess.Popen(
        [sys.executable, "-m", "popnavshift", "run", "quick", "--out", str(tmp_path / "s"),
         "--no-report", "--workers", "2"],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
    )
    workers: list[int] = []
    try:
        deadline = time.monotonic() + 240
        while len(workers) < 2 and time.monotonic() < deadline and main.poll() is None:
            time.sleep(0.2)
            workers = _children(main.pid)
        assert len(workers) == 2, "the worker processes never started"
        main.send_signal(signal.SIGKILL)
        main.wait()
        deadline = time.monotonic() + 15
        while any(_alive(w) for w in workers) and time.monotonic() < deadline:
            time.sleep(0.2)
        assert not any(_alive(w) for w in workers)
    finally:
        main.kill()
        main.wait()
        for w in workers:
            if _alive(w):
                os.kill(w, signal.SIGKILL)


# ---- 9. the default output stays in the working folder --------------------------------
@pytest.mark.parametrize("name", ["../escape", "a/b", ".."])
def test_a_study_name_cannot_leave_the_working_folder(tmp_path, name):
    work = tmp_path / "work"
    work.mkdir()
    tiny_study(work)  # a tiny study, renamed
    text = (work / "tiny.yaml").read_text().replace("name: tiny", f"name: '{name}'")
    (work / "tiny.yaml").unlink()
    (work / "s.yaml").write_text(text)
    assert_one_line_error(run_cli("run", "s.yaml", cwd=work), "study name")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["work"]
    assert sorted(p.name for p in work.iterdir()) == ["s.yaml"]


def test_an_unknown_executor_fails_before_any_stage(tmp_path):
    out = tmp_path / "s"
    proc = run_cli("run", "quick", "--out", str(out), "--executor", "bogus")
    assert proc.returncode == 2 and "unknown executor 'bogus'" in proc.stderr
    assert "Traceback" not in proc.stderr and not (out / "personas.parquet").exists()
