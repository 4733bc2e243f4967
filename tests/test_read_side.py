"""The read side stands without the simulator: a finished study folder is read, analysed
and reported with navground unimportable, and the main part is never chosen by position."""

from __future__ import annotations

import shutil
import subprocess
import sys
import textwrap

import pytest

from popnavshift.design.study import study_from_dict
from popnavshift.errors import ConfigError

#: A child process in which ``import navground`` fails, as on a machine without it.
BLOCK_NAVGROUND = textwrap.dedent('''
    import importlib.abc, sys

    class NoNavground(importlib.abc.MetaPathFinder):
        def find_spec(self, name, path, target=None):
            if name.partition(".")[0] == "navground":
                raise ImportError(f"{name} is blocked in this test")
            return None

    sys.meta_path.insert(0, NoNavground())
''')


def _without_navground(code: str, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", BLOCK_NAVGROUND + textwrap.dedent(code), *args],
                          capture_output=True, text=True, timeout=600)


def test_a_report_builds_with_navground_unimportable(reported_study, tmp_path):
    folder = tmp_path / "study"
    shutil.copytree(reported_study, folder)
    shutil.rmtree(folder / "report")
    proc = _without_navground('''
        import sys
        from popnavshift.cli import main
        folder = sys.argv[1]
        sys.argv = ["popnavshift", "report", folder, "--n-boot", "50"]
        try:
            main()
        except SystemExit as exc:
            assert not exc.code, exc.code
        loaded = sorted(m for m in sys.modules if m.partition(".")[0] == "navground"
                        or m.startswith(("popnavshift.sim", "popnavshift.engine.run")))
        assert not loaded, loaded
        import popnavshift
        runs = popnavshift.load(folder, part="main")
        assert len(runs) and "run_inputs" in runs
        assert "evidence_headline" in popnavshift.results(folder)
    ''', str(folder))
    assert proc.returncode == 0, proc.stderr[-3000:]
    page = (folder / "report" / "index.html").read_text("utf-8")
    assert "which needs navground" in page  # the replays say why they are absent
    assert (folder / "report" / "tables" / "reversals.csv").is_file()


MAIN = {"populations": ["mixed", "matched_base"], "controllers": ["reactive"],
        "episodes": {"ids": ["sidewalk-w1.8-d0.06-s1.0-v1"]}}


def _study(parts: dict) -> dict:
    return {"name": "roles", "parts": parts}


def test_the_main_part_is_declared_or_named_never_chosen_by_position():
    named = study_from_dict(_study({"extra": MAIN, "main": MAIN}))
    assert named.main_part()[0] == "main"
    declared = study_from_dict(_study({"first": MAIN, "grid": {**MAIN, "role": "main"}}))
    assert declared.main_part()[0] == "grid"  # not the first part
    reordered = study_from_dict(_study({"grid": {**MAIN, "role": "main"}, "first": MAIN}))
    assert reordered.main_part()[0] == "grid"
    assert reordered.config_hash() == declared.config_hash()  # order is not the design
    none = study_from_dict(_study({"first": MAIN, "second": MAIN}))
    assert none.main_part() is None and none.part_with("main") is None
    with pytest.raises(ConfigError, match="no main part"):
        none.require_main()


def test_a_null_part_can_never_be_main():
    with pytest.raises(ConfigError, match="null design.*cannot be the main part"):
        study_from_dict(_study({"main": {"null_design": {"kind": "swap", "replicates": 2}}}))
    with pytest.raises(ConfigError, match="null design.*cannot be the main part"):
        study_from_dict(_study({"grid": MAIN, "nulls": {
            "role": "main", "null_design": {"kind": "sized", "replicates": 2}}}))
