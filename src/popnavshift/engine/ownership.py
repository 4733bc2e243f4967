"""Whose folder is this? A study folder names its study, and a run refuses another's.

``popnavshift run other --out study-quick`` would compact study ``other``'s plan over
``quick``'s tables (``runs.parquet`` went from 160 rows to 4, exit 0), and ``--out ~``
would fill a home folder with shards. :func:`claim_folder` runs under the folder's lock
before any stage: a folder that names another study, or a non-empty folder with none of
our files, is refused unless forced; then the folder is marked with the study's name,
and the temporary files a killed writer left behind are removed.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

from ..design.study import Study
from ..errors import ConfigError
from ..io import write_json
from .lock import LOCK_NAME

#: the study a folder belongs to: written by the first run, before any stage
MARK = "study.json"
#: files only a PopNavShift command writes: a folder holding one is ours
OURS = (MARK, "manifest.json", "stages.json", "personas.parquet", "runs.parquet")


def folder_owner(folder: Path) -> str | None:
    """The study name ``folder`` belongs to ("" when it is ours but names no study, as the
    stage commands leave it; None when nothing in it is ours)."""
    for name in (MARK, "manifest.json"):
        path = folder / name
        try:
            owner = json.loads(path.read_text("utf-8")).get("study")
        except (OSError, ValueError, AttributeError):
            continue  # absent or damaged: the next marker decides
        if isinstance(owner, str):
            return owner
    return "" if any((folder / name).exists() for name in OURS) else None


def claim_folder(folder: Path, study: Study, force: bool | None = False,
                 option: str = "--out") -> None:
    """Refuse ``folder`` (given as ``option``) when it belongs to another study or to
    nothing of ours (unless ``force``; None: the command has no --force), then mark it
    as ``study``'s and clean its leftover temporary files. Call it holding the lock."""
    owner = folder_owner(folder)
    hint = f"choose another {option}" + (
        "" if force is None else ", or add --force to write into it anyway")
    if not force and owner not in (None, "", study.name):
        raise ConfigError(f"{option} {folder} holds the results of study {owner!r}, not "
                          f"{study.name!r}; running here would replace its tables", hint=hint)
    if not force and owner is None and _has_files(folder):
        raise ConfigError(f"{option} {folder} is not empty and holds no PopNavShift study",
                          hint=hint)
    write_json({"study": study.name, "config_hash": study.config_hash()}, folder / MARK)
    clean_leftovers(folder)


def _has_files(folder: Path) -> bool:
    return any(p.name != LOCK_NAME and not p.name.startswith(".popnavshift-write-test")
               for p in folder.iterdir())


def clean_leftovers(folder: Path) -> int:
    """Remove the temporary files and folders (``.<name>.<random>.tmp``, see
    :mod:`popnavshift.io` and :mod:`popnavshift.outputs`) that a writer killed mid-write
    left anywhere in ``folder``; return how many. Only under the folder's lock: a live
    writer's temporary file is never touched."""
    removed = 0
    for path in sorted(folder.rglob(".*.tmp")):
        if path.is_dir():
            shutil.rmtree(path, ignore_errors=True)
        elif path.is_file():
            path.unlink(missing_ok=True)
        else:
            continue  # inside a folder removed above
        removed += 1
    return removed
