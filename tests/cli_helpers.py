"""The command line as the CLI tests meet it: ``popnavshift`` in a real process, the
one-line error check, and a tiny study file (one episode); its finished folder is the
``finished`` fixture of conftest.py."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path


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


def study_copy(src: Path, dst: Path) -> Path:
    """A copy of the study folder ``src`` (and its study file ``../tiny.yaml``) at ``dst``."""
    import shutil

    shutil.copytree(src, dst)
    if (src.parent / "tiny.yaml").exists():
        shutil.copy(src.parent / "tiny.yaml", dst.parent / "tiny.yaml")
    return dst


def table_hashes(folder: Path) -> dict[str, str]:
    """sha256 of each of a study folder's own tables and JSON files (not its outputs): what
    no command reading or evaluating the study may change."""
    import hashlib

    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.glob("*")) if p.suffix in (".parquet", ".json")
            and p.name != "study.json"}
