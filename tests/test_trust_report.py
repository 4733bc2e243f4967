"""Issue 34: a report you can trust after any fault. Its stamp covers what it wrote as well
as what it read: a report missing a file, with a file changed or added since, with a
damaged stamp, or killed while it was built is rebuilt (one line saying why) and never
read back as it is; ``calibrate`` prints its tables on stdout and recomputes a
calibration table that is not as the report wrote it. On a reported copy of the
finished tiny study (the report `run` would write)."""

from __future__ import annotations

import json
import os
import shutil
import signal
import time
from pathlib import Path

import pandas as pd
import pytest

import popnavshift
from cli_helpers import study_copy, table_hashes
from forked_cli import run_cli
from popnavshift.analysis.calibrate import COLUMNS
from popnavshift.errors import InputError
from popnavshift.io import write_csv
from popnavshift.outputs import folder_hashes, write_output_manifest
from popnavshift.read.access import report_intact
from popnavshift.report.build import build_report, report_is_current

pytestmark = pytest.mark.slow  # a study reported once (~10 s)
RUN = {"rng_seed": 0, "n_boot": 1000, "replays": 2}  # what `run` builds and checks (conftest)


def _first(folder: Path, pattern: str) -> Path:
    return next(iter(sorted((folder / "report").glob(pattern))))


DAMAGES = {
    "[]": (lambda s: (s / "report" / "stamp.json").write_text("[]"), "stamp.json is damaged"),
    "no stamp": (lambda s: (s / "report" / "stamp.json").unlink(), "stamp.json is missing"),
    "{}": (lambda s: (s / "report" / "stamp.json").write_text('{"files": {}}'),
           "stamp.json changed since it was written"),
    "page": (lambda s: (s / "report" / "index.html").write_text("<p>replaced</p>"),
             "index.html changed since it was written"),
    "table": (lambda s: _first(s, "tables/*.csv").unlink(), ".csv is missing"),
    "figures": (lambda s: shutil.rmtree(s / "report" / "figures"), "is missing"),
    "added": (lambda s: (s / "report" / "tables" / "mine.csv").write_text("a\n1\n"),
              "tables/mine.csv was added since it was written"),
}


@pytest.mark.parametrize("damage", list(DAMAGES))
def test_a_report_not_as_written_is_named_and_never_read_back(reported_tiny, tmp_path, damage):
    s = study_copy(reported_tiny, tmp_path / "s")
    hurt, said = DAMAGES[damage]
    hurt(s)
    assert said in report_is_current(s, RUN)
    with pytest.raises(InputError, match="report"):
        popnavshift.results(s)


def test_run_rebuilds_a_damaged_report_with_one_line_saying_why(reported_tiny, tmp_path):
    s = study_copy(reported_tiny, tmp_path / "s")
    tables = table_hashes(s)
    yaml = str(s.parent / "tiny.yaml")
    proc = run_cli("run", yaml, "-o", str(s), "-w", "1")
    assert proc.returncode == 0 and "report is up to date" in proc.stderr, proc.stderr
    (s / "report" / "stamp.json").write_text("[]")  # the repro
    shutil.rmtree(s / "report" / "figures")
    proc = run_cli("run", yaml, "-o", str(s), "-w", "1")
    assert proc.returncode == 0, proc.stderr
    assert "rebuilding the report: " in proc.stderr and "stamp.json is damaged" in proc.stderr
    assert report_is_current(s, RUN) == "" and report_intact(s) == ""
    assert table_hashes(s) == tables
    assert set(popnavshift.results(s)) >= {"controller_outcomes", "cell_metrics"}


def test_a_report_killed_while_it_is_built_leaves_the_old_one_whole(reported_tiny, tmp_path):
    s = study_copy(reported_tiny, tmp_path / "s")
    old = folder_hashes(s / "report")
    pid = os.fork()
    if pid == 0:  # pragma: no cover - the child: a build killed when half its files exist
        try:
            import popnavshift.report.build as build

            real = build.write_tables

            def slow(*args, **kwargs):
                out = real(*args, **kwargs)
                time.sleep(60)
                return out

            build.write_tables = slow
            build_report(s, **RUN)
        finally:
            os._exit(0)
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and not any(
            (p / "tables").is_dir() for p in s.glob(".report.*.tmp")):
        time.sleep(0.2)
    os.kill(pid, signal.SIGKILL)
    os.waitpid(pid, 0)
    assert list(s.glob(".report.*.tmp"))  # the half-built one, beside the report
    assert folder_hashes(s / "report") == old and report_is_current(s, RUN) == ""
    build_report(s, **RUN)  # the next build clears what the killed one left
    assert not list(s.glob(".report.*.tmp")) and report_is_current(s, RUN) == ""


def _calibration_table() -> pd.DataFrame:
    rows = [{"comparison": scope, "test": "prediction t", "rule": "raw", "claim": "above the null",
             "kind": "false positive", "nominal": 0.025, "placebos": 40, "claims": 1,
             "rate": 0.025, "cp_low": 0.001, "cp_high": 0.13, "within": True, "status": "within"}
            for scope in ("table", "all")]
    return pd.DataFrame(rows)[COLUMNS]


def test_calibrate_prints_on_stdout_and_recomputes_a_table_not_as_written(reported_tiny, tmp_path):
    """The report's calibration table is read when the report is intact (stdout holds the
    tables: `calibrate S > f` keeps them); changed since, it is computed again from the
    study (which here ran no null: exit 1, said); damaged beyond that, one line."""
    s = study_copy(reported_tiny, tmp_path / "s")
    csv = s / "report" / "tables" / "evidence_calibration.csv"
    write_csv(_calibration_table(), csv)
    stamp = json.loads((s / "report" / "stamp.json").read_text())
    files = {**stamp["files"], "tables/evidence_calibration.csv":
             folder_hashes(s / "report")["tables/evidence_calibration.csv"]}
    write_output_manifest(s / "report" / "stamp.json", {**stamp, "files": files})
    proc = run_cli("calibrate", str(s))
    assert proc.returncode == 0, proc.stderr
    assert "prediction t" in proc.stdout and "within" in proc.stdout
    assert "prediction t" not in proc.stderr
    csv.write_text(csv.read_text().replace("0.025", "abc"))
    proc = run_cli("calibrate", str(s))
    assert proc.returncode == 1, proc.stderr
    assert "computing the calibration again: " in proc.stderr and "changed since" in proc.stderr
    assert "ran no null replicates" in proc.stderr and "Traceback" not in proc.stderr
