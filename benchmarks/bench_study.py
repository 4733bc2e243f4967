"""Time a study (the paper's main grid, a fraction of it, or any study file) on N workers.

Prints, per worker count: runs/s (wall clock), how many of the runs were simulated
(a batch simulates runs with equal inputs once), the CPU time per run (workers and
parent, local executor only: Ray's workers are not our child processes), the
scaling from the first to the last worker count, peak memory, and whether every
row's study tables are identical to the first row's (a local Ray instance is
started before the timing, on 127.0.0.1). With --bare it also runs
the simulation bench (popnavshift.sim.bench). Not a test: run it by hand; on a
shared machine compare the CPU figures, the wall clock is only as quiet as the
machine.

    .venv/bin/python benchmarks/bench_study.py                   # variant 1 only (1/3 grid)
    .venv/bin/python benchmarks/bench_study.py --fraction 1      # the whole main grid
    .venv/bin/python benchmarks/bench_study.py --study my.yaml --executor ray --workers 1 2
    .venv/bin/python benchmarks/bench_study.py --executor local ray --workers 1 2   # side by side
"""

from __future__ import annotations

import argparse
import json
import resource
import shutil
import tempfile
import time
from pathlib import Path
from typing import Any

import pandas as pd

from popnavshift.engine.runner import population_settings, run_stages, run_study
from popnavshift.engine.study import load_study, study_from_dict

TABLES = ("runs", "pedestrians")


def grid_study(fraction: float):
    """The paper's main part restricted to the first round(3·fraction) variants."""
    paper = load_study("paper").model_dump(mode="json")
    variants = list(range(1, max(1, round(3 * fraction)) + 1))
    paper["parts"] = {"main": {**paper["parts"]["main"], "episodes": {"variants": variants}}}
    paper["name"] = f"bench-{len(variants)}of3"
    return study_from_dict(paper)


def _cpu(who: int) -> float:
    usage = resource.getrusage(who)
    return usage.ru_utime + usage.ru_stime


def time_study(study, workers: int, populations_from: Path, executor: str,
               address: str | None) -> tuple[dict, Path]:
    """One timed run of ``study`` in a fresh folder (population stages copied in, so
    only the runs and the compaction are timed); returns its row and the folder."""
    folder = Path(tempfile.mkdtemp(prefix=f"bench-{executor}-w{workers}-"))
    for f in populations_from.iterdir():
        if f.is_file():
            shutil.copy(f, folder / f.name)
    shutil.copytree(populations_from / "figures", folder / "figures")
    own_ray = executor == "ray" and address is None
    if own_ray:  # the instance's start is not timed
        import ray

        ray.init(num_cpus=workers, include_dashboard=False, log_to_driver=False,
                 _node_ip_address="127.0.0.1")
    cpu_self, cpu_children = _cpu(resource.RUSAGE_SELF), _cpu(resource.RUSAGE_CHILDREN)
    started = time.perf_counter()
    try:
        report = run_study(study, folder, workers=workers, executor_name=executor,
                           address=address, show_progress=False)
    finally:
        seconds = time.perf_counter() - started
        if own_ray:
            ray.shutdown()
    row: dict[str, Any] = {
        "executor": executor,
        "workers": workers,
        "runs": report.executed,
        "runs_simulated": report.simulated,  # the others repeated an identical run
        "seconds": round(seconds, 2),
        "runs_per_s": round(report.executed / seconds, 1),
        "minutes": round(seconds / 60, 2),
        "parent_cpu_s": round(_cpu(resource.RUSAGE_SELF) - cpu_self, 2),
    }
    if executor == "local" and workers > 1:
        worker_cpu = _cpu(resource.RUSAGE_CHILDREN) - cpu_children
        row["worker_cpu_s"] = round(worker_cpu, 2)
        row["worker_cpu_ms_per_run"] = round(1e3 * worker_cpu / max(1, report.executed), 3)
    elif executor == "local":  # one worker runs in this process
        row["worker_cpu_ms_per_run"] = round(1e3 * row["parent_cpu_s"] / max(1, report.executed), 3)
    return row, folder


def same_tables(a: Path, b: Path) -> bool:
    return all(pd.read_parquet(a / f"{t}.parquet").equals(pd.read_parquet(b / f"{t}.parquet"))
               for t in TABLES)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--fraction", type=float, default=1 / 3, help="share of the variants")
    parser.add_argument("--study", help="a study name or YAML file instead of the paper grid")
    parser.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--executor", choices=("local", "ray"), nargs="+", default=["local"],
                        help="one or both; every row's tables are compared with the first's")
    parser.add_argument("--address", help="Ray cluster address (default: a local instance)")
    parser.add_argument("--bare", action="store_true", help="also run the simulation bench")
    parser.add_argument("--json", type=Path, help="write the results here")
    args = parser.parse_args()

    study = load_study(args.study) if args.study else grid_study(args.fraction)
    pops = Path(tempfile.mkdtemp(prefix="bench-pops-"))
    folders: list[Path] = []
    try:
        run_stages(pops, population_settings(study), show_progress=False)
        rows = []
        for executor in args.executor:
            for w in args.workers:
                row, folder = time_study(study, w, pops, executor, args.address)
                rows.append(row)
                folders.append(folder)
        identical = [same_tables(folders[0], f) for f in folders[1:]]
    finally:
        for f in [pops, *folders]:
            shutil.rmtree(f, ignore_errors=True)
    out: dict = {"study": study.name, "rows": rows,
                 "tables_identical_to_first_row": all(identical)}
    out["scaling"] = {}
    for executor in args.executor:  # runs/s against the same executor's first worker count
        mine = [r for r in rows if r["executor"] == executor]
        for r in mine[1:]:
            out["scaling"][f"{executor} {mine[0]['workers']}_to_{r['workers']}"] = round(
                r["runs_per_s"] / mine[0]["runs_per_s"], 2)
    if not args.study:
        full_grid_runs = 9984
        best = max(rows, key=lambda r: r["runs_per_s"])
        out["projected_main_grid_minutes"] = round(full_grid_runs / best["runs_per_s"] / 60, 2)
    out["peak_rss_mb"] = {
        "parent": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, 1),
        "largest_worker": round(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024, 1),
    }
    if args.bare:
        from popnavshift.sim.bench import run_bench

        bench = run_bench()
        out["sim_bench"] = bench.summary
    print(json.dumps(out, indent=2, default=str))
    if args.json:
        args.json.write_text(json.dumps(out, indent=2, default=str))


if __name__ == "__main__":
    main()
