"""One small hierarchy of user-facing errors.

Every error a user can cause (bad file, unknown name, invalid config, invalid LLM
output, missing key, network failure) is a :class:`PopNavShiftError`. The CLI turns
it into one red line and exit code 2; nothing else is caught there, so bugs still
show a traceback.
"""

from __future__ import annotations

import difflib
from collections.abc import Iterable


class PopNavShiftError(Exception):
    """Base class: ``str(err)`` is one line saying what, where and a hint."""

    def __init__(self, message: str, *, hint: str | None = None) -> None:
        self.message = message
        self.hint = hint
        super().__init__(message if hint is None else f"{message} ({hint})")

    def __reduce__(self):
        # subclasses have other constructors: rebuild from the final text so an error
        # raised in a worker process crosses back to the parent intact
        return (_rebuild, (type(self), self.message, self.hint))


class InputError(PopNavShiftError):
    """A user-supplied file or table is unreadable or invalid."""


class ConfigError(PopNavShiftError):
    """A configuration value or a name is invalid."""


class UnknownNameError(ConfigError):
    """A name is not in a registry; the message suggests the closest names."""

    def __init__(self, kind: str, name: str, known: Iterable[str]) -> None:
        known = sorted(known)
        close = close_names(name, known)
        hint = f"did you mean {', '.join(repr(c) for c in close)}?" if close else None
        listed = ", ".join(known) if len(known) <= 12 else (
            f"{', '.join(known[:4])}, … ({len(known)} in all)"
        )
        super().__init__(f"unknown {kind} {name!r}{code_points(name)}; known: {listed}",
                         hint=hint)


def close_names(name: str, known: Iterable[str], n: int = 3) -> list[str]:
    """The ``n`` known names closest to ``name``, ignoring case (``hrvo`` → ``HRVO``,
    ``Reactve`` → ``reactive``): a name differing only in case comes first."""
    by_lower: dict[str, list[str]] = {}
    for k in known:
        by_lower.setdefault(k.lower(), []).append(k)
    hits = difflib.get_close_matches(name.lower(), list(by_lower), n=n)
    return [k for hit in hits for k in by_lower[hit]][:n]


class RespondentError(PopNavShiftError):
    """A respondent (LLM or rule) could not produce a valid answer."""


class TransportError(RespondentError):
    """The network or the server failed after all retries."""


class MissingKeyError(RespondentError):
    """An API key environment variable is not set."""


def code_points(text: str) -> str:
    """`` (U+0456 at 2)`` for the first non-ASCII characters of ``text``: a homoglyph
    (Cyrillic і for Latin i) looks like the known name it fails to match."""
    odd = [(i, ch) for i, ch in enumerate(text) if not ch.isascii()][:3]
    if not odd:
        return ""
    return " (" + ", ".join(f"U+{ord(ch):04X} at {i + 1}" for i, ch in odd) + ")"


def _rebuild(cls: type[PopNavShiftError], message: str, hint: str | None) -> PopNavShiftError:
    err = cls.__new__(cls)
    PopNavShiftError.__init__(err, message, hint=hint)
    return err
