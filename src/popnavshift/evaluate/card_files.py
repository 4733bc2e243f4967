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
from collections.abc import Sequence
from functools import cache
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..controller_ids import POLICY, controller_id, parse_controller_id, policy_file
from ..errors import ConfigError
from ..hashing import digest, sources_digest
from ..outputs import check_writable
from ..read.access import CARD, EVALUATE_DIR, EVALUATION, card_intact
from ..version import __version__

if TYPE_CHECKING:
    from ..design.study import Study


def slug(identity: str) -> str:
    """A folder name for a controller id: letters, digits, ``_``, ``.`` and ``-`` only, never
    starting with a dot (so never ``.`` or ``..``); a short hash keeps distinct ids apart. A
    policy's id (its file's absolute path and hash) is named by the file's name and hash."""
    policy = policy_file(identity)
    text = identity if policy is None else f"{POLICY}-{Path(policy[0]).name}-{policy[1]}"
    s = re.sub(r"[^A-Za-z0-9_.-]+", "-", text).strip("-.")[:60].strip("-.") or "controller"
    return s if s == identity else f"{s}-{digest(identity)[:8]}"


def folder_name(folder: Path) -> str:
    """How a card, its evaluation.json and a comparison name the study folder: its name,
    never a machine path (records stay portable, docs/llm.md)."""
    return Path(folder).resolve().name


def card_folder(base_folder: Path, identity: str) -> Path:
    """``base_folder/evaluate/<slug>``: the default folder of ``identity``'s card."""
    return Path(base_folder) / EVALUATE_DIR / slug(identity)


def check_out(out: Path, base_folder: Path) -> None:
    """ConfigError unless ``out`` can hold a card beside the study in ``base_folder``:
    not the study folder nor a folder holding it (the card's ``runs.parquet`` would
    replace the study's), inside the study folder only in its ``evaluate/``, not a file,
    writable, and, outside the study folder, empty or a card folder already."""
    target, base = Path(out).resolve(), Path(base_folder).resolve()
    hint = "choose another --out, or leave it out for STUDY_DIR/evaluate/<controller>"
    if target == base or target in base.parents:
        raise ConfigError(f"--out {out} is the baseline study's folder {base_folder} or holds "
                          "it: the card's runs.parquet would replace the study's", hint=hint)
    if target.exists() and not target.is_dir():
        raise ConfigError(f"--out {out} exists and is not a folder", hint=hint)
    inside = (base / EVALUATE_DIR) in target.parents
    if base in target.parents and not inside:
        raise ConfigError(f"--out {out} is inside the study folder {base_folder} but not in "
                          f"its {EVALUATE_DIR}/ folder, where cards go", hint=hint)
    if target.is_dir() and not inside and not (target / EVALUATION).exists() and any(
            not p.name.startswith(".") for p in target.iterdir()):
        raise ConfigError(f"--out {out} is not empty and holds no card: its files could be "
                          "replaced", hint=hint)
    check_writable(target, f"--out {out}")


def check_card_settings(n_boot: object, seed: object, safety_threshold: object) -> None:
    """ConfigError unless the card's settings are what the command line accepts: from
    Python too, a bad value is refused before any work."""
    def integer(v: object) -> bool:
        return isinstance(v, int) and not isinstance(v, bool)

    if not integer(n_boot) or not 1 <= n_boot <= 100_000:  # type: ignore[operator]
        raise ConfigError(f"n_boot must be an integer from 1 to 100000; got {n_boot!r}")
    if not integer(seed) or seed < 0:  # type: ignore[operator]
        raise ConfigError(f"seed must be a non-negative integer; got {seed!r}")
    if safety_threshold is not None and not (
            isinstance(safety_threshold, int | float) and not isinstance(safety_threshold, bool)
            and 0 <= safety_threshold <= 1):
        raise ConfigError(f"safety_threshold must be a share from 0 to 1 or None; got "
                          f"{safety_threshold!r}")


#: evaluation modules that put cards side by side and make none: a change to them never
#: makes a card stale
NOT_CARD_CODE = frozenset({"evaluate/compare.py", "evaluate/compare_page.py",
                           "evaluate/leaderboard.py"})


@cache
def card_code() -> str:
    """Stamp of the code that computes a card: the analysis and the evaluation (but the
    comparison pages, :data:`NOT_CARD_CODE`)."""
    return digest([__version__, sources_digest("analysis", "evaluate", exclude=NOT_CARD_CODE)])


def runs_digest(*folders: Path) -> str:
    """Hex sha256 of the runs a card can read: the bytes of the study folder's
    ``runs.parquet`` and the card's own. A run's row holds ``run_inputs``, the digest of its
    own inputs and code (:mod:`popnavshift.engine.run_inputs`), and its outcome, so equal
    files mean equal runs and pedestrians; a table written again with the same rows is
    written byte for byte the same. Hashing the file, not its parsed columns, recognises a
    current card in a few milliseconds (a change of bytes alone would only make the card
    again)."""
    h = hashlib.sha256()
    for folder in folders:
        path = Path(folder) / "runs.parquet"
        if not path.is_file():
            h.update(b"-\0")
            continue
        with path.open("rb") as f:
            h.update(hashlib.file_digest(f, "sha256").digest())
    return h.hexdigest()


def run_code(controller: str, baselines: Sequence[str]) -> str:
    """Stamp of the code the card's runs execute now: the simulator and each compared
    controller's own module (:func:`popnavshift.engine.stamps.code_stamps`). With the
    study's configuration and the stored runs unchanged, an equal stamp means ``evaluate``
    would simulate nothing: a card can be reused without planning its runs."""
    from ..engine.stamps import code_stamps  # loads navground: only when a card is judged

    return digest(code_stamps((controller, *baselines, "none")))


def card_identity(controller: str, baselines: Sequence[str], config_hash: str,
                  runs: str, *, n_boot: int, seed: int,
                  safety_threshold: float | None) -> dict[str, Any]:
    """Everything the verdict of ``controller``'s card depends on (module doc), as
    ``card.json`` records it; ``runs``: the :func:`runs_digest` of what it reads."""
    return {"controller": controller, "baselines": list(baselines),
            "config_hash": config_hash, "n_boot": n_boot, "seed": seed,
            "safety_threshold": safety_threshold, "runs": runs,
            "run_code": run_code(controller, baselines), "code": card_code()}


#: how each part of a card's identity is named when it changed
_CHANGED = {
    "controller": "it is another controller's card",
    "baselines": "it was made against {old} (now {new})",
    "config_hash": "it was made for another configuration of the study",
    "n_boot": "it was made with --n-boot {old} (now {new})",
    "seed": "it was made with --seed {old} (now {new})",
    "safety_threshold": "it was made with --safety-threshold {old} (now {new})",
    "runs": "its runs or pedestrians changed since it was made",
    "run_code": "the simulator's or a compared controller's code changed since it was made",
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


def current_card(controller: str, study: Study, base_folder: Path, out: Path | None = None, *,
                 baselines: Sequence[str], n_boot: int = 1000, seed: int = 0,
                 safety_threshold: float | None = None) -> tuple[Path, str]:
    """The folder of ``controller``'s card and why the card there cannot stand for the one
    :func:`.run.make_card` would make now ("" when it can: :func:`card_is_current`).
    Reads two columns of the runs tables and the card's manifest, nothing else: a current
    card is recognised in a moment, without planning or loading a run."""
    identity = controller_id(*parse_controller_id(controller))
    base_ids = tuple(b for b in dict.fromkeys(baselines) if b != identity)
    out = Path(out) if out is not None else card_folder(base_folder, identity)
    if not (out / CARD).is_file():
        return out, "no card yet"
    from .safety import SAFETY_THRESHOLD

    threshold = SAFETY_THRESHOLD if safety_threshold is None else safety_threshold
    check_card_settings(n_boot, seed, threshold)
    wanted = card_identity(identity, base_ids, study.config_hash(),
                           runs_digest(base_folder, out), n_boot=n_boot, seed=seed,
                           safety_threshold=threshold)
    return out, card_is_current(out, wanted)
