"""PopNavShift: stress-test social robot navigation under behavioral population shift.

The package is laid out as the pipeline of SPEC §1, in order of dependency:
personas → responses → profiles → populations → design → read → analysis → sim → engine
→ (report, evaluate) → cli. ``popnavshift.load``, ``results`` and ``cards``
(:mod:`popnavshift.read.access`) and ``leaderboard`` (:mod:`popnavshift.evaluate.leaderboard`,
which may simulate) are imported on first use, so ``import popnavshift``
(and the command line's start-up) loads nothing heavy.
"""

from typing import Any

from .version import __version__

__all__ = ["__version__", "cards", "leaderboard", "load", "results"]


def __getattr__(name: str) -> Any:
    if name in ("cards", "load", "results"):
        from .read import access

        return getattr(access, name)
    if name == "leaderboard":
        from .evaluate.leaderboard import leaderboard

        return leaderboard
    raise AttributeError(f"module 'popnavshift' has no attribute {name!r}")
