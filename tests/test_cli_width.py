"""Terminal output that fits: at 80 columns no line of ``--help``, ``describe`` or ``plan``
is wider than the terminal (an unbreakable token aside), help paragraphs are reflowed rather
than broken where the docstring's lines ended, and piped output has real line breaks.
The width is read when a console is made, so each check runs a fresh process."""

from __future__ import annotations

import json
import os
import subprocess
import sys

from rich.cells import cell_len

from forked_cli import run_cli

COLUMNS = 80
ENV = {**os.environ, "COLUMNS": str(COLUMNS)}

#: runs each command line (argv lists, from stdin) in one interpreter and prints
#: {command line: what it wrote to stdout}
CAPTURE = """
import contextlib, io, json, sys
from popnavshift.cli import main
out = {}
for argv in json.loads(sys.stdin.read()):
    sys.argv = ["popnavshift", *argv]
    buffer = io.StringIO()
    with contextlib.redirect_stdout(buffer):
        try:
            main()
        except SystemExit:
            pass
    out[" ".join(argv)] = buffer.getvalue()
print(json.dumps(out))
"""


def _outputs(*commands: list[str]) -> dict[str, str]:
    proc = subprocess.run([sys.executable, "-c", CAPTURE], input=json.dumps(commands),
                          capture_output=True, text=True, timeout=120, env=ENV)
    assert proc.returncode == 0, proc.stderr
    return json.loads(proc.stdout)


def _too_wide(text: str) -> list[str]:
    """Lines wider than the terminal, but for a line that is one token (an id, a path)."""
    return [ln for ln in text.splitlines()
            if cell_len(ln) > COLUMNS and len(ln.split()) > 1]


def _broken_sentences(help_text: str) -> list[str]:
    """Lines of a help's prose (above its first panel) that end well short of the width
    though their paragraph goes on: a docstring's line break shown mid-sentence."""
    prose = help_text.split("╭")[0].splitlines()
    return [ln for ln, nxt in zip(prose, prose[1:], strict=False)
            if ln.strip() and nxt.strip() and not nxt.strip().startswith("- ")
            and cell_len(ln.rstrip()) < 60]


COMMANDS = ("personas", "probe", "profiles", "populations", "episodes", "simulate", "replay",
            "bench", "plan", "calibrate", "run", "report", "evaluate", "compare", "audit",
            "show-prompt", "describe")


def test_every_help_fits_80_columns_in_reflowed_paragraphs():
    helps = _outputs(["--help"], *[[c, "--help"] for c in COMMANDS])
    assert len(helps) == len(COMMANDS) + 1 and all("Usage" in h for h in helps.values())
    assert {c: _too_wide(h) for c, h in helps.items() if _too_wide(h)} == {}
    assert {c: _broken_sentences(h) for c, h in helps.items() if _broken_sentences(h)} == {}
    audit = helps["audit --help"]
    assert "\n - spread: per probe and item" in audit and "\b" not in audit  # the list kept


def test_describe_wraps_its_column_notes_at_80_columns():
    text = _outputs(["describe"])["describe"]
    assert "persona_id · string · key" in text
    assert _too_wide(text) == []
    notes = [ln for ln in text.splitlines() if ln.startswith("    ")]
    assert notes and all(ln == ln.rstrip() for ln in notes)  # no padding to the width


POWER = ("comparison,metric,rule,excess,verdict,limit,seed_sets_needed,nulls_needed,"
         "runs_needed,minutes_needed\n")
ROWS = [("matched", "mean_delay", "sig", 0.154, "above the null", "decided", "", "", "", ""),
        ("matched", "cvar90_delay", "raw", 0.035, "undecided", "seed sets", 6, 19, 123456,
         312.4),
        ("all_pairs", "mean_delay", "raw", -0.024, "undecided", "nothing reachable (a null "
         "replicate is at or above the observed)", "", "", "", "")] * 8


def test_plan_advice_fits_80_columns_in_a_block_per_row(tmp_path):
    pilot = tmp_path / "pilot"
    (pilot / "report" / "tables").mkdir(parents=True)
    (pilot / "study.json").write_text('{"study": "pilot"}')
    (pilot / "report" / "tables" / "evidence_power.csv").write_text(
        POWER + "".join(",".join(map(str, r)) + "\n" for r in ROWS))
    proc = subprocess.run([sys.executable, "-m", "popnavshift", "plan", "quick", "--from",
                           str(pilot)], capture_output=True, text=True, timeout=300, env=ENV)
    assert proc.returncode == 0, proc.stderr
    assert _too_wide(proc.stdout) == []
    advice = proc.stdout.split("power (from")[1]
    assert len(advice.splitlines()) <= 2 * len(ROWS) + 8  # a line per row, one for advice
    assert "matched · mean_delay · sig: +15.4 pp, above the null (decided)" in advice
    assert ("    seed sets: 6 seed sets, 19 null replicates (about +123,456 runs, ~312"
            in advice)


def test_piped_bench_output_has_real_line_breaks(monkeypatch):
    import popnavshift.sim.bench as bench

    monkeypatch.setattr(bench, "run_bench", lambda **kw: None)
    monkeypatch.setattr(bench, "format_bench", lambda result: "condition  ratio\nnone  1.30")
    proc = run_cli("bench")
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.splitlines() == ["condition  ratio", "none  1.30"]
    assert "\\x0a" not in proc.stdout


def test_prose_is_cut_between_words_and_keeps_a_long_token_whole():
    script = "from popnavshift.cli.app import indented\nindented('word ' * 30 + 'x' * 100)\n"
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                          timeout=60, env=ENV)
    lines = proc.stdout.splitlines()
    assert len(lines) > 2 and all(ln.startswith("    word") for ln in lines[:-1])
    assert lines[-1] == "    " + "x" * 100  # one token: never cut
    assert all(cell_len(ln) <= COLUMNS for ln in lines[:-1])
