"""Decode speed of the MatrAIx release reader on one release-sized shard.

    .venv/bin/python benchmarks/bench_release.py [--rows 100000] [--repeats 3]

Writes a temporary release (the test fixture's 1,290-column codebook, random codes,
60% of fields missing, Zstd) and times ``read_release`` on it: rows/s and seconds
per 100,000-row shard (the real release has ten). Not a test: a measurement.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from fixtures_matraix import OVERRIDE_TYPE, SOURCES, codebook_doc, codebook_fields  # noqa: E402
from popnavshift.personas.matraix import read_release  # noqa: E402


def fixed_binary(matrix: np.ndarray) -> pa.Array:
    matrix = np.ascontiguousarray(matrix, dtype=np.uint8)
    width = matrix.shape[1]
    return pa.Array.from_buffers(pa.binary(width), len(matrix), [None, pa.py_buffer(matrix)])


def write_shard(folder: Path, rows: int, seed: int = 0) -> None:
    fields = codebook_fields()
    rng = np.random.default_rng(seed)
    n_values = np.array([len(f["values"]) for f in fields])
    codes = (rng.random((rows, len(fields))) * n_values).astype(np.uint8)
    codes = np.concatenate([codes, np.zeros((rows, len(fields) % 2), np.uint8)], axis=1)
    missing = rng.random((rows, len(fields))) < 0.6
    table = pa.table(
        {
            "source": pa.array(np.array(SOURCES)[np.arange(rows) % len(SOURCES)]),
            "source_row_index": pa.array(np.arange(rows, dtype=np.uint64)),
            "source_record_id": pa.array([f"r{i}" for i in range(rows)]),
            "attributes": fixed_binary(codes[:, 0::2] | (codes[:, 1::2] << 4)),
            "null_bitmap": fixed_binary(np.packbits(missing, axis=1, bitorder="little")),
            "attribute_overrides": pa.array([None] * rows, OVERRIDE_TYPE),
        }
    )
    (folder / "persona_codes.schema.json").write_text(json.dumps(codebook_doc(fields)))
    (folder / "data").mkdir()
    pq.write_table(table, folder / "data" / "persona-1m-0000.parquet", compression="zstd")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rows", type=int, default=100_000)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        write_shard(Path(tmp), args.rows)
        for _ in range(args.repeats):
            started = time.perf_counter()
            _, prov = read_release(Path(tmp), n=600, seed=0)
            seconds = time.perf_counter() - started
            print(
                f"{prov['records_scanned']} rows in {seconds:.2f} s "
                f"({prov['records_scanned'] / seconds:,.0f} rows/s; "
                f"{seconds * 100_000 / args.rows:.2f} s per 100k-row shard)"
            )


if __name__ == "__main__":
    main()
