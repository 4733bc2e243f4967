"""One call to a study's data from Python: ``popnavshift.load`` (the runs or pedestrians
of one study part), ``popnavshift.results`` (every table of its report: the headline,
power, calibration…) and ``popnavshift.cards`` (every card's tables).

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

from ..design.plan import plan_study
from ..errors import ConfigError, InputError, UnknownNameError
from .folder import open_study

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
    """``run_id`` of every run that study part ``part`` plans (the study as the folder
    stored it, :func:`.folder.open_study`)."""
    opened = open_study(folder)
    manifest, episodes = folder / "manifest.json", opened.episodes
    if not manifest.is_file():
        raise InputError(f"{manifest}: not found", hint="run the study first (popnavshift run)")
    if episodes is None:
        raise InputError(f"{folder / 'episodes.parquet'}: not found",
                         hint="run the study first (popnavshift run)")
    spec = opened.study
    if spec is None:
        raise InputError(f"{manifest}: no study_config to find the parts in")
    if part not in spec.parts:
        raise UnknownNameError("study part", part, spec.parts)
    only = spec.model_copy(update={"parts": {part: spec.parts[part]}})
    return {run.id for run in plan_study(only, episodes.itertuples(index=False))}


def results(study: str | Path) -> dict[str, pd.DataFrame]:
    """Every table of the study's report as a DataFrame, by name (``evidence_headline``,
    ``evidence_power``, ``evidence_calibration``, ``reversals``, …: the CSVs of
    ``STUDY/report/tables``). Raises :class:`InputError` when the study has no report."""
    folder = Path(study) / "report" / "tables"
    if not folder.is_dir():
        raise InputError(f"{folder}: not found", hint=f"write the report: popnavshift report "
                         f"{study}")
    return {p.stem: pd.read_csv(p) for p in sorted(folder.glob("*.csv"))}


def cards(study: str | Path) -> dict[str, dict[str, object]]:
    """Every robustness card of the study (``popnavshift evaluate``): folder name → its
    verdict (``card.json``) and tables (its CSVs) as DataFrames, under ``"verdict"`` and
    each table's name."""
    out: dict[str, dict[str, object]] = {}
    for card in sorted((Path(study) / "evaluate").glob("*/card.json")):
        entry: dict[str, object] = {"verdict": json.loads(card.read_text("utf-8"))["verdict"]}
        entry.update({p.stem: pd.read_csv(p) for p in sorted(card.parent.glob("*.csv"))})
        out[card.parent.name] = entry
    return out
