"""Outputs of several files, written and read as one: a card, a comparison, a report.

A reader takes such an output as a whole, so it is written as a whole. Each file of a
:class:`FileSet` goes to a temporary name beside its target (``.<name>.<random>.tmp``,
which :func:`popnavshift.engine.ownership.clean_leftovers` removes after a killed
writer); :meth:`FileSet.commit` removes the old manifest, renames the files into place
and writes the new manifest last, with each file's sha256. The manifest is the commit
marker, sealed by the digest of its own content: :func:`verify` names the file that is
missing or changed since (:func:`read_output_manifest` the manifest itself), and a reader
rebuilds the output (or refuses it) instead of taking it half-made. A folder that is
one output as a whole (the report) is built in a temporary folder, hashed
(:func:`folder_files`) and swapped in (:func:`replace_folder`).
"""

from __future__ import annotations

import hashlib
import os
import secrets
import shutil
import tempfile
from collections.abc import Callable
from pathlib import Path, PurePosixPath
from typing import Any

from .errors import ConfigError, InputError
from .hashing import digest
from .io import UMASK, read_json_object, write_json


def sha256_file(path: Path) -> str:
    """Hex sha256 of the bytes of ``path``."""
    h = hashlib.sha256()
    with open(path, "rb") as stream:
        for block in iter(lambda: stream.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


class FileSet:
    """The files of one output in ``folder``, staged then committed under ``manifest``
    (a JSON file in ``folder``). Use as a context manager: what was staged and not
    committed is removed on the way out, whatever happened."""

    def __init__(self, folder: Path, manifest: str) -> None:
        self.folder = Path(folder)
        self.manifest = manifest
        self._staged: dict[str, Path] = {}

    def __enter__(self) -> FileSet:
        return self

    def __exit__(self, *exc: object) -> None:
        self.discard()

    def add(self, name: str, writer: Callable[[Path], Any]) -> Path:
        """Stage ``folder/name``: ``writer(tmp)`` writes it to a temporary path beside
        it; returns the final path (written at :meth:`commit`)."""
        target = self.folder / name
        target.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp", dir=target.parent)
        os.close(fd)
        self._staged[name] = Path(tmp)
        writer(Path(tmp))
        return target

    def add_text(self, name: str, text: str) -> Path:
        """Stage ``folder/name`` holding ``text`` (UTF-8)."""
        return self.add(name, lambda tmp: tmp.write_text(text, "utf-8"))

    def commit(self, record: dict[str, Any]) -> dict[str, Any]:
        """Rename every staged file into place and write the manifest, ``record`` with
        ``files`` (name → sha256); returns what the manifest holds."""
        files = {name: sha256_file(tmp) for name, tmp in self._staged.items()}
        (self.folder / self.manifest).unlink(missing_ok=True)  # from here: not a whole set
        for name, tmp in self._staged.items():
            os.chmod(tmp, 0o666 & ~UMASK)
            os.replace(tmp, self.folder / name)
        self._staged.clear()
        return write_output_manifest(self.folder / self.manifest, {**record, "files": files})

    def discard(self) -> None:
        """Remove the staged files (nothing under a final name was touched)."""
        for tmp in self._staged.values():
            tmp.unlink(missing_ok=True)
        self._staged.clear()


def read_output_manifest(path: Path) -> tuple[dict[str, Any], str]:
    """The manifest at ``path`` and "", or what it holds and why it cannot be used:
    missing (the output was never finished), damaged, listing no files, or edited since
    it was written (its ``digest``)."""
    path = Path(path)
    if not path.is_file():
        return {}, f"{path} is missing (it was not finished)"
    try:
        doc = read_json_object(path)
    except InputError as err:
        return {}, err.message
    if not isinstance(doc.get("files"), dict):
        return {}, f"{path} is damaged or of an older version (it lists no files)"
    if doc.get("digest") != digest({k: v for k, v in doc.items() if k != "digest"}):
        return doc, f"{path} changed since it was written"
    return doc, ""


def write_output_manifest(path: Path, doc: dict[str, Any]) -> dict[str, Any]:
    """Write the manifest ``doc`` (with its ``files``) to ``path`` atomically, sealed by the
    digest of its own content (``digest``): an edit of the manifest itself is a change
    :func:`read_output_manifest` names. Returns what was written."""
    doc = {k: v for k, v in doc.items() if k != "digest"}
    doc["digest"] = digest(doc)
    write_json(doc, path)
    return doc


def safe_name(name: object) -> bool:
    """Whether ``name`` is a relative path that stays inside its folder."""
    if not isinstance(name, str) or not name or "\\" in name or "\0" in name:
        return False
    parts = PurePosixPath(name).parts
    return not PurePosixPath(name).is_absolute() and ".." not in parts and "." not in parts


def verify(folder: Path, manifest: dict[str, Any], *, only: bool = False,
           ignore: tuple[str, ...] = ()) -> str:
    """Why the files ``manifest["files"]`` lists under ``folder`` are not as they were
    written: the first one missing or changed ("" when all are intact). With ``only``,
    a file in ``folder`` the manifest does not list (except ``ignore`` and hidden ones)
    is a reason too."""
    folder = Path(folder)
    files = manifest.get("files")
    if not isinstance(files, dict) or not all(safe_name(n) and isinstance(h, str)
                                              for n, h in files.items()):
        return "its manifest lists no files (an older version or a damaged file)"
    for name, sha in files.items():
        path = folder / name
        if not path.is_file():
            return f"{path} is missing"
        if sha256_file(path) != sha:
            return f"{path} changed since it was written"
    if only:
        for name in folder_files(folder):
            if name not in files and name not in ignore:
                return f"{folder / name} was added since it was written"
    return ""


def folder_files(folder: Path) -> list[str]:
    """Every file under ``folder`` (relative POSIX names, sorted), hidden ones left out."""
    folder = Path(folder)
    return sorted(p.relative_to(folder).as_posix() for p in folder.rglob("*")
                  if p.is_file() and not any(part.startswith(".") for part in
                                             p.relative_to(folder).parts))


def folder_hashes(folder: Path) -> dict[str, str]:
    """name → sha256 of :func:`folder_files`."""
    return {name: sha256_file(Path(folder) / name) for name in folder_files(folder)}


def staging_folder(target: Path) -> Path:
    """A new empty folder beside ``target`` to build it in (``.<name>.<random>.tmp``, a
    leftover of a killed writer is removed as one), with the usual permissions."""
    target = Path(target)
    target.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{target.name}.", suffix=".tmp", dir=target.parent))
    os.chmod(tmp, 0o777 & ~UMASK)
    return tmp


def check_writable(folder: Path, what: str) -> None:
    """ConfigError unless ``folder`` can be written in, or created: its nearest existing
    ancestor is a folder where a file can be made (tried, and removed). Nothing is
    created: a check before any work leaves no trace."""
    folder = Path(folder)
    existing = next(p for p in (folder, *folder.absolute().parents) if p.exists())
    if not existing.is_dir():
        raise ConfigError(f"{what}: {existing} is a file, not a folder",
                          hint="choose another path")
    try:
        fd, probe = tempfile.mkstemp(prefix=".popnavshift-write-test-", dir=existing)
        os.close(fd)
        os.unlink(probe)
    except OSError as exc:
        raise ConfigError(f"{what}: {existing} is not writable ({exc.strerror or exc})",
                          hint="choose another place or fix its permissions") from None


def replace_folder(new: Path, target: Path) -> None:
    """Put the folder ``new`` in place of ``target`` (which may not exist): two renames,
    so ``target`` is at every moment the old folder, absent, or the new one — never a
    mix of both."""
    target = Path(target)
    old = None
    if target.exists():
        old = target.with_name(f".{target.name}.{secrets.token_hex(6)}.old.tmp")
        os.replace(target, old)
    os.replace(new, target)
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)


def remove_staging(folder: Path, name: str) -> int:
    """Remove what killed builders of ``folder/name`` left beside it; how many."""
    found = [p for p in Path(folder).glob(f".{name}.*.tmp") if p.is_dir()]
    for path in found:
        shutil.rmtree(path, ignore_errors=True)
    return len(found)
