"""One call to the runs (or pedestrians) of one study part: ``popnavshift.load``.

A run that several parts plan is simulated and stored once, under the first part
that plans it (the ``part`` column), so ``runs[runs.part == "matched"]`` misses the
matched runs that ``main`` also holds. :func:`load` selects by the part's plan
instead, rebuilt from the study configuration in ``manifest.json`` and the
folder's ``episodes.parquet``.
"""

from __future__ import annotations

import json
from pathlib import Path

import pandas as pd

from .errors import ConfigError, InputError, UnknownNameError

TABLES = ("runs", "pedestrians")


def load(study: str | Path, part: str | None = "main", table: str = "runs", *,
         evaluated: bool = True) -> pd.DataFrame:
    """The ``table`` rows (runs or pedestrians) of study part ``part`` (None: every row).

    Every run the part plans, shared or not, with ``part`` set to ``part``; rows in
    the stored order. With ``evaluated``, the runs of every controller evaluated against
    the study (``popnavshift evaluate``, kept in ``STUDY/evaluate/<controller>/``) follow,
    on the episodes they share with the part. Raises :class:`InputError` when the folder
    lacks the table or the manifest, :class:`UnknownNameError` for a part the study does
    not have.
    """
    folder = Path(study)
    if table not in TABLES:
        raise ConfigError(f"table must be one of {', '.join(TABLES)}; got {table!r}")
    path = folder / f"{table}.parquet"
    if not path.is_file():
        raise InputError(f"{path}: not found", hint="run the study first (popnavshift run)")
    rows = pd.read_parquet(path)
    extra = ([pd.read_parquet(p) for p in sorted((folder / "evaluate").glob(f"*/{table}.parquet"))]
             if evaluated else [])
    key = ["run_id", "slot"] if table == "pedestrians" else ["run_id"]
    if part is None:
        return _with(rows, extra, key)
    ids = part_run_ids(folder, part)
    mine = rows[rows["run_id"].isin(ids)]
    episodes = set(mine["episode"])
    return _with(mine, [e[e["episode"].isin(episodes)] for e in extra], key).assign(part=part)


def _with(rows: pd.DataFrame, extra: list[pd.DataFrame], key: list[str]) -> pd.DataFrame:
    """``rows`` and then the evaluated controllers' rows it does not hold already (a
    baseline evaluated as a controller keeps copies of the study's own runs)."""
    if not extra:
        return rows
    return pd.concat([rows, *extra], ignore_index=True).drop_duplicates(key, ignore_index=True)


def part_run_ids(folder: Path, part: str) -> set[str]:
    """``run_id`` of every run that study part ``part`` plans."""
    # lazy: `import popnavshift` (which imports this module) must not load the engine
    # and navground; only a part selection needs them
    from .engine.plan import plan_study
    from .engine.study import study_from_dict

    manifest, episodes = folder / "manifest.json", folder / "episodes.parquet"
    for needed in (manifest, episodes):
        if not needed.is_file():
            raise InputError(f"{needed}: not found", hint="run the study first (popnavshift run)")
    config = json.loads(manifest.read_text("utf-8")).get("study_config")
    if not config:
        raise InputError(f"{manifest}: no study_config to find the parts in")
    spec = study_from_dict(config, f"{manifest} study_config")
    if part not in spec.parts:
        raise UnknownNameError("study part", part, spec.parts)
    only = spec.model_copy(update={"parts": {part: spec.parts[part]}})
    grid = pd.read_parquet(episodes).itertuples(index=False)
    return {run.id for run in plan_study(only, grid)}
