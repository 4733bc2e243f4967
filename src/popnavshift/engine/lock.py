"""One command at a time per study folder: an exclusive advisory lock.

Two ``popnavshift run`` (or ``probe``) commands writing one folder would race on
its shards, stamps and tables. The first takes ``flock`` on ``<folder>/.lock`` and
writes its pid there; a second gets a one-line error naming that pid. The kernel
drops the lock when the holder exits, however it exits (kill -9 included), so a
stale lock file never blocks anyone. Re-entrant within one process. Where
``fcntl`` does not exist (Windows) there is no lock.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from ..errors import ConfigError

try:
    import fcntl
except ImportError:  # pragma: no cover - Windows
    fcntl = None  # type: ignore[assignment]

LOCK_NAME = ".lock"
_HELD: dict[Path, int] = {}  # resolved folder → nesting depth in this process


@contextmanager
def study_lock(folder: Path) -> Iterator[None]:
    """Hold the folder's lock for the ``with`` block; ConfigError if another process has it."""
    key = Path(folder).resolve()
    if fcntl is None or key in _HELD:
        _HELD[key] = _HELD.get(key, 0) + 1
        try:
            yield
        finally:
            _HELD[key] -= 1
            if not _HELD[key]:
                del _HELD[key]
        return
    fd = os.open(key / LOCK_NAME, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            holder = os.pread(fd, 32, 0).decode("ascii", "replace").strip() or "unknown"
            raise ConfigError(
                f"study folder {folder} is in use by another popnavshift process "
                f"(pid {holder})",
                hint="wait for it to finish or stop it; the lock goes when it exits",
            ) from None
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
        _HELD[key] = 1
        try:
            yield
        finally:
            del _HELD[key]
    finally:
        os.close(fd)  # releases the lock
