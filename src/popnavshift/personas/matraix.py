"""Reader for a MatrAIx Persona 1M release folder (SPEC §2c), streamed shard by shard.

Where the files are is ``release.py``'s business; this module decodes them. Row
format of a shard (the producer's ``UNIFIED_SCHEMA``):

- ``source`` (gss, amazon, stackoverflow, wiki, prism, synthetic, …),
  ``source_row_index`` and ``source_record_id``. The persona id is
  ``source:source_record_id`` (``source:#source_row_index`` when the record id is
  null): stable across shard layouts and unique, duplicates raise.
- ``attributes``: binary(645), 4-bit codes two per byte; the field in codebook
  slot i is the low nibble of byte i // 2 when i is even, the high nibble when i is
  odd; a code indexes that field's ``values`` in the codebook.
- ``null_bitmap``: binary(162), ``np.packbits(missing, bitorder="little")``; a set bit
  means missing; a null bitmap means nothing missing. Rows are sparse (a gss row
  has about 15 of 1,290 fields, a synthetic row all of them).
- ``attribute_overrides``: list<struct{field_index, value}>, free-text values
  outside the codebook. We have no level for them, so an overridden field is
  missing (and its code, 0, is not read).

Codebook: ``{"format": "persona_codes", "columns": [{"id", "label", "category",
"values"}, …]}``; the column order defines the slots. For other layouts (via
``--codebook``) the columns may also be a top-level list or sit under ``fields`` or
``dimensions``, an entry's id under ``field_id`` or ``name`` and its values under
``levels`` (a list in code order, or an object code → value). Codebook values map
onto the shipped vocabulary by exact text, else ignoring case and surrounding
blanks; any other value of a field we use is an error, even if no record uses it.

Sampler policy, applied in this order before sampling: only the ``sources`` named
(all when None); minors excluded (``age_bracket`` whose upper bound is under 18,
e.g. "Under 5", "13-17"; a record without an age bracket is kept); the missing
policy of ``flat.apply_missing`` on our required fields. Each step's count is in
the provenance, with the records scanned and usable per source.

Sampling keeps the n records with the smallest ``sample_key(seed, persona_id)``
(see ``flat.py``). Memory holds at most n + ``batch_size`` records. Duplicate ids
are detected when both copies compete for the sample (the only case in which they
could change it).
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterator, Sequence
from functools import partial
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

from ..errors import ConfigError, InputError
from .codebook import Codebook, read_codebook
from .decode import decode_batch
from .flat import apply_missing, check_missing_policy, sample_key
from .release import codebook_path, find_shards, read_manifest, verify_shard
from .table import PERSONAS

DEFAULT_BATCH_SIZE = 65_536
ROW_COLUMNS = ("source", "source_row_index", "source_record_id", "attributes")
OPTIONAL_COLUMNS = ("null_bitmap", "attribute_overrides")

__all__ = ["Codebook", "decode_batch", "read_codebook", "read_release"]


def read_release(
    folder: str | Path,
    n: int | None,
    seed: int,
    missing: str = "require",
    batch_size: int = DEFAULT_BATCH_SIZE,
    codebook: str | Path | None = None,
    sources: Sequence[str] | None = None,
    verify_checksums: bool = True,
) -> tuple[pd.DataFrame, dict]:
    """Sample ``n`` records (all if None) from a release folder; returns (table, provenance).

    The table has the ``personas`` columns (``source`` = the record's source), in no
    particular order. Provenance: codebook, codebook_format, shards, checksums,
    batch_size, sources, records_scanned, scanned_per_source, records_other_source,
    records_excluded_minor, records_dropped_missing, values_filled, usable_per_source.
    """
    check_missing_policy(missing)
    if isinstance(batch_size, bool) or not isinstance(batch_size, int) or batch_size < 1:
        raise ConfigError(f"batch_size must be a positive integer, got {batch_size!r}")
    folder = Path(folder)
    if not folder.is_dir():
        raise InputError(f"{folder}: no such release folder")
    book = read_codebook(codebook_path(folder, codebook))
    shards = find_shards(folder)
    checksums = read_manifest(folder) if verify_checksums else None
    wanted = None if sources is None else frozenset(sources)
    counts: Counter[str] = Counter()
    scanned: Counter[str] = Counter()
    usable: Counter[str] = Counter()
    kept: pd.DataFrame | None = None
    for shard in shards:
        if checksums is not None:
            verify_shard(folder, shard, checksums)
        name = shard.relative_to(folder).as_posix()
        first_row = 1
        for batch in _iter_batches(shard, batch_size):
            records = decode_batch(batch, book, str(shard), first_row)
            records["_where"] = name
            records["_row"] = np.arange(first_row, first_row + len(records))
            first_row += batch.num_rows
            scanned.update(records["source"])
            records = _apply_policy(records, wanted, missing, str(shard), counts)
            usable.update(records["source"])
            kept = _keep_smallest(kept, records, n, seed)
    _check_sources_seen(wanted, scanned, folder)
    prov = {
        "codebook": str(book.path),
        "codebook_format": book.format,
        "shards": [s.relative_to(folder).as_posix() for s in shards],
        "checksums": _checksum_note(verify_checksums, checksums),
        "batch_size": batch_size,
        "sources": None if wanted is None else sorted(wanted),
        "records_scanned": sum(scanned.values()),
        "scanned_per_source": dict(sorted(scanned.items())),
        "records_other_source": counts["other_source"],
        "records_excluded_minor": counts["minor"],
        "records_dropped_missing": counts["dropped"],
        "values_filled": counts["filled"],
        "usable_per_source": dict(sorted(usable.items())),
    }
    if kept is None:
        kept = pd.DataFrame(columns=PERSONAS.names)
    return kept[PERSONAS.names].reset_index(drop=True), prov


def _apply_policy(
    records: pd.DataFrame,
    sources: frozenset[str] | None,
    missing: str,
    where: str,
    counts: Counter[str],
) -> pd.DataFrame:
    """Named sources only, no minors, then the missing policy; counts what each step drops."""
    if sources is not None:
        ours = records["source"].isin(sources).to_numpy()
        counts["other_source"] += int((~ours).sum())
        records = records[ours]
    minor = records["_minor"].to_numpy(bool)
    counts["minor"] += int(minor.sum())
    records = records[~minor]
    records = records.reset_index(drop=True)
    records, dropped, filled = apply_missing(
        records, missing, where, row_numbers=records["_row"].to_numpy()
    )
    counts["dropped"] += dropped
    counts["filled"] += filled
    return records


def _check_sources_seen(wanted: frozenset[str] | None, scanned: Counter[str], folder: Path) -> None:
    absent = sorted((wanted or frozenset()) - set(scanned))
    if absent:
        raise InputError(
            f"{folder}: no record of source(s) {', '.join(absent)}",
            hint=f"sources in this release: {', '.join(sorted(scanned)) or 'none'}",
        )


def _checksum_note(verify: bool, checksums: dict[str, str] | None) -> str:
    if not verify:
        return "not verified (turned off)"
    return "no manifest.json" if checksums is None else "verified against manifest.json"


def _keep_smallest(
    kept: pd.DataFrame | None, records: pd.DataFrame, n: int | None, seed: int
) -> pd.DataFrame:
    """Merge ``records`` into ``kept``, keeping the n smallest (key, id); checks duplicates."""
    if n is not None:
        records = records.assign(_key=records["persona_id"].map(partial(sample_key, seed)))
        if kept is not None and len(kept) >= n:  # only records that could enter the sample
            records = records[records["_key"] <= kept["_key"].max()]
    both = records if kept is None else pd.concat([kept, records], ignore_index=True)
    dup = both["persona_id"].duplicated(keep=False).to_numpy()
    if dup.any():
        first = both.loc[dup, "persona_id"].iloc[0]
        copies = both[both["persona_id"] == first]
        where = [f"{s} row {r}" for s, r in zip(copies["_where"], copies["_row"], strict=True)]
        raise InputError(f"duplicate persona id {first!r} in {' and '.join(where)}")
    if n is not None and len(both) > n:
        both = both.sort_values(["_key", "persona_id"], kind="stable").iloc[:n]
    return both.reset_index(drop=True)


def _iter_batches(shard: Path, batch_size: int) -> Iterator[pa.RecordBatch]:
    try:
        parquet = pq.ParquetFile(shard)
        names = parquet.schema_arrow.names
        absent = [c for c in ROW_COLUMNS if c not in names]
        if absent:
            raise InputError(
                f"{shard}: shard lacks column(s) {', '.join(absent)}; has {', '.join(names)}"
            )
        wanted = [*ROW_COLUMNS, *(c for c in OPTIONAL_COLUMNS if c in names)]
        yield from parquet.iter_batches(batch_size=batch_size, columns=wanted)
    except (pa.ArrowException, OSError) as exc:
        raise InputError(f"{shard}: unreadable Parquet shard: {exc}") from exc
