"""One call to a study's data from Python: ``popnavshift.load`` (the runs or pedestrians
of one study part), ``popnavshift.results`` (every table of its report: the headline,
power, calibration…) and ``popnavshift.cards`` (every card's tables).

A run that several parts plan is simulated and stored once, under the first part
that plans it (the ``part`` column), so ``runs[runs.part == "matched"]`` misses the
matched runs that ``main`` also holds. :func:`load` selects by the part's plan
instead, rebuilt from the study configuration in ``manifest.json`` and the
folder's ``episodes.parquet``.

This is also where a study's multi-file outputs are read back and checked against
their manifests (:mod:`popnavshift.outputs`): a report against ``report/stamp.json``
(:func:`report_intact`), a card against its ``card.json`` (:func:`card_intact`).
Whatever is damaged, half-made or changed since it was written is an
:class:`InputError` naming the file, never a parser's traceback nor a silent mix; a
card or an evaluation made for another configuration of the study is left out with a
warning.
"""

from __future__ import annotations

import os
import warnings
from pathlib import Path
from typing import Any

import pandas as pd

from ..design.plan import plan_study
from ..errors import ConfigError, InputError, UnknownNameError
from ..io import read_csv, read_json_object
from ..outputs import read_output_manifest, verify
from ..result_tables import RESULT_TABLES, TABLES_DIR, csv_path
from .folder import open_study

TABLES = ("runs", "pedestrians")
REPORT_DIR = "report"
STAMP = "stamp.json"  # the report's manifest: its inputs' stamp and every file's sha256
EVALUATE_DIR = "evaluate"
CARD = "card.json"  # a card's manifest: its identity, its verdict and every file's sha256
EVALUATION = "evaluation.json"  # an evaluation's record, beside its runs and pedestrians


def load(study: str | Path, part: str | None = "main", table: str = "runs", *,
         evaluated: bool = True) -> pd.DataFrame:
    """The ``table`` rows (runs or pedestrians) of study part ``part`` (None: every row).

    Every run the part plans, shared or not, with ``part`` set to ``part``; rows in
    the stored order. With ``evaluated``, the runs of every controller evaluated against
    the study (``popnavshift evaluate``, kept in ``STUDY/evaluate/<controller>/``) follow,
    on the episodes they share with the part; an evaluation made for another
    configuration of the study is left out with a warning. Raises :class:`InputError`
    when the folder lacks the table or the manifest or one is damaged,
    :class:`UnknownNameError` for a part the study does not have.
    """
    folder = _folder(study)
    if not isinstance(table, str) or table not in TABLES:
        raise ConfigError(f"table must be one of {', '.join(TABLES)}; got {table!r}")
    if part is not None and not isinstance(part, str):
        raise ConfigError(f"part must be the name of a study part, or None; got {part!r}")
    path = folder / f"{table}.parquet"
    if not path.is_file():
        raise InputError(f"{path}: not found", hint="run the study first (popnavshift run)")
    rows = _parquet(path)
    extra = [_parquet(p) for p in _evaluations(folder, table)] if evaluated else []
    key = ["run_id", "slot"] if table == "pedestrians" else ["run_id"]
    if part is None:
        return _with(rows, extra, key)
    ids = part_run_ids(folder, part)
    mine = rows[rows["run_id"].isin(ids)]
    episodes = set(mine["episode"])
    return _with(mine, [e[e["episode"].isin(episodes)] for e in extra], key).assign(part=part)


def _folder(study: object) -> Path:
    """A study folder given as a path (str or path-like): checked where it enters."""
    if not isinstance(study, str | os.PathLike) or str(study) == "":
        raise ConfigError(f"study must be the path of a study folder; got {study!r}")
    return Path(study)


def _parquet(path: Path, columns: list[str] | None = None) -> pd.DataFrame:
    try:
        return pd.read_parquet(path, columns=columns)
    except (OSError, ValueError) as exc:  # pyarrow's ArrowInvalid is a ValueError
        if isinstance(exc, OSError) and exc.errno is not None:
            raise  # the machine said no (permissions…): the CLI names it
        raise InputError(f"{path} is damaged (not a readable Parquet file)",
                         hint="`popnavshift run` on the study folder makes it again") from None


def _evaluations(folder: Path, table: str) -> list[Path]:
    """The ``table`` files of the evaluations made for this configuration of the study."""
    mine = config_hash(folder)
    found = []
    for path in sorted((folder / EVALUATE_DIR).glob(f"*/{table}.parquet")):
        record = path.parent / EVALUATION
        try:
            theirs = read_json_object(record).get("config_hash") if record.is_file() else None
        except InputError:
            theirs = None
        if theirs is None or (mine is not None and theirs != mine):
            why = ("it has no readable evaluation.json (the evaluation was not finished)"
                   if theirs is None else "it was made for another configuration of the study")
            warnings.warn(f"{path.parent}: left out: {why}", stacklevel=3)
            continue
        found.append(path)
    return found


def _with(rows: pd.DataFrame, extra: list[pd.DataFrame], key: list[str]) -> pd.DataFrame:
    """``rows`` and then the evaluated controllers' rows it does not hold already (a
    baseline evaluated as a controller keeps copies of the study's own runs)."""
    if not extra:
        return rows
    return pd.concat([rows, *extra], ignore_index=True).drop_duplicates(key, ignore_index=True)


def config_hash(folder: Path) -> str | None:
    """The configuration hash of the study ``folder`` holds (its ``study.json``, written by
    every run); None when it names none."""
    mark = Path(folder) / "study.json"
    try:
        value = read_json_object(mark).get("config_hash") if mark.is_file() else None
    except InputError:
        return None
    return value if isinstance(value, str) else None


def part_run_ids(folder: Path, part: str) -> set[str]:
    """``run_id`` of every run that study part ``part`` plans (the study as the folder
    stored it, parsed once by :func:`.folder.open_study`)."""
    manifest, episodes = folder / "manifest.json", folder / "episodes.parquet"
    for needed in (manifest, episodes):
        if not needed.is_file():
            raise InputError(f"{needed}: not found", hint="run the study first (popnavshift run)")
    spec = open_study(folder).study
    if spec is None:
        raise InputError(f"{manifest}: no study_config to find the parts in")
    if part not in spec.parts:
        raise UnknownNameError("study part", part, spec.parts)
    only = spec.model_copy(update={"parts": {part: spec.parts[part]}})
    try:
        grid = _parquet(episodes).itertuples(index=False)
        return {run.id for run in plan_study(only, grid)}
    except (AttributeError, KeyError, TypeError) as exc:  # a table of another shape
        raise InputError(f"{episodes} is damaged (not an episodes table: {exc})",
                         hint="`popnavshift run` on the study folder makes it again") from None


def report_intact(folder: str | Path) -> str:
    """Why the files of the study ``folder``'s report are not those its build wrote
    ("" when they are): missing, changed or added since, or an unfinished build (no
    stamp). Whether the report is current is :func:`popnavshift.report.build.report_is_current`."""
    out = Path(folder) / REPORT_DIR
    stamp, why = read_output_manifest(out / STAMP)
    return why or verify(out, stamp, only=True, ignore=(STAMP,))


def results(study: str | Path) -> dict[str, pd.DataFrame]:
    """Every table of the study's report as a DataFrame, by name (``evidence_headline``,
    ``evidence_power``, ``evidence_calibration``, ``reversals``, …), in the order of the
    report's sections: each table of :data:`popnavshift.result_tables.RESULT_TABLES` the
    report wrote (``docs/data.md`` says what each holds). Raises :class:`InputError` when
    the study has no report, or one that is not as its build wrote it
    (:func:`report_intact`)."""
    report = _folder(study) / REPORT_DIR
    hint = f"write the report: popnavshift report {study}"
    if not (report / TABLES_DIR).is_dir():
        raise InputError(f"{report / TABLES_DIR}: not found", hint=hint)
    why = report_intact(study)
    if why:
        raise InputError(f"{Path(study) / REPORT_DIR} cannot be read: {why}", hint=hint)
    paths = {t.name: report / csv_path(t.name) for t in RESULT_TABLES}
    return {name: read_csv(path) for name, path in paths.items() if path.is_file()}


def _verdict_ok(part: object, field: str) -> bool:
    """Whether one of a card's two verdicts reads back: a label, a text and ``field``."""
    return (isinstance(part, dict) and isinstance(part.get("label"), str)
            and isinstance(part.get("text"), str) and field in part)


def card_intact(card: Path) -> tuple[dict[str, Any], str]:
    """A card folder's ``card.json`` and "", or what it holds and why the card cannot be
    used: no card, a damaged ``card.json``, a file missing or changed since."""
    doc, why = read_output_manifest(Path(card) / CARD)
    if why:
        return doc, why
    verdict, tables = doc.get("verdict"), doc.get("tables")
    if not (isinstance(verdict, dict) and _verdict_ok(verdict.get("robustness"), "decide")
            and _verdict_ok(verdict.get("safety"), "findings")
            and isinstance(tables, list) and all(t in doc["files"] for t in tables)):
        return doc, f"{Path(card) / CARD} is damaged (no verdict or tables)"
    return doc, verify(card, doc)


def cards(study: str | Path) -> dict[str, dict[str, object]]:
    """Every robustness card of the study (``popnavshift evaluate``): folder name → its
    verdict (``card.json``) and tables (its CSVs) as DataFrames, under ``"verdict"`` and
    each table's name. Raises :class:`InputError` when the study folder does not exist or
    a card is damaged or unfinished (a page or figure without its ``card.json``); a card
    made for another configuration of the study is left out with a warning."""
    root = _folder(study)
    if not root.is_dir():
        raise InputError(f"{root}: no such study folder",
                         hint="give the --study-dir of `popnavshift evaluate`")
    mine = config_hash(root)
    out: dict[str, dict[str, object]] = {}
    folders = {p.parent for name in (CARD, "card.html", "card.png")
               for p in (root / EVALUATE_DIR).glob(f"*/{name}")}
    for path in sorted(folder / CARD for folder in folders):  # a card, or an unfinished one
        doc, why = card_intact(path.parent)
        if why:
            who = doc.get("controller")
            raise InputError(f"card {path.parent}: {why}", hint=(
                f"make it again: popnavshift evaluate '{who}' -d {root}" if isinstance(who, str)
                else f"delete {path.parent}, or evaluate its controller again"))
        if mine is not None and doc.get("config_hash") != mine:
            warnings.warn(f"card {path.parent}: left out: it was made for another "
                          "configuration of the study (evaluate the controller again)",
                          stacklevel=2)
            continue
        entry: dict[str, object] = {"verdict": doc["verdict"]}
        entry.update({Path(t).stem: read_csv(path.parent / t) for t in doc["tables"]})
        out[path.parent.name] = entry
    return out
