"""A study folder's own files, read and checked: the stage stamps (``stages.json``), the
manifest, and whether its tables read back. The engine writes them; the read side, the
report and ``run`` check them with these functions, which need no simulator."""

from __future__ import annotations

import json
from pathlib import Path

import pyarrow.parquet as pq

from ..errors import InputError

#: the ``stages.json`` entry that says the compacted run tables are whole
RUNS_RECORD = "runs"
#: its value when the runs carry the digest of their own inputs (``run_inputs``)
RUNS_IDENTITY = 1


def read_stamps(folder: Path) -> dict:
    """The stage stamps of ``folder/stages.json`` ({} if absent); InputError if damaged."""
    path = Path(folder) / "stages.json"
    if not path.exists():
        return {}
    try:
        stamps = json.loads(path.read_text("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError):
        stamps = None
    if not isinstance(stamps, dict) or not all(_stamp_ok(k, v) for k, v in stamps.items()):
        raise InputError(
            f"{path} is damaged (not a JSON object of stage stamps)",
            hint="delete it: every stage is then checked and redone as needed",
        )
    return stamps


def _stamp_ok(key: str, value: object) -> bool:
    """A stage's stamp is a string; the run record (:attr:`RUNS_RECORD`) says the
    compacted tables are whole (``{"run_inputs": 1}``), or, in a folder compacted before
    runs carried their own digests, holds the inputs stamp and each controller's code
    stamp (:meth:`popnavshift.engine.store.RunStore.legacy_inputs`)."""
    if key != RUNS_RECORD:
        return isinstance(value, str)
    if isinstance(value, dict) and value.get("run_inputs") == RUNS_IDENTITY:
        return True
    return (isinstance(value, dict) and isinstance(value.get("inputs"), str)
            and isinstance(value.get("code", {}), dict))


def read_manifest(folder: Path) -> dict | None:
    """``folder/manifest.json`` (None when absent); InputError saying how to recover
    when it is damaged."""
    path = Path(folder) / "manifest.json"
    if not path.exists():
        return None
    try:
        manifest = json.loads(path.read_text("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError):
        manifest = None
    if not isinstance(manifest, dict):
        raise InputError(f"{path} is damaged (not a JSON object)",
                         hint="run the study again on this folder: `popnavshift run "
                              "STUDY --out FOLDER` rewrites it without simulating again")
    return manifest


def readable_parquet(path: Path) -> bool:
    """Whether ``path`` is a Parquet file with an intact footer (a truncated or
    overwritten file has none). Pages are not decoded: the tables can be large."""
    try:
        pq.read_metadata(path)
        return True
    except Exception:
        return False


def check_study_folder(folder: Path) -> None:
    """InputError naming the first damaged table or JSON file of a study folder (the
    report reads them all); absent files are left for the reader to report."""
    folder = Path(folder)
    for name in ("runs", "pedestrians", "populations", "episodes"):
        path = folder / f"{name}.parquet"
        if path.exists() and not readable_parquet(path):
            raise InputError(
                f"{path} is damaged (not a readable Parquet file)",
                hint="`popnavshift run` on this folder rebuilds the run tables from their "
                "shards" if name in ("runs", "pedestrians") else "run its stage again",
            )
    read_manifest(folder)
    for name in ("personas", "responses"):
        path = folder / f"{name}.json"
        try:
            if path.exists():
                json.loads(path.read_text("utf-8"))
        except (UnicodeDecodeError, json.JSONDecodeError):
            raise InputError(f"{path} is damaged (not valid JSON)",
                             hint="run the study again to rewrite it") from None
    read_stamps(folder)
