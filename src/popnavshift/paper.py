"""The paper's study design as data: the controllers and population conditions it runs.

What the paper runs is not what the package can run. The registries of built-in
controllers (``sim/controllers/builtin.py`` ``BUILTINS``) and of population conditions
(``populations/build.py`` ``POPULATIONS``) may hold more, and adding to them changes no
paper result: these tuples are the default of a study part, the baselines of
``popnavshift evaluate`` and the controllers the paper's findings are about. They sit at
the bottom layer so the analysis reads them without loading the simulator; a test checks
that each is registered.
"""

from __future__ import annotations

from typing import NamedTuple


class Controller(NamedTuple):
    """A controller of the paper: its registered ``name`` (a study's controller id) and
    its ``label``, the name the paper gives it, which every page and figure shows."""

    name: str
    label: str


#: the paper's controllers, in its order
CONTROLLERS: tuple[Controller, ...] = (
    Controller("reactive", "Reactive"),
    Controller("early_yield", "Early yielding"),
    Controller("robot_orca", "Robot-ORCA"),
)
PAPER_CONTROLLERS: tuple[str, ...] = tuple(c.name for c in CONTROLLERS)
#: the paper's eight population conditions (SPEC §5), in its order
PAPER_POPULATIONS: tuple[str, ...] = (
    "homogeneous",
    "mixed",
    "high_time_pressure",
    "mobility_support",
    "high_caution",
    "low_robot_trust",
    "matched_base",
    "matched_deadline",
)
