"""Stage 10: evaluate one controller against the baselines of a study.

``evaluate`` runs what is missing (reusing the baseline study's runs and the
controller's own cached runs) and returns the evaluated part's tables;
``make_card`` writes the one-page population-robustness card (HTML + PNG, its verdict
as JSON and its tables as CSV); ``compare`` puts several controllers' cards side by side
(``compare.compare``; ``compare_table``, pure; ``compare_page.write_comparison`` writes the
page and tables); ``leaderboard.build_leaderboard`` does so for every controller there is.
The names are imported on first use: a command that only reads a card's manifest
(:mod:`.card_files`) loads no simulator. ``compare`` and ``leaderboard`` are the modules
(a function of a module's own name would be shadowed by it once the module is imported).
"""

from importlib import import_module
from typing import Any

#: public name → the module that defines it
_WHERE = {"BASELINES": "run", "Evaluation": "run", "evaluate": "run", "make_card": "run",
          "Card": "card", "card_tables": "card", "Comparison": "compare",
          "compare_table": "compare"}

__all__ = sorted(_WHERE)


def __getattr__(name: str) -> Any:
    if name in _WHERE:
        return getattr(import_module(f".{_WHERE[name]}", __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
