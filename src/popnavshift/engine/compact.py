"""Compaction of a study's shards into ``runs.parquet`` and ``pedestrians.parquet``, streamed.

The tables are sorted by run key, whose first column is the episode, and every shard
holds one episode's runs (a batch is an episode × backend × mapping): so the sorted
tables are the episodes in order, each sorted on its own. Episodes are taken a few
at a time (about :data:`CHUNK_RUNS` runs), sorted, checked and appended to a Parquet
writer, so memory holds one chunk rather than the whole study (a 257k-run study held
2.4 GB as whole pandas tables). Runs carried over from the present tables are read
from them in the same episode order, one record batch at a time. Both files are
written under temporary names and renamed at the end: an interrupted compaction
leaves the previous tables, or none, never half of one.
"""

from __future__ import annotations

import ctypes
import gc
from collections.abc import Iterator, Mapping
from contextlib import ExitStack, suppress
from itertools import groupby
from pathlib import Path

import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

from ..io import atomic_path
from ..populations.identity import PopulationSpec, with_population_columns
from ..populations.perturb import with_profile_set_columns
from ..tables import PEDESTRIANS, RUN_KEY, RUNS, check_table

#: Runs per chunk: large enough for few row groups, small enough that a chunk's
#: pedestrian rows (about 8 per run) stay in the tens of megabytes.
CHUNK_RUNS = 20_000
#: Rows per record batch read from the present tables for the carried runs.
CARRIED_BATCH_ROWS = 65_536

#: (runs shard, pedestrians shard, runs in it) of one batch, with its episode
Shard = tuple[str, Path, Path, int]
TABLES = tuple((spec.stage, spec.file, list(spec.key)) for spec in (RUNS, PEDESTRIANS))


def episode_chunks(shards: list[Shard], chunk_runs: int = CHUNK_RUNS) -> list[list[Shard]]:
    """The shards grouped by episode in sorted order, consecutive episodes joined until a
    chunk holds at least ``chunk_runs`` runs (an episode is never split)."""
    chunks: list[list[Shard]] = []
    current: list[Shard] = []
    size = 0
    for _, group in groupby(sorted(shards, key=lambda s: s[0]), key=lambda s: s[0]):
        members = list(group)
        current += members
        size += sum(s[3] for s in members)
        if size >= chunk_runs:
            chunks.append(current)
            current, size = [], 0
    if current:
        chunks.append(current)
    return chunks


class CarriedRows:
    """The carried runs' rows of a present (sorted) table, read in order: ``upto(e)``
    gives those of every episode ≤ ``e`` not given yet (all that remain for None),
    with ``part`` as the plan now says."""

    def __init__(self, path: Path, carried: set[tuple], part: dict[tuple, str]) -> None:
        self._batches = pq.ParquetFile(path).iter_batches(batch_size=CARRIED_BATCH_ROWS)
        self._schema = pq.read_schema(path)
        self._carried, self._part = carried, part
        self._buffer: list[pd.DataFrame] = []
        self._last_read: str | None = None  # episode of the last row read
        self._done = False

    def _pull(self) -> None:
        try:
            batch = next(self._batches)
        except StopIteration:
            self._done = True
            return
        # through a Table with the file's schema: its pandas metadata sets the dtypes
        df = pa.Table.from_batches([batch], self._schema).to_pandas()
        if len(df):
            self._last_read = df["episode"].iloc[-1]
        keys = pd.Series(list(zip(*(df[c] for c in RUN_KEY), strict=True)), index=df.index)
        df = df[keys.isin(self._carried)].copy()
        df["part"] = keys[df.index].map(self._part)
        if not df.empty:
            self._buffer.append(df)

    def upto(self, episode: str | None) -> list[pd.DataFrame]:
        while not self._done and (episode is None or self._last_read is None
                                  or self._last_read <= episode):
            self._pull()
        if episode is None:
            out, self._buffer = self._buffer, []
            return out
        out, rest = [], []
        for df in self._buffer:
            mine = df["episode"] <= episode
            out.append(df[mine])
            rest.append(df[~mine])
        self._buffer = rest
        return out


def _sorted_chunk(frames: list[pd.DataFrame], name: str, key: list[str],
                  specs: Mapping[str, PopulationSpec],
                  inputs: Mapping[tuple, str]) -> pd.DataFrame:
    """One chunk of a table as the whole-table compaction made it: joined, ``error`` as
    a string column, each run's ``run_inputs`` from ``inputs``, sorted by ``key`` and
    checked."""
    df = pd.concat(frames, ignore_index=True)
    if name == "runs":
        if "error" not in df.columns:  # shards written before the column existed
            df["error"] = None
        df["error"] = df["error"].astype("string")  # all-None would be Arrow's null type
        keys = zip(*(df[c] for c in RUN_KEY), strict=True)
        digests = [inputs.get(k) for k in keys]
        # where the worker puts it (before error), also for rows stored before the column
        df = df.drop(columns="run_inputs", errors="ignore")
        df.insert(df.columns.get_loc("error"), "run_inputs", digests)
    df = with_profile_set_columns(df)  # rows stored before those columns existed
    df = with_population_columns(df, specs)
    df = df.sort_values(key, kind="stable").reset_index(drop=True)
    return check_table(df, name)


class _TableWriter:
    """A Parquet writer opened on the first chunk (its schema, pandas metadata included,
    is the table's); every later chunk is cast to that schema."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.writer: pq.ParquetWriter | None = None
        self.rows = 0

    def write(self, df: pd.DataFrame) -> None:
        if df.empty and self.writer is not None:
            return
        table = pa.Table.from_pandas(df, preserve_index=False)
        if self.writer is None:
            self.writer = pq.ParquetWriter(self.path, table.schema)
        else:
            table = table.select(self.writer.schema.names).cast(self.writer.schema)
        self.writer.write_table(table)
        self.rows += len(df)

    def close(self) -> None:
        if self.writer is not None:
            self.writer.close()


def write_compacted(folder: Path, chunks: list[list[Shard]],
                    carried: tuple[set[tuple], dict[tuple, str]] | None = None,
                    specs: Mapping[str, PopulationSpec] | None = None,
                    inputs: Mapping[tuple, str] | None = None) -> tuple[int, int]:
    """Write ``folder/runs.parquet`` and ``folder/pedestrians.parquet`` from the shard
    ``chunks`` (:func:`episode_chunks`) plus, with ``carried`` (the keys of the runs to
    carry and the part of each), those runs' rows of the present tables; returns their
    row counts. Nothing replaces the present tables before both new ones are complete.
    ``specs`` (the study's populations) fill the population columns of rows stored
    before they existed; ``inputs`` gives every run its ``run_inputs`` (the digest of its
    own inputs, :mod:`.run_inputs`)."""
    readers = {name: CarriedRows(folder / file, *carried) if carried else None
               for name, file, _ in TABLES}
    with ExitStack() as stack:
        writers = {name: _TableWriter(stack.enter_context(atomic_path(folder / file)))
                   for name, file, _ in TABLES}
        try:
            for i, chunk in enumerate(_chunks_or_carried_only(chunks, readers)):
                last = None if i == len(chunks) - 1 or not chunks else chunk[-1][0]
                for column, (name, _, key) in enumerate(TABLES):
                    frames = [pd.read_parquet(s[1 + column]) for s in chunk]
                    reader = readers[name]
                    if reader is not None:
                        frames += reader.upto(last)
                    frames = [f for f in frames if not f.empty] or frames[:1]
                    if frames:
                        writers[name].write(_sorted_chunk(frames, name, key, specs or {},
                                                          inputs or {}))
        finally:
            for w in writers.values():
                w.close()
        if any(w.writer is None for w in writers.values()):
            raise ValueError(f"{folder}: nothing to compact")  # a plan always has runs
    _release_memory()
    return writers["runs"].rows, writers["pedestrians"].rows


def _release_memory() -> None:
    """Give what the simulation and the compaction freed back to the system before the
    report, which runs in the same process: Arrow's pool and glibc's heap keep freed
    pages (on the paper study, `make run` peaked at 1.91 GB without this)."""
    gc.collect()
    pa.default_memory_pool().release_unused()
    with suppress(OSError, AttributeError):  # glibc only
        ctypes.CDLL("libc.so.6").malloc_trim(0)


def _chunks_or_carried_only(chunks: list[list[Shard]],
                            readers: dict[str, CarriedRows | None]) -> Iterator[list[Shard]]:
    """The chunks; with no shard at all but carried runs, one empty chunk that takes them."""
    if chunks:
        yield from chunks
    elif any(readers.values()):
        yield []
