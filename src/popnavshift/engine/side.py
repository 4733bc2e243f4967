"""A study's side folder: the study with more null replicates, its own files untouched.

``popnavshift calibrate STUDY --replicates N`` measures every verdict rule's false-positive
rate on more placebos than the study ran. The study itself keeps its design (its verdicts,
report and cards stay as they are); the extra replicates are run in ``STUDY/calibration``:

* the side folder starts as hard links to the study's files (no copy: a 200,000-run study
  links in well under a second and takes no space). Every writer of the package replaces a
  file by renaming a new one over it (:mod:`popnavshift.io`), so writing in the side folder
  never changes a byte of the study's;
* the study, as its manifest stored it, extended to N replicates of every null design
  (:meth:`popnavshift.design.study.Study.extended`), is run there: every run of the study
  is carried by the digest of its inputs (:mod:`.run_inputs`), only the new replicates'
  runs are simulated;
* ``base.json`` records the bytes digest of the study's runs table it was made from; when
  the study changes (re-run, extended) the side folder is made again from it.

Interrupted, it resumes like any run (the side folder is a study folder of its own).
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

from ..errors import ConfigError
from ..io import write_json
from ..read.folder import open_study, stored_study

#: the side folder's name inside the study folder
SIDE = "calibration"
#: what is never linked into it: outputs of the study that the side folder writes anew
#: or does not need (its report, cards, leaderboard, and itself)
SKIP = frozenset({SIDE, "report", "evaluate", "leaderboard"})
BASE = "base.json"
#: copied, not linked: the response cache (SQLite writes its file in place, so a linked
#: cache would change the study's own when a stage runs again in the side folder)
COPIED = "cache"


def null_sizes(study) -> dict[str, int]:
    """Per null kind, the replicates the study judges against (its smallest if two parts
    declare the same kind with different counts)."""
    out: dict[str, int] = {}
    for part in study.parts.values():
        nd = part.null_design
        if nd is not None:
            out[nd.kind] = min(out.get(nd.kind, nd.replicates), nd.replicates)
    return out


def _runs_digest(folder: Path) -> str:
    from ..hashing import content_digest

    return content_digest(folder / "runs.parquet")


def link_tree(src: Path, dst: Path) -> None:
    """``dst`` as hard links to ``src``'s files (but :data:`SKIP` at the top and lock or
    temporary files), copying where the file system cannot link."""
    def ignore(folder: str, names: list[str]) -> set[str]:
        top = Path(folder) == src
        return {n for n in names if (top and n in SKIP) or n.startswith(".")}

    def link(a: str, b: str) -> None:
        if Path(a).relative_to(src).parts[0] == COPIED:  # SQLite writes in place
            shutil.copy2(a, b)
            return
        try:
            os.link(a, b)
        except OSError:
            shutil.copy2(a, b)

    shutil.copytree(src, dst, ignore=ignore, copy_function=link)


def prepare_side(study_dir: Path, replicates: int):
    """The side folder of ``study_dir`` (made or made again from it) and the study to run
    there: the stored study with ``replicates`` replicates of every null design. Returns
    (side folder, extended study, the study's own null sizes by kind). ConfigError when
    the study stored no configuration, ran no null, or already has ``replicates`` or more."""
    folder = open_study(study_dir)
    study = stored_study(folder.manifest)
    if study is None:
        raise ConfigError(f"{study_dir}: its manifest stores no study configuration",
                          hint="run it again with `popnavshift run`")
    sizes = null_sizes(study)
    if not sizes:
        raise ConfigError(f"{study_dir} ran no null design: there is nothing to add "
                          "replicates to", hint="run a study with a null_design part, "
                          "as the paper study has")
    if replicates <= max(sizes.values()):
        raise ConfigError(f"--replicates {replicates}: {study_dir} already has "
                          f"{max(sizes.values())} replicates of its null", hint="give more "
                          f"than {max(sizes.values())} (e.g. {3 * max(sizes.values()) + 2})")
    side = Path(study_dir) / SIDE
    if (side.exists() and not side.is_dir()) or side.is_symlink():
        raise ConfigError(f"{side} is not the side folder `calibrate --replicates` makes "
                          "(a file or a link)", hint="move it away and run it again")
    base = {"runs_digest": _runs_digest(Path(study_dir)), "config_hash": study.config_hash()}
    if side.is_dir() and _read_base(side) != base:
        shutil.rmtree(side)  # made from another state of the study: start again from it
    if not side.is_dir():
        tmp = side.with_name(f".{SIDE}.tmp")
        shutil.rmtree(tmp, ignore_errors=True)
        link_tree(Path(study_dir), tmp)
        write_json(base, tmp / BASE)
        os.replace(tmp, side)
    return side, study.extended(replicates=replicates), sizes


def _read_base(side: Path) -> dict | None:
    import json

    try:
        return json.loads((side / BASE).read_text("utf-8"))
    except (OSError, ValueError):
        return None
