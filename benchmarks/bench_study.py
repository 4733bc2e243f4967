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
    .venv/bin/python benchmarks/bench_study.py --study benchmarks/replicated_noswap.yaml \
        --against 5f83f25 --repeats 2 --workers 2   # this tree vs the code of issue #15

With --against REV (a git revision of this repository) it times instead ``popnavshift
run STUDY --workers N --no-report`` of this tree and of REV's ``src/`` side by side
(alternating which goes first, in fresh folders, each from personas on, after an
untimed run of ``quick`` that compiles each version's numba kernels), and prints
runs per second of the simulation phase (``manifest.json``) for both, their ratio,
and how many run rows agree on the columns both versions write.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import pandas as pd

from popnavshift.design.study import load_study, study_from_dict
from popnavshift.engine.runner import population_settings, run_stages, run_study
from popnavshift.tables import RUN_KEY

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


def checkout(rev: str) -> Path:
    """REV's ``src/`` extracted into a fresh folder (``git archive``); returns the folder."""
    out = Path(tempfile.mkdtemp(prefix="bench-rev-"))
    repo = Path(__file__).resolve().parent.parent
    archive = subprocess.run(["git", "-C", str(repo), "archive", rev, "src"],
                             capture_output=True, check=True).stdout
    subprocess.run(["tar", "-x", "-C", str(out)], input=archive, check=True)
    return out / "src"


def time_cli_run(study: str, workers: int, src: Path | None) -> tuple[dict, Path]:
    """``popnavshift run study --workers N --no-report`` in a fresh folder, with the
    package imported from ``src`` (None: this environment's install)."""
    folder = Path(tempfile.mkdtemp(prefix="bench-cli-")) / "study"
    env = dict(os.environ)
    if src is not None:
        env["PYTHONPATH"] = str(src)
    started = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "popnavshift", "run", study, "--out",
                           str(folder), "--workers", str(workers), "--no-report"],
                          env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    if done.returncode:
        shutil.rmtree(folder.parent, ignore_errors=True)
        version = "this tree" if src is None else str(src)
        raise SystemExit(f"popnavshift run {study} failed with {version}:\n"
                         + "\n".join(done.stderr.splitlines()[-5:]))
    wall = time.perf_counter() - started
    timings = json.loads((folder / "manifest.json").read_text())["timings"]
    runs = int(timings["runs_executed"])
    return {"runs": runs, "runs_simulated": timings.get("runs_simulated", runs),
            "simulation_s": timings["simulation_s"], "total_s": timings["total_s"],
            "wall_s": round(wall, 2),
            "runs_per_s": round(runs / timings["simulation_s"], 1)}, folder


def agreeing_runs(a: Path, b: Path) -> dict:
    """Run rows of two study folders joined on the run key: how many agree on every
    column both tables have (NaN equals NaN), and the differing rows per part and mapping."""
    ra, rb = pd.read_parquet(a / "runs.parquet"), pd.read_parquet(b / "runs.parquet")
    common = [c for c in ra.columns if c in rb.columns and c not in RUN_KEY and c != "part"]
    both = ra.merge(rb, on=list(RUN_KEY), suffixes=("_a", "_b"))
    same = pd.Series(True, index=both.index)
    for c in common:
        x, y = both[f"{c}_a"], both[f"{c}_b"]
        same &= (x == y) | (x.isna() & y.isna())
    differing = both[~same]
    return {"rows": [len(ra), len(rb)], "joined": len(both), "agree": int(same.sum()),
            "compared_columns": common,
            "differing_by_part_mapping": {f"{p} {m}": int(k) for (p, m), k in differing.groupby(
                ["part_a", "mapping"]).size().items()}}


def compare_revisions(study: str, rev: str, workers: int, repeats: int) -> dict:
    """This tree against ``rev`` on ``study``, ``repeats`` alternating pairs."""
    src = checkout(rev)
    if Path(study).is_file():
        study = str(Path(study).resolve())
    rows: dict[str, list[dict]] = {"this tree": [], rev: []}
    folders: dict[str, Path] = {}  # each version's last folder
    try:
        for path in (None, src):  # untimed: compile (and cache) each version's kernels
            shutil.rmtree(time_cli_run("quick", workers, path)[1].parent)
        for r in range(repeats):
            order = [("this tree", None), (rev, src)]
            for label, path in order if r % 2 == 0 else order[::-1]:
                if label in folders:
                    shutil.rmtree(folders[label].parent, ignore_errors=True)
                row, folders[label] = time_cli_run(study, workers, path)
                rows[label].append(row)
        agreement = agreeing_runs(folders["this tree"], folders[rev])
    finally:
        for f in [src, *folders.values()]:
            shutil.rmtree(f.parent, ignore_errors=True)
    rate = {k: statistics.median(r["runs_per_s"] for r in v) for k, v in rows.items()}
    return {"study": study, "workers": workers, "against": rev, "rows": rows,
            "median_runs_per_s": rate,
            "throughput_ratio": round(rate["this tree"] / rate[rev], 3),
            "run_rows_vs_against": agreement}


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
    parser.add_argument("--against", metavar="REV",
                        help="time this tree against git revision REV on --study instead")
    parser.add_argument("--repeats", type=int, default=2,
                        help="with --against: alternating pairs (default 2)")
    args = parser.parse_args()
    if args.against:
        if not args.study:
            parser.error("--against needs --study (a study name or YAML file)")
        emit(compare_revisions(args.study, args.against, args.workers[-1], args.repeats),
             args.json)
        return

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
    emit(out, args.json)


def emit(out: dict, path: Path | None) -> None:
    """Print ``out`` as JSON, and write it to ``path`` too if given."""
    text = json.dumps(out, indent=2, default=str)
    print(text)
    if path:
        path.write_text(text)


if __name__ == "__main__":
    main()
