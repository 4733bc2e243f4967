"""The machinery of :mod:`popnavshift.tables`: a column, a table's declaration, the
registry of declared tables and the check of a table against its declaration.

:mod:`popnavshift.tables` declares the tables with it (and re-exports it); this module
knows none of them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from .errors import InputError

#: dtype of each column kind in a Parquet file read with pandas
DTYPES = {"str": "string", "float": "float64", "int": "int64", "bool": "bool"}


@dataclass(frozen=True)
class Column:
    """One declared column: its dtype and, for the data dictionary (docs/data.md),
    its unit ("1" = dimensionless, "" = not a quantity), meaning, what a missing value
    means (required when nullable) and the ``table.column`` it refers to."""

    name: str
    kind: str  # "str", "float", "int", "bool"
    nullable: bool = False
    unit: str = ""
    doc: str = ""
    missing: str = ""
    refers: str = ""


@dataclass(frozen=True)
class TableSpec:
    stage: str
    columns: tuple[Column, ...]
    key: tuple[str, ...]
    file: str = ""  # file name in a study folder
    doc: str = ""  # what one row is

    @property
    def names(self) -> list[str]:
        return [c.name for c in self.columns]


def column(name: str, kind: str, doc: str, unit: str = "", **kw: object) -> Column:
    return Column(name, kind, unit=unit, doc=doc, **kw)  # type: ignore[arg-type]


SPECS: dict[str, TableSpec] = {}


def declare(
    stage: str, columns: tuple[Column, ...], key: tuple[str, ...], file: str = "", doc: str = ""
) -> TableSpec:
    spec = TableSpec(stage, columns, key, file or f"{stage}.parquet", doc)
    SPECS[stage] = spec
    return spec


_KIND_CHECK = {
    "str": lambda s: pd.api.types.is_string_dtype(s) or pd.api.types.is_object_dtype(s),
    "float": pd.api.types.is_float_dtype,
    "int": pd.api.types.is_integer_dtype,
    "bool": pd.api.types.is_bool_dtype,
}


def check_table(df: pd.DataFrame, stage: str) -> pd.DataFrame:
    """Validate ``df`` against the declaration of ``stage``; return it unchanged.

    Checks presence and dtype of every column, nulls in non-nullable columns,
    finiteness of float columns and uniqueness of the key.
    """
    spec = SPECS[stage]
    missing = [c for c in spec.names if c not in df.columns]
    if missing:
        raise InputError(f"{stage} table: missing column(s) {', '.join(missing)}")
    for col in spec.columns:
        s = df[col.name]
        if len(s) and not s.isna().all() and not _KIND_CHECK[col.kind](s):
            raise InputError(
                f"{stage} table: column {col.name!r} should be {col.kind}, got {s.dtype}"
            )
        if not col.nullable and s.isna().any():
            row = int(np.flatnonzero(s.isna().to_numpy())[0])
            raise InputError(f"{stage} table: column {col.name!r} has a missing value at row {row}")
        if col.kind == "float" and len(s) and not np.isfinite(s.dropna().to_numpy(float)).all():
            raise InputError(f"{stage} table: column {col.name!r} has a non-finite value")
    dup = df.duplicated(list(spec.key))
    if dup.any():
        row = int(np.flatnonzero(dup.to_numpy())[0])
        keys = {k: df[k].iloc[row] for k in spec.key}
        raise InputError(f"{stage} table: duplicate key {keys} at row {row}")
    return df
