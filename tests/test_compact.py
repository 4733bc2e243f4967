"""Streamed compaction and the analysis's categorical read: same tables as the whole-table code."""

from __future__ import annotations

import functools
import json
import shutil
from pathlib import Path

import pandas as pd
import pyarrow.parquet as pq
import pytest

from engine_helpers import TINY, tables, with_controllers
from popnavshift.design.study import study_from_dict
from popnavshift.engine import compact, store
from popnavshift.engine.runner import run_study
from popnavshift.read.folder import read_categorical
from popnavshift.tables import RUN_KEY


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    folder = tmp_path_factory.mktemp("ref")
    run_study(study_from_dict(TINY), folder, workers=1, show_progress=False)
    return folder


@pytest.fixture
def tiny_chunks(monkeypatch):
    """Every episode its own chunk, and carried rows read 7 at a time: every boundary
    the streaming has is crossed many times on the tiny study."""
    monkeypatch.setattr(store, "episode_chunks",
                        functools.partial(compact.episode_chunks, chunk_runs=1))
    monkeypatch.setattr(compact, "CARRIED_BATCH_ROWS", 7)


def whole_table_compaction(folder: Path) -> tuple[pd.DataFrame, pd.DataFrame]:
    """The tables as the compaction made them before it was streamed: every shard
    concatenated in pandas, then sorted."""
    shards = sorted((folder / "shards" / "runs").glob("*.parquet"))
    runs = pd.concat([pd.read_parquet(p) for p in shards], ignore_index=True)
    peds = pd.concat([pd.read_parquet(folder / "shards" / "peds" / p.name) for p in shards],
                     ignore_index=True)
    runs["error"] = runs["error"].astype("string")
    runs = runs.sort_values(list(RUN_KEY), kind="stable").reset_index(drop=True)
    peds = peds.sort_values([*RUN_KEY, "slot"], kind="stable").reset_index(drop=True)
    return runs, peds


def test_streamed_tables_equal_the_whole_table_compaction(reference, tmp_path, tiny_chunks):
    folder = tmp_path / "chunked"
    shutil.copytree(reference, folder)
    for name in ("runs.parquet", "pedestrians.parquet"):
        (folder / name).unlink()
    report = run_study(study_from_dict(TINY), folder, workers=1, show_progress=False)
    assert report.executed == 0 and report.compacted
    assert pq.ParquetFile(folder / "runs.parquet").num_row_groups == 6  # one per episode
    for ours, whole, ref in zip(tables(folder), whole_table_compaction(folder),
                                tables(reference), strict=True):
        pd.testing.assert_frame_equal(ours, whole)
        pd.testing.assert_frame_equal(ours, ref)


def test_carried_runs_merge_in_order_across_chunks(reference, tmp_path, tiny_chunks):
    folder = tmp_path / "grow"
    run_study(study_from_dict(with_controllers("robot_orca")), folder, workers=1,
              show_progress=False)
    second = run_study(study_from_dict(TINY), folder, workers=1, show_progress=False)
    assert second.executed == 6 * 3 and second.reused == 6 * 3 * 2  # 36 runs carried
    for ours, ref in zip(tables(folder), tables(reference), strict=True):
        pd.testing.assert_frame_equal(ours, ref)


def test_an_interrupted_compaction_leaves_the_old_tables_and_no_record(
        reference, tmp_path, tiny_chunks, monkeypatch):
    folder = tmp_path / "interrupted"
    shutil.copytree(reference, folder)
    before = {n: (folder / n).read_bytes() for n in ("runs.parquet", "pedestrians.parquet")}
    chunks = []

    def failing(frames, name, key, specs, inputs):
        chunks.append(name)
        if len(chunks) == 5:  # mid-way: two episodes written to the new files
            raise KeyboardInterrupt
        return real(frames, name, key, specs, inputs)

    real = compact._sorted_chunk
    monkeypatch.setattr(compact, "_sorted_chunk", failing)
    runs = sorted((folder / "shards" / "runs").glob("*.parquet"))
    shards = [(pd.read_parquet(p, columns=["episode"])["episode"].iloc[0], p,
               folder / "shards" / "peds" / p.name, pq.read_metadata(p).num_rows) for p in runs]
    batches = [_Batch(s) for s in shards]
    with pytest.raises(KeyboardInterrupt):
        store.RunStore(folder).compact_files(batches, inputs=stored_inputs(folder))  # type: ignore[arg-type]
    assert {n: (folder / n).read_bytes() for n in before} == before  # untouched
    assert not [p.name for p in folder.iterdir() if p.name.endswith(".tmp")]
    assert "runs" not in json.loads((folder / "stages.json").read_text())  # never carried
    monkeypatch.setattr(compact, "_sorted_chunk", real)
    report = run_study(study_from_dict(TINY), folder, workers=1, show_progress=False)
    assert report.executed == 0 and report.compacted
    for ours, ref in zip(tables(folder), tables(reference), strict=True):
        pd.testing.assert_frame_equal(ours, ref)


def stored_inputs(folder: Path) -> dict[tuple, str]:
    """Each stored run's ``run_inputs`` by its key (what a plan gives the compaction)."""
    runs = pd.read_parquet(folder / "runs.parquet", columns=[*RUN_KEY, "run_inputs"])
    return dict(zip(zip(*(runs[c] for c in RUN_KEY), strict=True), runs["run_inputs"],
                    strict=True))


class _Batch:
    """A stand-in batch for ``RunStore.compact_files``: its episode, its number of runs
    and its id (the store finds the batch's shard files from the id)."""

    def __init__(self, shard: tuple) -> None:
        self.episode, runs_path, _, n = shard
        self.runs = [None] * n
        self.id = runs_path.stem


def test_categorical_read_equals_astype_category(tmp_path):
    values = ["b", "é", None, "Z", "a", "b", "ä", "a"]
    df = pd.DataFrame({"name": pd.Series(values, dtype="str"), "n": range(len(values)),
                       "other": pd.Series(values[::-1], dtype="str")})
    path = tmp_path / "t.parquet"
    df.to_parquet(path, index=False, row_group_size=3)  # dictionaries differ per row group
    assert pq.ParquetFile(path).num_row_groups == 3
    ours = read_categorical(path, ["name", "n"])
    text = pd.read_parquet(path, columns=["name", "n"]).astype({"name": "category"})
    pd.testing.assert_frame_equal(ours, text)
    assert list(ours["name"].cat.categories) == ["Z", "a", "b", "ä", "é"]
