"""The CLI as a user meets it: real processes, exit codes, one-line errors. A command is
spawned where the process itself is under test (the end-to-end study, ``--help``, a user's
PYTHONPATH, the terminal width, a server thread in the test process) and forked
(:mod:`forked_cli`: no interpreter start-up) elsewhere."""

from __future__ import annotations

import subprocess
import sys

import pandas as pd
import pytest

from cli_helpers import assert_one_line_error, cli
from forked_cli import run_cli
from popnavshift.dictionary import STUDY_TABLES
from popnavshift.tables import SPECS, check_table


@pytest.mark.slow
def test_quick_study_end_to_end(tmp_path):
    out = tmp_path / "s"
    proc = cli("run", "quick", "--out", str(out), "--no-report")
    assert proc.returncode == 0, proc.stderr
    for name in ("personas", "responses", "profiles", "populations"):
        assert (out / f"{name}.parquet").exists()
    pops = pd.read_parquet(out / "populations.parquet")
    sizes = pops[pops.mapping == "A"].groupby("population").size()
    assert sizes["mixed"] == 600 and sizes["matched_base"] == sizes["matched_deadline"] == 202
    assert (out / "figures" / "fig3a_profiles.png").stat().st_size > 10_000
    assert "matched_deadline" in proc.stderr  # sizes are printed
    runs = pd.read_parquet(out / "runs.parquet")
    assert len(runs) == 160 and (out / "manifest.json").exists()
    for stage in STUDY_TABLES:  # every table the folder holds is the declared one
        table = check_table(pd.read_parquet(out / f"{stage}.parquet"), stage)
        assert set(table.columns) == set(SPECS[stage].names), stage
    described = cli("describe", str(out))
    assert described.returncode == 0 and "not declared" not in described.stdout
    assert "pedestrians.parquet · " in described.stdout
    again = cli("run", "quick", "--out", str(out), "--no-report")
    assert again.returncode == 0 and "nothing to do" in again.stderr
    # the report: built once with a line per step in a log, then left alone while current
    first = cli("run", "quick", "--out", str(out))
    assert first.returncode == 0 and "rebuilding the report: there is no report yet" in \
        first.stderr and "report: the page" in first.stderr
    page = out / "report" / "index.html"
    written = page.stat().st_mtime_ns
    second = cli("run", "quick", "--out", str(out))
    assert "report is up to date" in second.stderr and page.stat().st_mtime_ns == written
    (out / "manifest.json").touch()  # an input changed: the report is built again
    third = cli("run", "quick", "--out", str(out))
    assert "rebuilding the report: the study's tables" in third.stderr
    assert page.stat().st_mtime_ns > written


def test_stages_one_by_one_and_personas_to_a_file(tmp_path):
    target = tmp_path / "d" / "personas.parquet"
    assert run_cli("personas", "--n", "300", "--seed", "1", "--out", str(target)).returncode == 0
    assert len(pd.read_parquet(target)) == 300 and target.with_suffix(".json").exists()
    folder = str(target.parent)
    assert run_cli("probe", "--out", folder, "--matched-n", "50").returncode == 0
    assert run_cli("profiles", "--out", folder, "--mapping", "A").returncode == 0
    proc = run_cli("populations", "--out", folder, "--matched-n", "50")
    assert proc.returncode == 0, proc.stderr
    assert set(pd.read_parquet(target.parent / "profiles.parquet").mapping) == {"A"}


@pytest.mark.parametrize(
    "args, needles",
    [
        (["personas", "--source", "/nonexistent/file.csv"], ["/nonexistent/file.csv"]),
        (["probe", "--respondent", "rulez"], ["unknown respondent 'rulez'", "did you mean"]),
        (["personas", "--missing", "maybe"], ["maybe"]),
        (["populations"], ["not found"]),
    ],
)
def test_user_errors_are_one_red_line_and_exit_2(tmp_path, args, needles):
    if args[0] == "probe":
        assert run_cli("personas", "--out", str(tmp_path)).returncode == 0
    proc = run_cli(*args, "--out", str(tmp_path / "x" if args[0] == "populations" else tmp_path))
    assert_one_line_error(proc, *needles)


def test_bad_persona_value_names_file_row_and_field(tmp_path):
    from popnavshift.personas.synthetic import generate_personas

    df = generate_personas(20, seed=0).drop(columns="source")
    df.loc[3, "trust_level"] = "Paranoid"
    path = tmp_path / "p.csv"
    df.to_csv(path, index=False)
    proc = run_cli("personas", "--source", str(path), "--n", "10", "--out", str(tmp_path))
    assert_one_line_error(proc, "p.csv", "trust_level", "Paranoid")


def test_help_teaches_every_command():
    proc = cli("--help")
    assert proc.returncode == 0
    for command in ("personas", "probe", "profiles", "populations", "run"):
        assert command in proc.stdout
        assert run_cli(command, "--help").returncode == 0


def test_probe_with_an_openai_compatible_server_caches_every_record(tmp_path):
    from llm_server import serve, valid_text

    assert run_cli("personas", "--n", "30", "--out", str(tmp_path)).returncode == 0
    with serve() as server:
        from llm_server import Reply

        server.responder = lambda rec: Reply(text=valid_text())
        args = (
            "probe",
            "--respondent",
            "openai",
            "--base-url",
            server.openai_url,
            "--model",
            "test-model",
            "--api-key-env",
            "none",
            "--matched-n",
            "5",
            "--out",
            str(tmp_path),
        )
        first = cli(*args)
        assert first.returncode == 0, first.stderr
        calls = server.calls
        assert calls == 35
        second = cli(*args)
        assert second.returncode == 0, second.stderr
        assert server.calls == calls  # every record served from the SQLite cache
        assert "35 cache hits" in second.stderr
    responses = pd.read_parquet(tmp_path / "responses.parquet")
    assert len(responses) == 35 and set(responses.respondent) == {"openai"}


def test_probe_with_a_missing_key_is_one_line(tmp_path, monkeypatch):
    monkeypatch.delenv("POPNAV_TEST_KEY", raising=False)
    assert run_cli("personas", "--n", "10", "--out", str(tmp_path)).returncode == 0
    proc = run_cli(
        "probe",
        "--respondent",
        "openai",
        "--base-url",
        "http://127.0.0.1:9/v1",
        "--api-key-env",
        "POPNAV_TEST_KEY",
        "--matched-n",
        "2",
        "--out",
        str(tmp_path),
    )
    assert_one_line_error(proc, "POPNAV_TEST_KEY")


def test_probe_accepts_a_respondent_class_spec(tmp_path):
    import os

    (tmp_path / "my_resp.py").write_text(
        "from popnavshift.responses.rule import RuleRespondent\n\n"
        "class Grumpy(RuleRespondent):\n    name = 'grumpy'\n"
    )
    env = {**os.environ, "PYTHONPATH": str(tmp_path)}
    out = tmp_path / "s"
    run = lambda *a: subprocess.run(  # noqa: E731
        [sys.executable, "-m", "popnavshift", *a],
        capture_output=True,
        text=True,
        env=env,
        timeout=120,
    )
    assert run("personas", "--n", "40", "--out", str(out)).returncode == 0
    proc = run("probe", "--respondent", "my_resp:Grumpy", "--matched-n", "4", "--out", str(out))
    assert proc.returncode == 0, proc.stderr
    assert set(pd.read_parquet(out / "responses.parquet").respondent) == {"grumpy"}
    bad = run("probe", "--respondent", "my_resp:Nope", "--out", str(out))
    assert_one_line_error(bad, "Nope")


def test_episodes_show_whole_ids_at_80_columns_and_check_the_scene():
    import json
    import os
    import subprocess
    import sys

    env = {**os.environ, "COLUMNS": "80"}

    def episodes(*args):
        return subprocess.run([sys.executable, "-m", "popnavshift", "episodes", *args],
                              capture_output=True, text=True, timeout=120, env=env)

    shown = episodes("--scene", "obstruction")
    assert shown.returncode == 0
    assert "obstruction-w1.8-d0.06-s0.6-v1" in shown.stdout + shown.stderr  # never cut
    bad = episodes("--scene", "obstructon")
    assert bad.returncode == 2 and "did you mean 'obstruction'" in bad.stderr
    counts = json.loads(episodes("--scene", "head_on", "--json").stdout)
    assert counts["by_scene"] == {"head_on": counts["episodes"]} and counts["episodes"] == 24
