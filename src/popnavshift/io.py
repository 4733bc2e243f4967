"""Atomic file writes, and reading back what we wrote with one clear error.

A write goes to a temporary file beside the target, then is renamed: a crash never
leaves a half-written table, JSON or figure under the final name. A JSON object or a
CSV read back that is damaged is an :class:`InputError` naming the file and what is
wrong (never a parser's traceback); CSV text cells that a spreadsheet would run as a
formula are written with a leading apostrophe and read back as they were.
"""

from __future__ import annotations

import json
import os
import re
import tempfile
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import pandas as pd

from .errors import InputError


def _current_umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


UMASK = _current_umask()


@contextmanager
def atomic_path(path: str | os.PathLike[str]) -> Iterator[Path]:
    """Yield a temporary path in the target's folder; rename it over ``path`` on success."""
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp", dir=target.parent)
    os.close(fd)
    tmp_path = Path(tmp)
    try:
        yield tmp_path
        os.chmod(tmp_path, 0o666 & ~UMASK)  # mkstemp makes 0600; give the usual permissions
        os.replace(tmp_path, target)
    finally:
        if tmp_path.exists():
            tmp_path.unlink()


def write_atomic(path: str | os.PathLike[str], writer: Callable[[Path], Any]) -> Path:
    """Call ``writer(tmp_path)`` and move the result to ``path`` atomically."""
    with atomic_path(path) as tmp:
        writer(tmp)
    return Path(path)


def write_parquet(df: pd.DataFrame, path: str | os.PathLike[str]) -> Path:
    """Write ``df`` as Parquet (no index) atomically."""
    return write_atomic(path, lambda tmp: df.to_parquet(tmp, index=False))


def write_json(obj: Any, path: str | os.PathLike[str]) -> Path:
    """Write ``obj`` as pretty JSON atomically."""

    def _write(tmp: Path) -> None:
        tmp.write_text(json.dumps(obj, indent=2, sort_keys=True, default=str) + "\n", "utf-8")

    return write_atomic(path, _write)


def write_text(text: str, path: str | os.PathLike[str]) -> Path:
    """Write ``text`` atomically (UTF-8)."""
    return write_atomic(path, lambda tmp: tmp.write_text(text, "utf-8"))


# ----------------------------------------------------------------- reading back
def read_json_object(path: str | os.PathLike[str], what: str = "a JSON object") -> dict:
    """``path`` as a JSON object; InputError naming the file when it is missing, not
    UTF-8, not JSON or not an object (``what`` says what it should be)."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: not found")
    try:
        data = json.loads(path.read_text("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InputError(f"{path} is damaged (not valid JSON: {_first_line(exc)})") from None
    if not isinstance(data, dict):
        raise InputError(f"{path} is damaged (not {what}: a JSON {type(data).__name__})")
    return data


#: a text cell starting with one of these is a formula to a spreadsheet (``=1+1``,
#: ``@SUM(…)``, ``+cmd``, ``-cmd``, a tab, a carriage return): it is written with a leading
#: apostrophe (also before apostrophes already leading such a cell, so that reading back
#: through :func:`read_csv` gives the value written)
_FORMULA = re.compile(r"'*[=+\-@\t\r]")


def csv_cell(value: Any) -> Any:
    """``value`` safe as a spreadsheet cell (see ``_FORMULA``); other values unchanged."""
    return "'" + value if isinstance(value, str) and _FORMULA.match(value) else value


def _uncell(value: Any) -> Any:
    if isinstance(value, str) and value.startswith("'") and _FORMULA.match(value, 1):
        return value[1:]
    return value


def _text_columns(df: pd.DataFrame) -> list:
    return [c for c in df.columns if df[c].dtype == object or pd.api.types.is_string_dtype(
        df[c]) or isinstance(df[c].dtype, pd.CategoricalDtype)]


def csv_text(df: pd.DataFrame) -> str:
    """``df`` as CSV (no index, every digit), text cells made safe for a spreadsheet
    (:func:`csv_cell`)."""
    text = _text_columns(df)
    if text:
        df = df.assign(**{str(c): df[c].astype(object).map(csv_cell) for c in text})
    return df.to_csv(index=False)


def write_csv(df: pd.DataFrame, path: str | os.PathLike[str]) -> Path:
    """Write ``df`` as :func:`csv_text` atomically."""
    return write_text(csv_text(df), path)


def read_csv(path: str | os.PathLike[str]) -> pd.DataFrame:
    """A CSV this package wrote (:func:`csv_text`), text cells as written; InputError
    naming the file when it is missing or not a readable CSV. A file holding one line
    break is a table without columns (what :func:`csv_text` writes for one): empty."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: not found")
    if path.stat().st_size == 1 and path.read_bytes() == b"\n":
        return pd.DataFrame()
    try:
        df = pd.read_csv(path)
    except (ValueError, UnicodeDecodeError) as exc:  # pandas' parser errors are ValueErrors
        raise InputError(f"{path} is damaged (not a readable CSV: {_first_line(exc)})") from None
    text = [c for c in _text_columns(df) if df[c].notna().any()]
    return df.assign(**{str(c): df[c].map(_uncell) for c in text}) if text else df


def _first_line(exc: BaseException) -> str:
    lines = str(exc).strip().splitlines()
    return lines[0][:200] if lines else type(exc).__name__
