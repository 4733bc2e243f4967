"""Flat persona tables (CSV, JSONL, Parquet) and the record rules shared by all sources.

A flat table has one row per persona, an id column (``persona_id``, or ``id`` when
``persona_id`` is absent) and one column per field id (SPEC §2b); other columns
are ignored. :func:`read_flat_table` checks the file and every value against the
shipped vocabulary and returns a table in the ``personas`` column layout whose
required fields may still be missing: :func:`apply_missing` then applies the
missing-field policy. The release reader (``matraix.py``) decodes its shards into
the same layout and reuses :func:`apply_missing` and :func:`sample_key`.

Rows in messages are 1-based data rows (the CSV header is not a row).
In CSV only an empty cell is missing: ``None`` is a value of ``accessibility_needs``.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow.parquet as pq

from ..errors import ConfigError, InputError, code_points
from .fields import PERSONA_FIELDS, REQUIRED_FIELDS, field_catalog, vocabulary
from .table import PERSONAS

ID_COLUMNS: tuple[str, ...] = ("persona_id", "id")
MISSING_POLICIES: tuple[str, ...] = ("require", "fill", "error")
SUFFIXES: tuple[str, ...] = (".csv", ".jsonl", ".parquet")


def read_flat_table(path: str | Path) -> pd.DataFrame:
    """Read and check a flat persona table; rows keep file order (row r at index r − 1).

    Columns: ``persona_id`` (str), ``source`` (the file name), the required and
    optional fields (str; missing as NaN). Raises :class:`InputError` naming the file,
    row, field and the allowed values on an unreadable file, missing columns, an
    unknown value, a missing or duplicate id.
    """
    path = Path(path)
    raw = _read_raw(path)
    if raw.empty:
        raise InputError(f"{path}: no data rows")
    id_col = next((c for c in ID_COLUMNS if c in raw.columns), None)
    if id_col is None:
        raise InputError(f"{path}: no id column", hint="expected a 'persona_id' or 'id' column")
    absent = [f for f in REQUIRED_FIELDS if f not in raw.columns]
    if absent:
        raise InputError(
            f"{path}: missing required column(s) {', '.join(absent)}",
            hint=f"a flat table needs one column per field: {', '.join(REQUIRED_FIELDS)}",
        )
    table = pd.DataFrame(
        {
            "persona_id": _ids(raw[id_col], path, id_col),
            "source": path.name,
            **{f: _field_values(raw, f) for f in PERSONA_FIELDS},
        }
    )
    for field in PERSONA_FIELDS:
        check_vocabulary(table[field], field, str(path))
    return table[PERSONAS.names]


def check_vocabulary(values: pd.Series, field: str, where: str, first_row: int = 1) -> None:
    """Raise naming ``where``, the row, ``field`` and the allowed values on an unknown value."""
    allowed = vocabulary(field)
    bad = values.notna().to_numpy() & ~values.isin(allowed).to_numpy()
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        more = int(bad.sum()) - 1
        raise InputError(
            f"{where}: row {first_row + k}: field {field!r} has unknown value "
            f"{values.iloc[k]!r}{code_points(str(values.iloc[k]))}"
            + (f" (and {more} more row(s))" if more else ""),
            hint=f"allowed: {', '.join(repr(v) for v in allowed)}",
        )


def apply_missing(
    table: pd.DataFrame,
    missing: str,
    where: str,
    first_row: int = 1,
    row_numbers: np.ndarray | None = None,
) -> tuple[pd.DataFrame, int, int]:
    """Apply the missing-field policy to required fields; returns (table, dropped, filled).

    ``require`` drops records lacking a required field (counted in ``dropped``);
    ``fill`` sets each missing required value to the field's schema ``defaultValue``
    (counted in ``filled``) and raises when the field has none; ``error`` raises on
    the first missing value. Optional fields stay missing under every policy. Rows
    in messages are ``row_numbers[position]`` when given, else ``first_row`` + position.
    """
    check_missing_policy(missing)
    absent = table[list(REQUIRED_FIELDS)].isna().to_numpy()
    if not absent.any():
        return table, 0, 0
    if missing == "require":
        keep = ~absent.any(axis=1)
        return table.iloc[np.flatnonzero(keep)], int((~keep).sum()), 0
    def row_number(position: int) -> int:
        return first_row + position if row_numbers is None else int(row_numbers[position])

    row, col = (int(i[0]) for i in np.nonzero(absent))
    field = REQUIRED_FIELDS[col]
    if missing == "error":
        raise InputError(
            f"{where}: row {row_number(row)}: required field {field!r} is missing",
            hint="--missing require (personas.missing: require) skips such records, "
                 "--missing fill fills schema defaults",
        )
    table = table.copy()
    for j, field in enumerate(REQUIRED_FIELDS):
        if not absent[:, j].any():
            continue
        default = field_catalog()[field].get("defaultValue")
        if not isinstance(default, str):
            row = int(np.flatnonzero(absent[:, j])[0])
            raise InputError(
                f"{where}: row {row_number(row)}: required field {field!r} is missing and "
                "has no schema default to fill",
                hint="--missing require (personas.missing: require) skips such records",
            )
        table[field] = table[field].fillna(default)
    return table, 0, int(absent.sum())


def check_missing_policy(missing: str) -> None:
    if missing not in MISSING_POLICIES:
        raise ConfigError(f"missing must be one of {', '.join(MISSING_POLICIES)}; got {missing!r}")


def sample_key(seed: int, persona_id: str) -> int:
    """Sampling priority: first 63 bits of sha256("<seed>\\x1f<persona_id>").

    A seeded sample of n records is the n smallest (key, persona_id): it depends
    on the ids only, never on file, shard or row order.
    """
    h = hashlib.sha256(f"{seed}\x1f{persona_id}".encode()).digest()
    return int.from_bytes(h[:8], "big") >> 1


def take_sample(table: pd.DataFrame, n: int | None, seed: int) -> pd.DataFrame:
    """The ``n`` records of ``table`` with the smallest :func:`sample_key` (all if None)."""
    if n is None or len(table) <= n:
        return table
    keys = table["persona_id"].map(lambda pid: sample_key(seed, pid))
    order = np.lexsort((table["persona_id"].to_numpy(str), keys.to_numpy(np.int64)))
    return table.iloc[np.sort(order[:n])]


def _read_raw(path: Path) -> pd.DataFrame:
    if not path.is_file():
        raise InputError(f"{path}: no such file")
    suffix = path.suffix.lower()
    if suffix not in SUFFIXES:
        raise InputError(
            f"{path}: unsupported persona table type {suffix!r}",
            hint=f"use one of {', '.join(SUFFIXES)}",
        )
    if path.stat().st_size == 0:
        raise InputError(f"{path}: file is empty")
    try:
        if suffix == ".csv":
            # Only an empty cell is missing: pandas' default NA strings include "None".
            return pd.read_csv(
                path, dtype=str, keep_default_na=False, na_values=[""], encoding="utf-8-sig"
            )
        if suffix == ".jsonl":
            return _read_jsonl(path)
        return _read_parquet(path)
    except InputError:
        raise
    except Exception as exc:  # pandas/pyarrow raise many types for a malformed file
        raise InputError(f"{path}: unreadable {suffix[1:]} file: {exc}") from exc


def _read_jsonl(path: Path) -> pd.DataFrame:
    records = []
    with path.open(encoding="utf-8") as fh:
        for line_no, line in enumerate(fh, start=1):
            if not line.strip():
                continue
            try:
                record = json.loads(line)
            except json.JSONDecodeError as exc:
                raise InputError(f"{path}: line {line_no}: invalid JSON ({exc.msg})") from exc
            if not isinstance(record, dict):
                raise InputError(f"{path}: line {line_no}: expected a JSON object per line")
            records.append(record)
    return pd.DataFrame.from_records(records, coerce_float=False)


def _read_parquet(path: Path) -> pd.DataFrame:
    names = pq.read_schema(path).names
    wanted = [c for c in (*ID_COLUMNS, *PERSONA_FIELDS) if c in names]
    return pq.read_table(path, columns=wanted).to_pandas()


def _ids(column: pd.Series, path: Path, id_col: str) -> np.ndarray:
    ids = np.array([None if _is_missing(v) else str(v) for v in column], dtype=object)
    empty = np.array([v is None or v == "" for v in ids])
    if empty.any():
        raise InputError(f"{path}: row {int(np.flatnonzero(empty)[0]) + 1}: {id_col!r} is empty")
    first_row: dict[str, int] = {}
    for row, pid in enumerate(ids, start=1):
        if pid in first_row:
            raise InputError(
                f"{path}: duplicate {id_col} {pid!r} at rows {first_row[pid]} and {row}"
            )
        first_row[pid] = row
    return ids


def _field_values(raw: pd.DataFrame, field: str) -> np.ndarray:
    if field not in raw.columns:  # only optional fields can be absent here
        return np.full(len(raw), None, dtype=object)
    # Non-strings (a number in JSON, say) are kept as they are: the vocabulary check names them.
    return np.array([None if _is_missing(v) else v for v in raw[field]], dtype=object)


def _is_missing(value: object) -> bool:
    return value is None or (isinstance(value, float) and np.isnan(value)) or value is pd.NA
