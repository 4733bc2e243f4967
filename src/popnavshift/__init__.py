"""PopNavShift: stress-test social robot navigation under behavioral population shift.

The package is laid out as the pipeline of SPEC §1, in order of dependency:
personas → responses → profiles → populations → episodes → sim → (engine, analysis, report).
"""

__version__ = "0.1.0"

from .access import load  # noqa: E402  (popnavshift.load(study, part="main"))

__all__ = ["__version__", "load"]
