"""Tiny MatrAIx Persona 1M release folders for tests, laid out as published (never real rows).

``write_release`` writes what the public release holds, with pyarrow:

- ``persona_codes.schema.json`` (format ``persona_codes`` v2): 1,290 columns, ours
  interleaved with ``age_bracket``, ``region`` and filler fields; column order
  defines the slots (deliberately not our field order) and our fields' values are
  listed in reverse, so codes differ from our vocabulary order;
- shards ``data/persona-1m-0000.parquet``… (or nested ``data/<source>/…``) with the
  producer's columns: ``source``, ``source_row_index``, ``source_record_id``,
  ``attributes`` binary(645) (4-bit codes, even slot = low nibble), ``null_bitmap``
  binary(162) (packbits little, set = missing, null = nothing missing),
  ``attribute_overrides`` list<struct{field_index, value}> and two columns the reader
  must not need (``has_description``, ``metadata_json``); Zstd;
- ``sample/sample.parquet`` (a decoded preview with another schema),
  ``manifest.json`` (SHA-256 of every file), ``calibration_targets.json``,
  ``audit.json``, ``RESULTS.md`` and ``indexes/postings.sqlite``.

Records are sparse like the release's: a synthetic row has every field, a gss row
a handful of fillers; two records are minors.
"""

from __future__ import annotations

import hashlib
import json
import sqlite3
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from popnavshift.personas.fields import PERSONA_FIELDS, vocabulary
from popnavshift.personas.synthetic import generate_personas

N_COLUMNS = 1290
AGE_BRACKETS = ["Under 5", "5-12", "13-17", "18-24", "25-34", "35-44", "45-54", "55-64", "65+"]
EXTRA_FIELDS: dict[str, list[str]] = {
    "age_bracket": AGE_BRACKETS,
    "region": ["North America", "South Asia", "East Asia", "Western Europe"],
}
SOURCES = ("amazon", "gss", "stackoverflow", "synthetic", "wiki")
#: every how many filler fields a record of each source has a value (release-like sparsity)
FILLER_EVERY = {"gss": 90, "amazon": 50, "stackoverflow": 16, "wiki": 3, "synthetic": 1}
#: record index → a minor's age bracket
MINORS = {7: "Under 5", 12: "13-17"}
OVERRIDE_TYPE = pa.list_(
    pa.struct([pa.field("field_index", pa.uint16(), nullable=False), ("value", pa.string())])
)


def codebook_fields(order_seed: int = 7) -> list[dict]:
    """1,290 codebook columns: our 12 fields (values reversed), the extras, fillers; shuffled."""
    fields = [
        {"id": f, "label": f, "category": "Behaviour", "values": list(reversed(vocabulary(f)))}
        for f in PERSONA_FIELDS
    ]
    fields += [
        {"id": f, "label": f, "category": "Demographics", "values": v}
        for f, v in EXTRA_FIELDS.items()
    ]
    fields += [
        {"id": f"dim_{i:04d}", "label": f"Dim {i}", "category": "Other", "values": ["a", "b", "c"]}
        for i in range(N_COLUMNS - len(fields))
    ]
    order = np.random.default_rng(order_seed).permutation(len(fields))
    return [fields[i] for i in order]


def codebook_doc(fields: list[dict]) -> dict:
    return {"format": "persona_codes", "format_version": 2, "columns": fields}


def make_records(n: int = 60, seed: int = 3) -> list[dict]:
    """``n`` records (dicts field → value plus source, source_record_id, persona_id)."""
    table = generate_personas(n, seed)
    records = table.drop(columns="source").to_dict("records")
    fillers = [f"dim_{i:04d}" for i in range(N_COLUMNS - len(PERSONA_FIELDS) - len(EXTRA_FIELDS))]
    for k, record in enumerate(records):
        source = SOURCES[k % len(SOURCES)]
        record["source"] = source
        record["source_record_id"] = f"r{k:05d}"
        record["persona_id"] = f"{source}:r{k:05d}"
        record["age_bracket"] = MINORS.get(k, AGE_BRACKETS[3 + k % 6])
        record["region"] = EXTRA_FIELDS["region"][k % 4]
        for i in range(0, len(fillers), FILLER_EVERY[source]):
            record[fillers[i]] = "abc"[(k + i) % 3]
    return records


def adult_ids(records: list[dict]) -> list[str]:
    return sorted(r["persona_id"] for r in records if r["age_bracket"] not in MINORS.values())


def pack_record(record: dict, fields: list[dict]) -> tuple[bytes, bytes | None, list | None]:
    """(attributes, null_bitmap, overrides) for one record, as the producer encodes it.

    A field absent or None is missing; a value outside the field's codebook values is
    an override (code 0, not missing), like the producer's ``encode_mapping``.
    """
    codes = np.zeros(len(fields) + len(fields) % 2, dtype=np.uint8)
    missing = np.zeros(len(fields), dtype=bool)
    overrides = []
    for i, field in enumerate(fields):
        value = record.get(field["id"])
        if value is None:
            missing[i] = True
        elif value in field["values"]:
            codes[i] = field["values"].index(value)
        else:
            overrides.append({"field_index": i, "value": str(value)})
    attributes = (codes[0::2] | (codes[1::2] << 4)).astype(np.uint8).tobytes()
    bitmap = np.packbits(missing, bitorder="little").tobytes() if missing.any() else None
    return attributes, bitmap, overrides or None


def shard_table(rows: list[dict], fields: list[dict]) -> pa.Table:
    packed = [pack_record(r, fields) for r in rows]
    return pa.table(
        {
            "source": pa.array([r["source"] for r in rows], pa.string()),
            "source_row_index": pa.array(
                [int(r["source_record_id"][1:]) for r in rows], pa.uint64()
            ),
            "source_record_id": pa.array([r.get("source_record_id") for r in rows], pa.string()),
            "attributes": pa.array([p[0] for p in packed], pa.binary((len(fields) + 1) // 2)),
            "null_bitmap": pa.array([p[1] for p in packed], pa.binary((len(fields) + 7) // 8)),
            "attribute_overrides": pa.array([p[2] for p in packed], OVERRIDE_TYPE),
            "has_description": pa.array([False] * len(rows)),
            "metadata_json": pa.array(["{}"] * len(rows)),
        }
    )


def write_release(
    folder: Path,
    records: list[dict],
    n_shards: int = 3,
    fields: list[dict] | None = None,
    codebook: object = None,
    nested: bool = False,
    manifest: bool = True,
) -> Path:
    """Write ``records`` as a release folder (see the module docstring); returns ``folder``.

    ``codebook`` replaces the codebook document written; ``nested`` writes
    ``data/<source>/part-NNNN.parquet`` (``n_shards`` per source) instead of
    ``data/persona-1m-NNNN.parquet``.
    """
    fields = codebook_fields() if fields is None else fields
    folder.mkdir(parents=True, exist_ok=True)
    doc = codebook_doc(fields) if codebook is None else codebook
    (folder / "persona_codes.schema.json").write_text(json.dumps(doc), "utf-8")
    groups: dict[str, list[dict]] = {"": records}
    if nested:
        groups = {s: [r for r in records if r["source"] == s] for s in SOURCES}
    for group, members in groups.items():
        for s, chunk in enumerate(np.array_split(np.arange(len(members)), n_shards)):
            name = f"{group}/part-{s:04d}.parquet" if group else f"persona-1m-{s:04d}.parquet"
            path = folder / "data" / name
            path.parent.mkdir(parents=True, exist_ok=True)
            table = shard_table([members[i] for i in chunk], fields)
            pq.write_table(table, path, compression="zstd")
    _write_extras(folder, records)
    if manifest:
        write_manifest(folder)
    return folder


def _write_extras(folder: Path, records: list[dict]) -> None:
    """The release's other files: a decoded preview, targets, audit, results, an index."""
    (folder / "sample").mkdir(exist_ok=True)
    preview = {k: [str(r.get(k)) for r in records[:5]] for k in ("source", *PERSONA_FIELDS[:3])}
    pq.write_table(pa.table(preview), folder / "sample" / "sample.parquet")
    targets = {"age_bracket": {"Under 5": 0.06, "18-24": 0.1, "65+": 0.1}}
    (folder / "calibration_targets.json").write_text(json.dumps(targets), "utf-8")
    (folder / "audit.json").write_text(json.dumps({"rows": len(records)}), "utf-8")
    (folder / "RESULTS.md").write_text("# Results\n", "utf-8")
    (folder / "indexes").mkdir(exist_ok=True)
    with sqlite3.connect(folder / "indexes" / "postings.sqlite") as db:
        db.execute("CREATE TABLE IF NOT EXISTS postings (term TEXT, row_id INTEGER)")
    db.close()


def write_manifest(folder: Path) -> None:
    """``manifest.json``: the SHA-256 and size of every file of the release."""
    files = [
        {
            "path": p.relative_to(folder).as_posix(),
            "bytes": p.stat().st_size,
            "sha256": hashlib.sha256(p.read_bytes()).hexdigest(),
        }
        for p in sorted(folder.rglob("*"))
        if p.is_file() and p.name != "manifest.json"
    ]
    (folder / "manifest.json").write_text(json.dumps({"files": files}), "utf-8")
