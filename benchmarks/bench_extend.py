"""Time growing a finished study into a larger one: a hard-linked copy of FOLDER, then
``popnavshift run STUDY --out COPY --force --no-report`` (only the new runs are simulated),
as docs/method.md tells a user to grow `make run`'s folder into ``paper-large``.

Prints the wall time of the run, the runs executed and reused (from its manifest), the
simulated runs per second and the machine's load average before and after. Not a test:
run it by hand; the wall clock is only as quiet as the machine.

    .venv/bin/python benchmarks/bench_extend.py study paper-large [--keep]
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from popnavshift.engine.side import link_tree


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("folder", type=Path, help="a finished study folder (e.g. make run's study)")
    ap.add_argument("study", help="the larger study (built-in name or YAML file)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--keep", action="store_true", help="keep the copy (its path is printed)")
    a = ap.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="bench_extend_", dir=a.folder.resolve().parent))
    copy = tmp / "study"
    try:
        link_tree(a.folder.resolve(), copy)  # the side folder's links: the cache copied
        load0 = os.getloadavg()[0]
        started = time.perf_counter()
        proc = subprocess.run([sys.executable, "-m", "popnavshift", "run", a.study, "--out",
                               str(copy), "--force", "--no-report", "-w", str(a.workers)],
                              capture_output=True, text=True)
        wall = time.perf_counter() - started
        if proc.returncode:
            sys.exit(proc.stderr)
        man = json.loads((copy / "manifest.json").read_text())
        runs = man.get("timings", {})
        print(f"{a.folder} → {a.study}: wall {wall:.0f} s ({wall / 60:.1f} min), "
              f"load average {load0:.2f} before, {os.getloadavg()[0]:.2f} after")
        print(json.dumps({k: v for k, v in runs.items() if not isinstance(v, dict)}, indent=1))
    finally:
        if a.keep:
            print(f"kept: {copy}")
        else:
            shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
