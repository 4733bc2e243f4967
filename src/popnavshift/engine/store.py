"""The study folder's run store: atomic shards, validation, compaction.

Each finished batch writes ``shards/peds/<batch>.parquet`` then
``shards/runs/<batch>.parquet`` (the runs shard is the commit marker), both
atomically and both tagged with the batch id and run count in the Parquet
metadata. On resume a batch counts as done only when both shards read back
with the right tag and row count; anything else (missing, truncated, corrupt,
foreign) is deleted and redone, never merged. At the end the shards are
compacted, sorted by run key, into ``runs.parquet`` and ``pedestrians.parquet``
(a few episodes at a time, :mod:`.compact`), each run with the digest of its own inputs
(``run_inputs``, :mod:`.run_inputs`); a later run of the study carries over from them
every run it still plans with the same digest (:meth:`RunStore.carried`).
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path

import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

from ..design.plan import Run
from ..io import write_atomic, write_json
from ..populations.identity import PopulationSpec
from ..read.checks import RUNS_IDENTITY, RUNS_RECORD, read_stamps, readable_parquet
from ..tables import RUN_KEY as TABLE_RUN_KEY
from ..tables import RUNS
from .batches import Batch
from .compact import episode_chunks, write_compacted
from .run_inputs import run_inputs

RUN_KEY = list(TABLE_RUN_KEY)
META_KEY = b"popnavshift"


class RunStore:
    def __init__(self, folder: Path) -> None:
        self.folder = Path(folder)
        self.runs_dir = self.folder / "shards" / "runs"
        self.peds_dir = self.folder / "shards" / "peds"

    def _paths(self, batch: Batch) -> tuple[Path, Path]:
        name = f"{batch.id}.parquet"
        return self.runs_dir / name, self.peds_dir / name

    @staticmethod
    def _write(df: pd.DataFrame, path: Path, tag: dict) -> None:
        table = pa.Table.from_pandas(df, preserve_index=False)
        meta = dict(table.schema.metadata or {})
        meta[META_KEY] = json.dumps(tag).encode()
        write_atomic(path, lambda tmp: pq.write_table(table.replace_schema_metadata(meta), tmp))

    def write_batch(self, batch: Batch, runs: pd.DataFrame, peds: pd.DataFrame) -> None:
        runs_path, peds_path = self._paths(batch)
        self._write(peds, peds_path, {"batch": batch.id, "rows": len(peds)})
        self._write(runs, runs_path, {"batch": batch.id, "rows": len(batch.runs)})

    @staticmethod
    def _valid(path: Path, batch_id: str, rows: int | None) -> bool:
        try:
            f = pq.ParquetFile(path)
            tag = json.loads((f.schema_arrow.metadata or {})[META_KEY])
            if tag.get("batch") != batch_id or f.metadata.num_rows != tag.get("rows"):
                return False
            if rows is not None and f.metadata.num_rows != rows:
                return False
            f.read()  # decodes every page: catches truncated or corrupt data
            return True
        except Exception:
            return False

    def is_done(self, batch: Batch, clean: bool = True) -> bool:
        """True when both shards of ``batch`` are present and valid; otherwise cleans them
        (unless ``clean`` is False: a plan that only counts changes nothing)."""
        runs_path, peds_path = self._paths(batch)
        if (
            runs_path.exists()
            and peds_path.exists()
            and self._valid(runs_path, batch.id, len(batch.runs))
            and self._valid(peds_path, batch.id, None)
        ):
            return True
        if clean:
            for p in (runs_path, peds_path):
                p.unlink(missing_ok=True)
        return False

    # ---- runs carried over from the compacted tables ----
    #: stages.json entry: the compacted tables are whole (written last by a compaction)
    RECORD = RUNS_RECORD
    #: its value's version: runs carry the digest of their own inputs (``run_inputs``)
    IDENTITY = RUNS_IDENTITY

    def carried(self, planned: Mapping[tuple, str],
                stored: Mapping[tuple, str] | None = None) -> set[tuple]:
        """Keys of the ``planned`` runs (key → digest of its inputs) the compacted tables
        already hold with the same digest: they are not run again. ``stored`` stands in
        for the tables' ``run_inputs`` column when they predate it (:meth:`legacy_inputs`).
        Empty without a record (never compacted, or compaction interrupted) or when a
        table is damaged or lacks a column of today's."""
        if stored is not None:
            return {k for k, d in planned.items() if stored.get(k) == d}
        record = self._record()
        runs_path = self.folder / "runs.parquet"
        if (record is None or record.get("run_inputs") != self.IDENTITY
                or not self.tables_intact()
                or set(RUNS.names) - set(pq.read_schema(runs_path).names)):  # older columns
            return set()
        have = pd.read_parquet(runs_path, columns=[*RUN_KEY, "run_inputs"])
        keys = zip(*(have[c] for c in RUN_KEY), strict=True)
        return {k for k, d in zip(keys, have["run_inputs"], strict=True)
                if planned.get(k) == d}

    def legacy_inputs(self, populations: pd.DataFrame, episode_seed: int,
                      inputs_stamp: str) -> dict[tuple, str] | None:
        """The digests of the runs of tables compacted before runs carried their own
        (a record of the populations' and episodes' stamps and each controller's code
        stamp), computed from ``populations`` as it is now: only when the record's stamp
        is ``inputs_stamp`` (the stamp of the folder's present populations and episodes,
        so the stored runs were simulated from them), each run with the code stamp it was
        run with. None when there is nothing to migrate or it cannot be trusted (then
        nothing is carried, as before)."""
        record = self._record()
        if (record is None or "inputs" not in record or record["inputs"] != inputs_stamp
                or not self.tables_intact()):
            return None
        columns = set(pq.read_schema(self.folder / "runs.parquet").names)
        if set(RUNS.names) - columns != {"run_inputs"}:
            return None
        have = pd.read_parquet(self.folder / "runs.parquet", columns=RUN_KEY)
        keys = list(zip(*(have[c] for c in RUN_KEY), strict=True))
        return run_inputs(keys, populations, episode_seed, record.get("code", {}))

    def tables_intact(self) -> bool:
        """Whether both compacted tables exist and read back. A damaged one (a truncated
        copy, a disk error) is never carried: its runs are rebuilt from their shards."""
        return all(readable_parquet(self.folder / name)
                   for name in ("runs.parquet", "pedestrians.parquet"))

    def _record(self) -> dict | None:
        return read_stamps(self.folder).get(self.RECORD)

    def _set_record(self, record: dict | None) -> None:
        path = self.folder / "stages.json"
        stamps = read_stamps(self.folder)
        if record is None:
            stamps.pop(self.RECORD, None)
        else:
            stamps[self.RECORD] = record
        write_json(stamps, path)

    def compact_files(self, batches: list[Batch], planned: list[Run] | None = None,
                      carried: set[tuple] | None = None,
                      inputs: Mapping[tuple, str] | None = None,
                      specs: Mapping[str, PopulationSpec] | None = None, *,
                      record: bool = True) -> tuple[int, int]:
        """Write the two study tables, sorted by key: every batch's shards, plus the
        ``carried`` runs (keys) of the present compacted tables, with their part as
        ``planned`` now says and the digest of their inputs as ``inputs`` says
        (``run_inputs``); returns their row counts. Streamed a few episodes at a time
        (:mod:`.compact`). The record is removed first and written last (``record``: the
        tables are a study's, to be carried by its next run), so tables a crash left
        half-written are never carried."""
        shards = [(b.episode, *self._paths(b), len(b.runs)) for b in batches]
        keep = None
        if carried:
            keep = (set(carried), {r.key: r.part for r in planned or []})
        self._set_record(None)
        counts = write_compacted(self.folder, episode_chunks(shards), keep, specs,
                                 inputs or {})
        if record:
            self._set_record({"run_inputs": self.IDENTITY})
        return counts

    def compact(self, batches: list[Batch], planned: list[Run] | None = None,
                carried: set[tuple] | None = None,
                inputs: Mapping[tuple, str] | None = None,
                specs: Mapping[str, PopulationSpec] | None = None, *,
                record: bool = True) -> tuple[pd.DataFrame, pd.DataFrame]:
        """:meth:`compact_files`, then the two tables read back (for small studies)."""
        self.compact_files(batches, planned, carried, inputs, specs, record=record)
        return (pd.read_parquet(self.folder / "runs.parquet"),
                pd.read_parquet(self.folder / "pedestrians.parquet"))
