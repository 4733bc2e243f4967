"""Time `make run` on a fresh clone: the README's first command, as a new user runs it.

Clones this repository's HEAD (or --rev) into a temporary folder, runs `make run` there
(creates .venv, installs, runs the default `paper` study and its report) and prints the
wall time, its phases (install, study stages, simulation, report — from the output and
the study's manifest), the run counts, peak memory of the largest process and the
machine's load before and after. Every `make run` time in README.md and docs/ comes
from this script. Not a test: run it by hand on a quiet machine.

    .venv/bin/python benchmarks/bench_make_run.py               # HEAD
    .venv/bin/python benchmarks/bench_make_run.py --keep        # keep the clone to inspect
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import subprocess
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rev", default="HEAD", help="the revision to clone (default HEAD)")
    ap.add_argument("--keep", action="store_true", help="keep the clone and its study")
    args = ap.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="popnavshift-fresh-"))
    clone = tmp / "repo"
    subprocess.run(["git", "clone", "--quiet", "--no-hardlinks", str(ROOT), str(clone)],
                   check=True)
    subprocess.run(["git", "-C", str(clone), "checkout", "--quiet", args.rev], check=True)
    rev = subprocess.run(["git", "-C", str(clone), "rev-parse", "--short", "HEAD"],
                         capture_output=True, text=True, check=True).stdout.strip()
    load_before = os.getloadavg()
    started = time.perf_counter()
    marks: dict[str, float] = {}
    with subprocess.Popen(["make", "run"], cwd=clone, stdout=subprocess.PIPE,
                          stderr=subprocess.STDOUT, text=True, bufsize=1,
                          env={**os.environ, "COLUMNS": "120"}) as proc:
        assert proc.stdout is not None
        for line in proc.stdout:
            now = time.perf_counter() - started
            if "popnavshift run" in line and "install" not in marks:
                marks["install"] = now
            if line.startswith("report →"):
                marks["report"] = now
    wall = time.perf_counter() - started
    load_after = os.getloadavg()
    peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
    if proc.returncode != 0:
        raise SystemExit(f"make run failed (exit {proc.returncode}) in {clone}")
    manifest = json.loads((clone / "study" / "manifest.json").read_text())
    t = manifest["timings"]
    install = marks.get("install", float("nan"))
    report = wall - install - t["total_s"]
    print(f"make run on a fresh clone of {rev}: {wall:.0f} s ({wall / 60:.1f} min), "
          f"{os.cpu_count()} cores")
    print(f"  install {install:.0f} s · study {t['total_s']:.0f} s (simulation "
          f"{t['simulation_s']:.0f} s) · report and the rest {report:.0f} s")
    print(f"  runs {t['runs_executed']:,} executed, {t['runs_simulated']:,} simulated "
          f"({t['runs_simulated'] / t['simulation_s']:.0f} simulated runs/s)")
    print(f"  peak memory (largest process) {peak:.0f} MB")
    print(f"  load average before {load_before[0]:.2f} / after {load_after[0]:.2f} "
          f"(1 min; {os.cpu_count()} cores)")
    if args.keep:
        print(f"  kept in {clone}")
    else:
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
