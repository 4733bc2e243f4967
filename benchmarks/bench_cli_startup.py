"""Time the command line's start: `--help`, `--version`, every subcommand's `--help`, usage
errors and a misspelt controller name, each as a whole process, as a user meets it.

Runs each command line --repeats times (in a fresh temporary folder, so no study is read)
and prints min / median / max wall time against its target (0.5 s; 1 s for a misspelt
controller, which loads navground's core to list its behaviours), with the exit code it
must give, the machine's cores and its load before and after. Every start-up figure in
README.md and docs/ comes from this script. Not a test: run it by hand on a quiet machine.

    .venv/bin/python benchmarks/bench_cli_startup.py
    .venv/bin/python benchmarks/bench_cli_startup.py --repeats 11 --src /tmp/old/src  # another tree
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

COMMANDS = ("personas", "probe", "profiles", "populations", "episodes", "simulate", "replay",
            "bench", "plan", "calibrate", "run", "report", "evaluate", "compare", "leaderboard",
            "audit", "show-prompt", "describe")
#: (label, arguments, exit code it must give, target wall time [s])
CASES: list[tuple[str, tuple[str, ...], int, float]] = [
    ("--version", ("--version",), 0, 0.5),
    ("--help", ("--help",), 0, 0.5),
    *[(f"{c} --help", (c, "--help"), 0, 0.5) for c in COMMANDS],
    ("unknown option", ("run", "--bogus"), 2, 0.5),
    ("bad option value", ("run", "--workers", "0"), 2, 0.5),
    ("unknown command", ("bogus",), 2, 0.5),
    ("misspelt controller (evaluate hrvo)", ("evaluate", "hrvo"), 2, 1.0),
    ("misspelt controller (simulate -c reactve)", ("simulate", "-e", "x", "-c", "reactve"), 2,
     1.0),
]


def time_once(command: list[str], cwd: Path, env: dict[str, str],
              code: int) -> tuple[float, float]:
    """(wall, CPU) seconds of one run of ``command``; CPU (user + system) is what the process
    itself needed, which a busy machine stretches less than the wall time."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    started = time.perf_counter()
    proc = subprocess.run(command, cwd=cwd, env=env, capture_output=True, text=True)
    wall = time.perf_counter() - started
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if proc.returncode != code:
        raise SystemExit(f"{' '.join(command)} exited {proc.returncode}, expected {code}:\n"
                         f"{proc.stderr[-2000:]}")
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=7, help="runs per command line (default 7)")
    ap.add_argument("--src", type=Path, help="time the package in this source folder "
                    "(put first on PYTHONPATH), e.g. an older checkout's src/")
    args = ap.parse_args()
    script = Path(sys.executable).with_name("popnavshift")
    base = [str(script)] if script.exists() else [sys.executable, "-m", "popnavshift"]
    env = {**os.environ, "COLUMNS": "80"}
    if args.src is not None:
        env["PYTHONPATH"] = str(args.src.resolve())
    load_before = os.getloadavg()
    rows = []
    with tempfile.TemporaryDirectory(prefix="popnavshift-startup-") as tmp:
        time_once([sys.executable, "-c", "pass"], Path(tmp), env, 0)  # warm the disk cache
        reference = [time_once([sys.executable, "-c", "pass"], Path(tmp), env, 0)[0]
                     for _ in range(args.repeats)]
        for label, argv, code, target in CASES:
            runs = [time_once([*base, *argv], Path(tmp), env, code)
                    for _ in range(args.repeats)]
            walls = [w for w, _ in runs]
            rows.append((label, min(walls), statistics.median(walls), max(walls),
                         statistics.median(c for _, c in runs), target))
    load_after = os.getloadavg()
    print(f"popnavshift start-up, {args.repeats} runs each, whole processes "
          f"({' '.join(base)}{'; PYTHONPATH=' + env['PYTHONPATH'] if args.src else ''})")
    print(f"{os.cpu_count()} cores; load average (1 min) before {load_before[0]:.2f}, after "
          f"{load_after[0]:.2f}; bare `python -c pass`: median "
          f"{statistics.median(reference):.3f} s")
    print(f"{'command line':<42} {'wall: min':>9} {'median':>6} {'max':>6} {'cpu med':>7} "
          f"{'target':>6}")
    for label, lo, mid, hi, cpu, target in rows:
        verdict = "ok" if mid <= target else "OVER"
        print(f"{label:<42} {lo:>9.3f} {mid:>6.3f} {hi:>6.3f} {cpu:>7.3f} {target:>6.1f}  "
              f"{verdict}")
    over = [r for r in rows if r[2] > r[5]]
    print(f"{len(rows) - len(over)} of {len(rows)} command lines within target (median wall "
          "time); times in s")


if __name__ == "__main__":
    main()
