"""Stable hashes: canonical JSON digests and seed derivation.

Python's ``hash`` is salted per process, so every seed and cache key here comes
from sha256 over canonical JSON (sorted keys, no whitespace, floats by ``repr``).
"""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path
from typing import Any


def canonical_json(obj: Any) -> str:
    """Serialise ``obj`` deterministically (sorted keys, compact separators)."""
    return json.dumps(obj, sort_keys=True, separators=(",", ":"), ensure_ascii=False, default=str)


def digest(obj: Any) -> str:
    """Hex sha256 of the canonical JSON of ``obj``."""
    return hashlib.sha256(canonical_json(obj).encode("utf-8")).hexdigest()


def stable_seed(*parts: Any) -> int:
    """A 63-bit seed derived from ``parts`` (same parts → same seed in every process)."""
    return int(digest(list(parts))[:16], 16) & ((1 << 63) - 1)


def unit_hash(*parts: Any) -> float:
    """A deterministic pseudo-uniform number in [0, 1) from ``parts``."""
    return int(digest(list(parts))[:13], 16) / float(1 << 52)


def content_digest(path: str | os.PathLike[str]) -> str:
    """Hex sha256 of a file's bytes, or of a folder's files (relative names and bytes,
    in sorted order): a stamp that changes when the content changes, whatever the path."""
    root = Path(path)
    files = [root] if root.is_file() else sorted(p for p in root.rglob("*") if p.is_file())
    h = hashlib.sha256()
    for f in files:
        if f != root:
            h.update(f.relative_to(root).as_posix().encode() + b"\0")
        with f.open("rb") as stream:
            for block in iter(lambda: stream.read(1 << 20), b""):
                h.update(block)
        h.update(b"\0")
    return h.hexdigest()


def sources_digest(*folders: str, suffixes: tuple[str, ...] = (".py", ".j2"),
                   exclude: frozenset[str] = frozenset()) -> str:
    """Hex digest of the package's source files (``suffixes``) under ``folders`` (names
    of its subpackages, e.g. ``"analysis"``): their relative names and contents, but the
    files named in ``exclude`` (paths relative to the package). A stamp of the code an
    output was made by; compiled caches are left out."""
    package = Path(__file__).resolve().parent
    return digest([[p.relative_to(package).as_posix(), hashlib.sha256(p.read_bytes()).hexdigest()]
                   for sub in folders for p in sorted((package / sub).rglob("*"))
                   if p.suffix in suffixes and p.is_file()
                   and p.relative_to(package).as_posix() not in exclude])
