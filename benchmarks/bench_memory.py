"""Peak memory (RSS) and time of a study's compaction and report, on a finished study folder.

Each step runs in a child process, whose peak RSS is read from ``wait4`` (what
``/usr/bin/time -v`` prints as "Maximum resident set size"):

* ``compaction``: the shards of ``--from`` (``shards/runs``, ``shards/peds``) compacted
  into runs.parquet and pedestrians.parquet of a scratch folder
  (:func:`popnavshift.engine.compact.write_compacted`, as ``popnavshift run`` does at its end),
  and the tables compared with those of ``--from``;
* ``report``: ``popnavshift report`` on a copy of the folder (its tables, not its shards).

With ``--runs N`` above the folder's run count, the report is measured on a synthetic
study of at least N runs built from it: the parts that repeat on extra episode seed sets
(matched, noise, swap_null in the paper study) get more seed sets, each a copy of an
existing one's runs and pedestrians under the new seed set's episode ids
(``<episode>@s<k>``, ``seed_set`` k, ``run_id`` recomputed) and the manifest's study
configuration lists them, so every analysis selects them as it would real ones. The
values repeat, so the statistics are not meaningful: only the sizes are.

    .venv/bin/python benchmarks/bench_memory.py --from study                  # compaction + report
    .venv/bin/python benchmarks/bench_memory.py --from study --runs 500000 --skip compaction
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

import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq

from popnavshift.design.plan import Run
from popnavshift.episodes.specs import seed_set_id
from popnavshift.tables import RUN_KEY

COMPACT = """
import json, sys
from pathlib import Path
import pyarrow.parquet as pq
from popnavshift.engine.compact import episode_chunks, write_compacted
src, out = Path(sys.argv[1]), Path(sys.argv[2])
shards = []
for path in sorted((src / "shards" / "runs").glob("*.parquet")):
    f = pq.ParquetFile(path)
    episode = f.read_row_group(0, columns=["episode"]).column(0)[0].as_py()
    shards.append((episode, path, src / "shards" / "peds" / path.name, f.metadata.num_rows))
print(json.dumps(write_compacted(out, episode_chunks(shards))))
"""


def measured(cmd: list[str]) -> tuple[float, float, str]:
    """Run ``cmd``; its peak RSS [MB], wall time [s] and standard output."""
    started = time.perf_counter()
    child = subprocess.Popen(cmd, stdout=subprocess.PIPE, text=True)
    out = child.stdout.read() if child.stdout else ""
    _, status, usage = os.wait4(child.pid, 0)
    child.returncode = os.waitstatus_to_exitcode(status)
    if child.returncode:
        raise SystemExit(f"{' '.join(cmd)} failed (exit {child.returncode})")
    return usage.ru_maxrss / 1024, time.perf_counter() - started, out


def extra_seeds(manifest: dict, runs: pa.Table, target: int) -> dict[int, int]:
    """New seed set → the existing seed set it copies, enough to reach ``target`` runs."""
    parts = manifest["study_config"]["parts"]
    have = sorted({s for p in parts.values() for s in p.get("seeds", [])})
    if not have:
        raise SystemExit("the study has no part on extra seed sets to replicate")
    per_set = pc.sum(pc.equal(runs["seed_set"], have[0])).as_py()
    missing = max(0, target - runs.num_rows)
    n_new = -(-missing // per_set)
    return {max(have) + 1 + i: have[i % len(have)] for i in range(n_new)}


def _renamed(table: pa.Table, source: int, seed: int, ids: dict[tuple, str]) -> pa.Table:
    """``table``'s rows of seed set ``source`` as seed set ``seed``'s (``ids``: a cache of
    run ids by key)."""
    rows = table.filter(pc.equal(table["seed_set"], source))
    base = pc.replace_substring_regex(rows["episode"], r"@s\d+$", "")
    episode = pa.array([seed_set_id(e, seed) for e in base.to_pylist()], rows["episode"].type)
    rows = rows.set_column(rows.schema.get_field_index("episode"), "episode", episode)
    rows = rows.set_column(rows.schema.get_field_index("seed_set"), "seed_set",
                           pa.array([seed] * len(rows), pa.int64()))
    episodes, populations, controllers, backends, mappings = (rows[c].to_pylist()
                                                              for c in RUN_KEY)
    keys = zip(episodes, populations, controllers, backends, mappings, strict=True)
    new = [ids[k] if k in ids else ids.setdefault(k, Run(*k, "").id) for k in keys]
    return rows.set_column(rows.schema.get_field_index("run_id"), "run_id",
                           pa.array(new, rows["run_id"].type))


def synthesize(src: Path, out: Path, target: int) -> int:
    """A study folder of at least ``target`` runs made from ``src`` (module doc); its run count."""
    copy_tables(src, out)  # runs, pedestrians and the manifest are replaced below
    manifest = json.loads((src / "manifest.json").read_text())
    runs = pq.read_table(src / "runs.parquet")
    plan = extra_seeds(manifest, runs, target)
    ids: dict[tuple, str] = {}
    all_runs = pa.concat_tables([runs] + [_renamed(runs, s, k, ids) for k, s in plan.items()])
    pq.write_table(all_runs, out / "runs.parquet")
    peds = pq.ParquetFile(src / "pedestrians.parquet")
    with pq.ParquetWriter(out / "pedestrians.parquet", peds.schema_arrow) as writer:
        for i in range(peds.num_row_groups):
            writer.write_table(peds.read_row_group(i))
        for k, s in plan.items():
            for i in range(peds.num_row_groups):
                writer.write_table(_renamed(peds.read_row_group(i), s, k, ids))
    for part in manifest["study_config"]["parts"].values():
        if part.get("seeds"):
            part["seeds"] = sorted({*part["seeds"], *plan})
    (out / "manifest.json").write_text(json.dumps(manifest, indent=2))
    return all_runs.num_rows


def copy_tables(src: Path, out: Path) -> None:
    """The tables, JSON files and figures of ``src`` (not its shards or report) into ``out``."""
    out.mkdir(parents=True, exist_ok=True)
    for path in [*src.glob("*.parquet"), *src.glob("*.json")]:
        shutil.copy(path, out / path.name)
    if (src / "figures").is_dir():
        shutil.copytree(src / "figures", out / "figures", dirs_exist_ok=True)


def bench_compaction(src: Path, scratch: Path) -> dict:
    """Compaction of ``src``'s shards into ``scratch``: peak RSS, time, tables equal to src's."""
    import pandas as pd

    scratch.mkdir(parents=True, exist_ok=True)
    rss, secs, out = measured([sys.executable, "-c", COMPACT, str(src), str(scratch)])
    same = {name: pd.read_parquet(scratch / f"{name}.parquet").equals(
        pd.read_parquet(src / f"{name}.parquet")) for name in ("runs", "pedestrians")
        if (src / f"{name}.parquet").exists()}
    return {"step": "compaction", "rows": json.loads(out), "peak_rss_mb": round(rss),
            "seconds": round(secs, 1), "equal_to_source": same}


def bench_report(folder: Path) -> dict:
    exe = Path(sys.executable).with_name("popnavshift")
    rss, secs, _ = measured([str(exe), "report", str(folder)])
    runs = pq.read_metadata(folder / "runs.parquet").num_rows
    return {"step": "report", "runs": runs, "peak_rss_mb": round(rss), "seconds": round(secs, 1)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--from", dest="src", type=Path, default=Path("study"),
                    help="a finished study folder, with its shards for the compaction")
    ap.add_argument("--runs", type=int, default=0,
                    help="measure the report on a synthetic study of at least this many runs")
    ap.add_argument("--out", type=Path, default=None, help="scratch folder (default: a temp one)")
    ap.add_argument("--skip", nargs="*", default=[], choices=["compaction", "report"])
    args = ap.parse_args()
    scratch = args.out or Path(tempfile.mkdtemp(prefix="bench-memory-"))
    rows = []
    if "compaction" not in args.skip:
        rows.append(bench_compaction(args.src, scratch / "compaction"))
        print(json.dumps(rows[-1]), flush=True)
    if "report" not in args.skip:
        folder = scratch / "study"  # the report is written into the folder: never --from's
        if args.runs > pq.read_metadata(args.src / "runs.parquet").num_rows:
            folder = scratch / f"study-{args.runs}"
            started = time.perf_counter()
            n = synthesize(args.src, folder, args.runs)
            print(f"synthetic study: {n:,} runs in {folder} "
                  f"({time.perf_counter() - started:.0f} s)", flush=True)
        else:
            copy_tables(args.src, folder)
        rows.append(bench_report(folder))
        print(json.dumps(rows[-1]), flush=True)


if __name__ == "__main__":
    main()
