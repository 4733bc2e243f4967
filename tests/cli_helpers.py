"""The command line as the CLI tests meet it: ``popnavshift`` in a real process, the
one-line error check, and a tiny study file (one episode) with its finished folder."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest


def cli(*args, cwd=None):
    return subprocess.run(
        [sys.executable, "-m", "popnavshift", *args],
        capture_output=True,
        text=True,
        cwd=cwd,
        timeout=300,
    )


def assert_one_line_error(proc, *needles):
    assert proc.returncode == 2, proc.stderr
    assert "Traceback" not in proc.stderr
    err = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert len(err) == 1 and err[0].startswith("error:"), proc.stderr
    for needle in needles:
        assert needle in err[0], err[0]


TINY = """\
name: tiny
personas: {{source: {source}, n: {n}}}
matched_n: 10
{respondent}parts:
  main:
    populations: [mixed]
    controllers: [{controller}]
    backends: [{backend}]
    mapping: {mapping}
    episodes: {episodes}
"""
ONE_EPISODE = "{ids: [head_on-w1.8-d0.06-s0.6-v1]}"


def tiny_study(folder: Path, *, source="synthetic", n=60, respondent="", controller="robot_orca",
               backend="orca", mapping="A", episodes=ONE_EPISODE) -> Path:
    path = folder / "tiny.yaml"
    path.write_text(TINY.format(source=source, n=n, respondent=respondent, controller=controller,
                                backend=backend, mapping=mapping, episodes=episodes))
    return path


@pytest.fixture(scope="module")
def finished(tmp_path_factory) -> Path:
    """A finished tiny study (2 runs); tests copy it before damaging it."""
    root = tmp_path_factory.mktemp("finished")
    proc = cli("run", str(tiny_study(root)), "--out", str(root / "s"), "--no-report", "-w", "1")
    assert proc.returncode == 0, proc.stderr
    return root / "s"
