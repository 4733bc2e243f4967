"""Time the card's fast paths and a new controller's evaluation on a finished study, each as
a whole process, as a user meets it (issue #31 item 5):

1. a card already made is reused (``popnavshift evaluate C`` a second time): target 2 s;
2. a misspelt controller fails with a did-you-mean (``evaluate hrv0``): target 1 s;
3. a controller never evaluated, with its null runs, is evaluated and carded (a navground
   behaviour with a parameter value no earlier run used, so every run of it is new):
   target 4 min on 2 cores for the paper study;
4. optionally (``--leaderboard``) the leaderboard with every card current.

Prints min / median / max wall time of each case against its target, the runs the new
controller executed, the machine's cores and its load before and after. Not a test: run it
by hand on a quiet machine, after ``make run`` (the default study in ./study):

    .venv/bin/python benchmarks/bench_cards.py --study-dir study
    .venv/bin/python benchmarks/bench_cards.py --study-dir study --leaderboard --repeats 3
"""

from __future__ import annotations

import argparse
import os
import re
import statistics
import subprocess
import sys
import time
from pathlib import Path

EXE = [sys.executable, "-m", "popnavshift"]


def timed(args: list[str], code: int = 0) -> tuple[float, str]:
    """Wall seconds of one ``popnavshift ARGS`` and what it wrote to stderr."""
    started = time.perf_counter()
    proc = subprocess.run([*EXE, *args], capture_output=True, text=True)
    wall = time.perf_counter() - started
    if proc.returncode != code:
        raise SystemExit(f"popnavshift {' '.join(args)} exited {proc.returncode}, expected "
                         f"{code}:\n{proc.stderr[-2000:]}")
    return wall, proc.stderr


def report(label: str, walls: list[float], target: float) -> None:
    ok = "ok" if statistics.median(walls) <= target else "OVER TARGET"
    print(f"{label:<48} min {min(walls):7.2f} s  median {statistics.median(walls):7.2f} s  "
          f"max {max(walls):7.2f} s  (target {target:g} s: {ok})", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--study-dir", type=Path, default=Path("study"))
    ap.add_argument("--study", default="paper")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--leaderboard", action="store_true")
    ap.add_argument("--skip-new", action="store_true", help="skip case 3 (minutes)")
    a = ap.parse_args()
    where = ["--study", a.study, "--study-dir", str(a.study_dir)]
    print(f"cores {os.cpu_count()}, load before {os.getloadavg()[0]:.2f}; study {a.study} in "
          f"{a.study_dir}", flush=True)

    timed(["evaluate", "HRVO", *where])  # makes the card if it is not there yet
    report("1. card reused (evaluate HRVO, card current)",
           [timed(["evaluate", "HRVO", *where])[0] for _ in range(a.repeats)], 2.0)
    report("2. misspelt controller (evaluate hrv0)",
           [timed(["evaluate", "hrv0", *where], code=2)[0] for _ in range(a.repeats)], 1.0)
    if not a.skip_new:
        horizon = 5 + (time.time_ns() % 10**6) / 10**7  # a value no earlier run used
        spec = f'HRVO{{"horizon": {horizon:.7f}}}'
        wall, log = timed(["evaluate", spec, *where])
        done = re.findall(r"reused ([\d,]+) runs, executed ([\d,]+)", log)
        runs = done[-1][1] if done else "?"
        report(f"3. new controller with its nulls ({runs} runs)", [wall], 240.0)
    if a.leaderboard:
        timed(["leaderboard", *where])  # makes any card that is missing
        report("4. leaderboard, every card current",
               [timed(["leaderboard", *where])[0] for _ in range(a.repeats)], 60.0)
    print(f"load after {os.getloadavg()[0]:.2f}", flush=True)


if __name__ == "__main__":
    main()
