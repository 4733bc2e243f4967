"""Where a card lives and when a stored one may be reused.

A card is the files of one evaluated controller in ``STUDY/evaluate/<slug>/``: its
tables as CSV, the outcomes as Markdown and LaTeX, ``card.png``, ``card.html`` and, last,
``card.json`` (:class:`popnavshift.outputs.FileSet`: the manifest with each file's
sha256). ``card.json`` also holds the card's **identity**, everything its verdict depends
on (:func:`card_identity`): the controller, its baselines, the study's configuration,
the bootstrap's resamples and seed, the safety threshold, the runs and pedestrians it
was computed on, and the code that computed it. :func:`card_is_current` reuses a card
only when every part of it is equal and every file is as written; otherwise it says
which changed, in words, and the card is made again.

Paths stay inside their folder: a controller id becomes a folder name by :func:`slug`
(never ``.``, ``..`` or a path), and an ``--out`` that is (or holds) the study folder, or
that holds anything but a card, is refused before anything runs (:func:`check_out`).
"""

from __future__ import annotations

import hashlib
import re
from functools import cache
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pandas as pd

from ..access import EVALUATE_DIR, EVALUATION, card_intact
from ..errors import ConfigError
from ..hashing import digest, sources_digest
from ..version import __version__

if TYPE_CHECKING:
    from .run import Evaluation


def slug(identity: str) -> str:
    """A folder name for a controller id: letters, digits, ``_``, ``.`` and ``-`` only, never
    starting with a dot (so never ``.`` or ``..``); a short hash keeps distinct ids apart."""
    s = re.sub(r"[^A-Za-z0-9_.-]+", "-", identity).strip("-.")[:60].strip("-.") or "controller"
    return s if s == identity else f"{s}-{digest(identity)[:8]}"


def card_folder(base_folder: Path, identity: str) -> Path:
    """``base_folder/evaluate/<slug>``: the default folder of ``identity``'s card."""
    return Path(base_folder) / EVALUATE_DIR / slug(identity)


def check_out(out: Path, base_folder: Path) -> None:
    """ConfigError unless ``out`` can hold a card beside the study in ``base_folder``:
    not the study folder nor a folder holding it (the card's ``runs.parquet`` would
    replace the study's), not a file, and, outside the study's ``evaluate/``, empty or a
    card folder already."""
    target, base = Path(out).resolve(), Path(base_folder).resolve()
    hint = "choose another --out, or leave it out for STUDY_DIR/evaluate/<controller>"
    if target == base or target in base.parents:
        raise ConfigError(f"--out {out} is the baseline study's folder {base_folder} or holds "
                          "it: the card's runs.parquet would replace the study's", hint=hint)
    if target.exists() and not target.is_dir():
        raise ConfigError(f"--out {out} exists and is not a folder", hint=hint)
    inside = (base / EVALUATE_DIR) in target.parents
    if target.is_dir() and not inside and not (target / EVALUATION).exists() and any(
            not p.name.startswith(".") for p in target.iterdir()):
        raise ConfigError(f"--out {out} is not empty and holds no card: its files could be "
                          "replaced", hint=hint)


@cache
def card_code() -> str:
    """Stamp of the code that computes a card: the analysis and the evaluation."""
    return digest([__version__, sources_digest("analysis", "evaluate")])


def tables_digest(*tables: pd.DataFrame) -> str:
    """Hex sha256 of the content of ``tables`` (every row and column, in order)."""
    h = hashlib.sha256()
    for table in tables:
        h.update(",".join(map(str, table.columns)).encode() + b"\0")
        h.update(pd.util.hash_pandas_object(table, index=False).to_numpy().tobytes())
    return h.hexdigest()


def card_identity(ev: Evaluation, *, n_boot: int, seed: int,
                  safety_threshold: float | None) -> dict[str, Any]:
    """Everything the verdict of ``ev``'s card depends on (module doc), as ``card.json``
    records it."""
    return {"controller": ev.controller, "baselines": list(ev.baselines),
            "config_hash": ev.study.config_hash(), "n_boot": n_boot, "seed": seed,
            "safety_threshold": safety_threshold,
            "runs": tables_digest(ev.runs, ev.pedestrians), "code": card_code()}


#: how each part of a card's identity is named when it changed
_CHANGED = {
    "controller": "it is another controller's card",
    "baselines": "it was made against {old} (now {new})",
    "config_hash": "it was made for another configuration of the study",
    "n_boot": "it was made with --n-boot {old} (now {new})",
    "seed": "it was made with --seed {old} (now {new})",
    "safety_threshold": "it was made with --safety-threshold {old} (now {new})",
    "runs": "its runs or pedestrians changed since it was made",
    "code": "the code that makes a card changed since it was made",
}


def card_is_current(folder: Path, identity: dict[str, Any]) -> str:
    """Why the card in ``folder`` cannot stand for a card of ``identity`` ("" when it
    can): no card, a damaged or unfinished one, a file changed since, or a part of its
    identity that differs (named, with both values)."""
    doc, why = card_intact(folder)
    if why:
        return why
    for key, value in identity.items():
        if doc.get(key) != value:
            return _CHANGED[key].format(old=_shown(doc.get(key)), new=_shown(value))
    return ""


def _shown(value: Any) -> str:
    if value is None:
        return "none"
    return ", ".join(map(str, value)) if isinstance(value, list) else str(value)

