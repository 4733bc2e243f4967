"""The release codebook: which slot holds each field we use, and what its codes mean.

See ``matraix.py`` for the layouts read. Besides our persona fields, the codebook's
``age_bracket`` (when present) tells which codes are minors, whom the sampler excludes.
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass
from pathlib import Path

from ..errors import InputError
from .fields import PERSONA_FIELDS, REQUIRED_FIELDS, vocabulary

FORMAT = "persona_codes"
AGE_FIELD = "age_bracket"
ADULT_AGE = 18
_LIST_KEYS = ("columns", "fields", "dimensions")
_ID_KEYS = ("id", "field_id", "name")
_VALUE_KEYS = ("values", "levels")
_UNDER = re.compile(r"^\s*(?:under|<|less than)\s*(\d+)", re.IGNORECASE)
_RANGE = re.compile(r"^\s*(\d+)\s*(?:-|–|to)\s*(\d+)")
_OPEN = re.compile(r"^\s*(\d+)\s*(?:\+|or (?:older|over|more))", re.IGNORECASE)


@dataclass(frozen=True)
class Codebook:
    """The slots of the fields we use, their values (in our vocabulary) and the minors."""

    path: Path
    n_slots: int
    slots: dict[str, int]  # field id → slot i
    values: dict[str, tuple[str, ...]]  # field id → value of each code
    age_slot: int | None = None  # slot of age_bracket, None when the codebook lacks it
    minor_codes: tuple[bool, ...] = ()  # per age_bracket code: is it a minor's bracket?
    format: str | None = None  # "persona_codes v2" as declared by the file


def read_codebook(path: Path) -> Codebook:
    """Parse and check a codebook file (see ``matraix.py`` for the layouts read)."""
    try:
        doc = json.loads(path.read_text("utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InputError(f"{path}: unreadable codebook: {exc}") from exc
    declared = _declared_format(doc, path)
    entries = _entries(doc, path)
    ids = [_entry_id(e, path, i) for i, e in enumerate(entries)]
    slots = {fid: i for i, fid in enumerate(ids) if fid in PERSONA_FIELDS}
    absent = [f for f in REQUIRED_FIELDS if f not in slots]
    if absent:
        raise InputError(f"{path}: codebook lacks required field(s) {', '.join(absent)}")
    values = {f: _our_values(_raw_values(entries[i], f, path), f, path) for f, i in slots.items()}
    age_slot = ids.index(AGE_FIELD) if AGE_FIELD in ids else None
    minors: tuple[bool, ...] = ()
    if age_slot is not None:
        raw = _raw_values(entries[age_slot], AGE_FIELD, path)
        minors = tuple(is_minor_bracket(str(v), path) for v in raw)
    return Codebook(path, len(entries), slots, values, age_slot, minors, declared)


def is_minor_bracket(bracket: str, where: Path | str = "codebook") -> bool:
    """True when every age in ``bracket`` ("Under 5", "13-17", "65+") is under 18."""
    if (m := _UNDER.match(bracket)) is not None:
        return int(m.group(1)) <= ADULT_AGE
    if (m := _RANGE.match(bracket)) is not None:
        return int(m.group(2)) < ADULT_AGE
    if _OPEN.match(bracket) is not None:  # open upwards ("65+"): never only minors
        return False
    raise InputError(
        f"{where}: {AGE_FIELD} value {bracket!r} is not an age range we can read",
        hint="expected 'Under N', 'A-B' or 'N+'",
    )


def _declared_format(doc: object, path: Path) -> str | None:
    if not isinstance(doc, dict) or "format" not in doc:
        return None
    if doc["format"] != FORMAT:
        raise InputError(f"{path}: codebook format {doc['format']!r}, expected {FORMAT!r}")
    version = doc.get("format_version", doc.get("version"))
    return FORMAT if version is None else f"{FORMAT} v{version}"


def _entries(doc: object, path: Path) -> list:
    if isinstance(doc, list):
        return doc
    if isinstance(doc, dict):
        for key in _LIST_KEYS:
            if isinstance(doc.get(key), list):
                return doc[key]
    raise InputError(
        f"{path}: codebook should hold its fields under "
        f"{', '.join(repr(k) for k in _LIST_KEYS)} or be a list of them"
    )


def _entry_id(entry: object, path: Path, index: int) -> str:
    if isinstance(entry, str):
        return entry
    if isinstance(entry, dict):
        for key in _ID_KEYS:
            if isinstance(entry.get(key), str):
                return entry[key]
    raise InputError(f"{path}: codebook entry {index} has no field id ({', '.join(_ID_KEYS)})")


def _raw_values(entry: object, field: str, path: Path) -> list:
    raw = next((entry[k] for k in _VALUE_KEYS if isinstance(entry, dict) and k in entry), None)
    if isinstance(raw, dict):  # code → value
        try:
            raw = [raw[c] for c in sorted(raw, key=int)]
        except ValueError as exc:
            raise InputError(f"{path}: field {field!r}: value codes must be integers") from exc
    if not isinstance(raw, list) or not raw or len(raw) > 16:
        raise InputError(f"{path}: field {field!r} needs a list of 1–16 values for 4-bit codes")
    return raw


def _our_values(raw: list, field: str, path: Path) -> tuple[str, ...]:
    ours = {v.casefold(): v for v in vocabulary(field)}
    mapped = []
    for value in raw:
        text = value if isinstance(value, str) else repr(value)
        if text not in vocabulary(field) and text.strip().casefold() not in ours:
            raise InputError(
                f"{path}: field {field!r}: codebook value {value!r} is not in our vocabulary",
                hint=f"allowed: {', '.join(repr(v) for v in vocabulary(field))}",
            )
        mapped.append(text if text in vocabulary(field) else ours[text.strip().casefold()])
    return tuple(mapped)
