"""PopNavShift: stress-test social robot navigation under behavioral population shift.

The package is laid out as the pipeline of SPEC §1, in order of dependency:
personas → responses → profiles → populations → episodes → sim → (engine, analysis, report).
"""

from .access import cards, load, results  # popnavshift.load(study, part="main")
from .version import __version__

__all__ = ["__version__", "cards", "load", "results"]
