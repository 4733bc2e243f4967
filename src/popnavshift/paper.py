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

#: the paper's controllers, in its order
PAPER_CONTROLLERS: tuple[str, ...] = ("reactive", "early_yield", "robot_orca")
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
