"""Stage 1 entry point: persona records from any source, sampled, checked, with provenance.

``source`` is ``"synthetic"`` (the seeded generator), a flat table file (CSV, JSONL,
Parquet), a MatrAIx release folder or ``hf://owner/name`` (that release, fetched
with ``huggingface_hub`` and cached). For a release, ``codebook`` names a codebook
file for other layouts, ``sources`` restricts the sample to those record sources,
and ``verify_checksums`` checks shards against ``manifest.json``; minors are always
excluded (see ``matraix.py``). Missing-field policy (required fields only;
optional fields simply stay missing):

- ``require`` (default): records lacking a required field are skipped and counted
  (``records_dropped_missing``); the sample is drawn from the complete records.
- ``fill``: a missing required value takes the field's schema ``defaultValue``
  (counted in ``values_filled``); a field without a default raises, naming file,
  row and field.
- ``error``: the first record lacking a required field raises, naming file, row
  and field.

Sampling: when the source holds more usable records than ``n``, the n with the
smallest ``sample_key(seed, persona_id)`` are kept (independent of file, shard and
row order). When it holds fewer than ``n``, :class:`InputError` says so rather
than returning a smaller study population; ``n=None`` takes every usable record.
The synthetic source generates exactly ``n`` (600 when ``n`` is None).
"""

from __future__ import annotations

import difflib
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from ..errors import ConfigError, InputError
from ..tables import check_table
from .flat import apply_missing, check_missing_policy, read_flat_table, take_sample
from .matraix import read_release
from .release import fetch_release, is_hub_source
from .synthetic import generate_personas
from .table import PERSONAS

SYNTHETIC = "synthetic"
SYNTHETIC_DEFAULT_N = 600


def load_personas(
    source: str | Path,
    n: int | None = 600,
    seed: int = 0,
    missing: str = "require",
    codebook: str | Path | None = None,
    sources: Sequence[str] | None = None,
    verify_checksums: bool = True,
) -> tuple[pd.DataFrame, dict]:
    """Load ``n`` persona records from ``source``; returns (personas table, provenance).

    The table passes ``check_table(df, "personas")``, is sorted by ``persona_id`` and
    has a RangeIndex. Provenance keys: kind, path, n_requested, n_obtained, seed,
    missing, records_scanned, records_dropped_missing, values_filled, source_mix
    (records per source value in the table), plus reader details for a release.
    """
    if n is not None and (isinstance(n, bool) or not isinstance(n, int | np.integer) or n < 1):
        raise ConfigError(f"n must be a positive integer or None, got {n!r}")
    check_missing_policy(missing)
    if source == SYNTHETIC:
        _check_release_only(codebook, sources)
        table = generate_personas(SYNTHETIC_DEFAULT_N if n is None else n, seed)
        prov: dict[str, Any] = {"kind": SYNTHETIC, "path": None, "records_scanned": len(table)}
        prov |= {"records_dropped_missing": 0, "values_filled": 0}
    else:
        path = fetch_release(str(source)) if is_hub_source(str(source)) else _existing_path(
            str(source)
        )
        if path.is_dir():
            table, details = read_release(
                path,
                n,
                seed,
                missing,
                codebook=codebook,
                sources=sources,
                verify_checksums=verify_checksums,
            )
            prov = {"kind": "matraix", "path": str(path), **details}
            if is_hub_source(str(source)):
                prov["hub"] = str(source)
        else:
            _check_release_only(codebook, sources)
            table, prov = _load_flat(path, n, seed, missing)
        _check_enough(table, n, path, prov)
    check_ids(table["persona_id"], source)
    table = table.sort_values("persona_id", kind="stable").reset_index(drop=True)
    table = check_table(table[PERSONAS.names], "personas")
    prov |= {
        "n_requested": n,
        "n_obtained": len(table),
        "seed": seed,
        "missing": missing,
        "source_mix": {
            str(k): int(v) for k, v in table["source"].value_counts().sort_index().items()
        },
    }
    return table, prov


def _check_release_only(codebook: object, sources: object) -> None:
    if codebook is not None or sources is not None:
        raise ConfigError(
            "codebook and sources apply to a MatrAIx release only",
            hint="give a release folder or hf:// source, or drop --codebook/--only-source",
        )


def _load_flat(path: Path, n: int | None, seed: int, missing: str) -> tuple[pd.DataFrame, dict]:
    records = read_flat_table(path)
    usable, dropped, filled = apply_missing(records, missing, str(path))
    prov = {
        "kind": "flat",
        "path": str(path),
        "records_scanned": len(records),
        "records_dropped_missing": dropped,
        "values_filled": filled,
    }
    return take_sample(usable, n, seed), prov


def _check_enough(table: pd.DataFrame, n: int | None, path: Path, prov: dict) -> None:
    if (n is not None and len(table) < n) or len(table) == 0:
        raise InputError(
            f"{path}: {n or 'at least one'} persona record(s) requested but only {len(table)} "
            f"usable ({prov['records_scanned']} scanned, "
            f"{prov['records_dropped_missing']} dropped for missing required fields)",
            hint="lower --n (personas.n in a study file), or fill missing fields with "
                 "--missing fill (personas.missing: fill)",
        )


def _existing_path(source: str) -> Path:
    path = Path(source).expanduser()
    if path.exists():
        return path
    close = difflib.get_close_matches(source, [SYNTHETIC], n=1)
    raise ConfigError(
        f"persona source {source!r} is neither {SYNTHETIC!r} nor an existing file or folder",
        hint=f"did you mean {SYNTHETIC!r}?"
        if close
        else "give a CSV/JSONL/Parquet file, a MatrAIx release folder or hf://owner/name",
    )


def check_ids(ids: pd.Series, source: object) -> None:
    """InputError for the first persona id that is blank or holds a character that is not
    printable (NUL, ESC, a newline, a bidi override): an id is shown on the terminal,
    written to every table and typed back by the user (`show-prompt ID`)."""
    for pid in ids.astype(str):
        if not pid.strip() or not pid.isprintable():
            shown = pid.encode("unicode_escape").decode("ascii")
            raise InputError(f"{source}: persona id '{shown}' is "
                             f"{'blank' if not pid.strip() else 'not printable text'}",
                             hint="ids are printable text, e.g. p-000123")
