"""The command line starts at once: ``--help``, ``--version``, a usage error and a misspelt
controller import no analysis stack (checked on ``sys.modules`` of a fresh interpreter,
not timed: benchmarks/bench_cli_startup.py measures the time)."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from popnavshift.cli.app import reflow
from popnavshift.errors import UnknownNameError, close_names

#: what a command imports when it runs, never before: the analysis stack and the simulator
HEAVY = ("scipy", "pandas", "pyarrow", "numba", "matplotlib", "navground",
         "popnavshift.analysis", "popnavshift.engine", "popnavshift.report", "popnavshift.sim",
         "popnavshift.read", "popnavshift.design", "popnavshift.pipeline")

#: runs each command line (argv lists, from stdin) through ``popnavshift.cli.main`` in one
#: fresh interpreter and prints, per command line, its exit code and the heavy modules
#: loaded so far
PROBE = """
import json, sys
heavy = tuple(sys.argv[1:])
def loaded():
    return sorted(m for m in sys.modules if any(m == h or m.startswith(h + ".") for h in heavy))
from popnavshift.cli import main
out = [["import popnavshift.cli", 0, loaded()]]
for argv in json.loads(sys.stdin.read()):
    sys.argv = ["popnavshift", *argv]
    try:
        main()
        code = 0
    except SystemExit as exc:
        code = exc.code
    out.append([" ".join(argv), code, loaded()])
print("\\n" + json.dumps(out), file=sys.__stdout__)
"""


def _probe(commands: list[list[str]], heavy: tuple[str, ...]) -> list:
    proc = subprocess.run([sys.executable, "-c", PROBE, *heavy], input=json.dumps(commands),
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    return json.loads(proc.stdout.strip().splitlines()[-1])


COMMANDS = ("personas", "probe", "profiles", "populations", "episodes", "simulate", "replay",
            "bench", "plan", "calibrate", "run", "report", "evaluate", "compare", "leaderboard",
            "audit", "show-prompt", "describe")


def test_help_version_and_usage_errors_import_no_analysis_stack():
    lines = [["--help"], ["--version"], *[[c, "--help"] for c in COMMANDS],
             ["run", "--bogus"], ["run", "--workers", "0"], ["bogus"], ["plan", "a", "b"],
             ["simulate"], ["audit", "--permutations", "many"]]
    results = _probe(lines, HEAVY)
    codes = {line: code for line, code, _ in results}
    assert codes["--help"] == codes["--version"] == codes["run --help"] == 0
    assert codes["run --bogus"] == codes["bogus"] == codes["simulate"] == 2
    assert [(line, mods) for line, _, mods in results if mods] == []


def test_a_misspelt_controller_fails_with_only_navground_core_loaded():
    lines = [["evaluate", "hrvo"], ["simulate", "-e", "x", "-c", "reactve"],
             ["compare", "reactive", "Orca"],
             ["evaluate", "reactive", "--baselines", "socialforce"]]
    results = _probe(lines, tuple(h for h in HEAVY if h not in ("navground", "popnavshift.sim")))
    assert [code for _, code, _ in results[1:]] == [2, 2, 2, 2]
    assert [(line, mods) for line, _, mods in results if mods] == []


@pytest.mark.parametrize("args, hint", [
    (("evaluate", "hrvo"), "did you mean 'HRVO'"),
    (("simulate", "-e", "x", "-c", "reactve"), "did you mean 'reactive'"),
    (("compare", "reactive", "Orca"), "did you mean 'ORCA'"),
])
def test_a_misspelt_controller_gets_a_did_you_mean_in_one_line(args, hint, tmp_path):
    proc = subprocess.run([sys.executable, "-m", "popnavshift", *args], capture_output=True,
                          text=True, timeout=120, cwd=tmp_path)
    err = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert proc.returncode == 2 and len(err) == 1 and hint in err[0], proc.stderr
    assert "unknown controller" in err[0]
    assert list(tmp_path.iterdir()) == []  # nothing was created before the name was checked


def test_close_names_ignore_case_and_list_a_case_twin_first():
    assert close_names("hrvo", ["HL", "HRVO", "ORCA", "reactive"]) == ["HRVO"]
    assert close_names("Reactve", ["reactive", "robot_orca"])[0] == "reactive"
    assert close_names("zzz", ["HRVO"]) == []
    with pytest.raises(UnknownNameError, match="did you mean 'SocialForce'"):
        raise UnknownNameError("controller", "socialforce", ["SocialForce", "HL"])


def test_reflow_joins_a_paragraph_and_keeps_a_list():
    doc = """First line
    goes on.

    A second
    paragraph.

    \b
    - one item
      continued;
    - two.
    """
    assert reflow(doc) == ("First line goes on.\n\nA second paragraph.\n\n"
                           "- one item continued;\n- two.")
