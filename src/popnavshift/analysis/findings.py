"""The paper's qualitative findings (§V), each checked on our tables.

:func:`paper_findings` turns Table I (:func:`popnavshift.analysis.summary.reversal_table`),
Table II (``controller_outcomes``), the width sensitivity and the Fig. 2 change in delay
into :class:`Finding` rows: a statement, whether it holds, and the numbers behind it.
The paper's own figures are in :mod:`popnavshift.analysis.paper_reference`.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import NamedTuple

import numpy as np
import pandas as pd

from ..paper import PAPER_CONTROLLERS
from ..populations.identity import MATCHED_PAIR
from .paper_reference import MATCHED_CHANGE_SIGN, TAIL_TO_MEAN_RATIO
from .reversals import METRICS


class Finding(NamedTuple):
    """One qualitative claim of the paper checked on our numbers."""

    statement: str
    holds: bool
    numbers: dict
    #: what it claims, for joining its interval check (:mod:`.surviving`): ``kind:detail``
    key: str = ""


def _rates(table1: pd.DataFrame, comparison: str, cells: str) -> pd.Series:
    sel = table1[(table1["comparison"] == comparison) & (table1["cells"] == cells)]
    return sel.set_index("metric")["rate"]


def burden_exceeds_time(rates: pd.Series, label: str) -> Finding:
    """Mean- and worst-decile-delay reversal rates both exceed the robot-time rate.

    ``rates`` is indexed by metric (fractions)."""
    time = rates["robot_time"]
    holds = rates["mean_delay"] > time and rates["worst_decile"] > time
    return Finding(f"Burden reversal rates exceed the robot-time rate ({label})", bool(holds),
                   {m: float(rates[m]) for m in METRICS}, f"burden_vs_time:{label}")


def completed_lower(all_cells: pd.Series, completed: pd.Series, label: str) -> Finding:
    """Every metric's completed-cell reversal rate is below its all-cell rate."""
    holds = all(completed[m] < all_cells[m] for m in METRICS)
    numbers = {m: (float(all_cells[m]), float(completed[m])) for m in METRICS}
    return Finding(f"Completed-cell reversal rates are lower than all-cell rates ({label})",
                   bool(holds), numbers, f"completed_lower:{label}")


WIDTH_SCENES: tuple[str, ...] = ("sidewalk", "bottleneck")  # the two panels of the paper's Fig. 4


def width_decreases(by_width: pd.DataFrame, label: str) -> Finding:
    """Sensitivity at the narrowest width exceeds the widest; ``monotonic`` reported too.

    ``by_width`` has one row per width (``width``, ``sensitivity``)."""
    s = by_width.sort_values("width").set_index("width")["sensitivity"]
    holds = len(s) >= 2 and s.iloc[0] > s.iloc[-1]
    numbers: dict = {float(w): float(v) for w, v in s.items()}
    numbers["monotonic"] = bool(len(s) >= 2 and (np.diff(s.to_numpy()) < 0).all())
    return Finding(f"Population sensitivity is larger at the narrowest than the widest width "
                   f"({label})", bool(holds), numbers, f"width:{label}")


#: our reading of "approximately": within this fraction of the paper's ratio
TAIL_REL_TOL = 0.25
#: the band of worst-decile / mean delay that counts as the paper's "about four times"
TAIL_BAND = (TAIL_TO_MEAN_RATIO * (1 - TAIL_REL_TOL), TAIL_TO_MEAN_RATIO * (1 + TAIL_REL_TOL))


def tail_ratio(outcomes: pd.DataFrame, k: float = TAIL_TO_MEAN_RATIO,
               rel_tol: float = TAIL_REL_TOL) -> Finding:
    """Worst-decile delay ≈ k × mean delay: every controller's ratio within k (1 ± rel_tol)."""
    ratio = outcomes["worst_decile"] / outcomes["mean_delay"]
    holds = len(ratio) > 0 and ratio.between(k * (1 - rel_tol), k * (1 + rel_tol)).all()
    return Finding(f"Worst-decile delay is about {k:g}× the mean delay", bool(holds),
                   {c: float(r) for c, r in ratio.items()}, "tail_ratio")


def controller_extreme(outcomes: pd.DataFrame, column: str, controller: str, *,
                       highest: bool, among: Sequence[str] | None = None) -> Finding:
    """``controller`` has the highest (or lowest) ``column`` among ``among`` (default all)."""
    col = outcomes[column] if among is None else outcomes.loc[list(among), column]
    best = col.idxmax() if highest else col.idxmin()
    word = "highest" if highest else "lowest"
    scope = "" if among is None else f" among {', '.join(among)}"
    return Finding(f"{controller} has the {word} {column}{scope}", bool(best == controller),
                   {c: float(v) for c, v in col.items()}, f"extreme:{controller}:{column}")


def matched_change_direction(change: pd.DataFrame, expected: dict[str, int]) -> Finding:
    """The matched shift moves each controller's delay in the paper's direction (sign)."""
    sel = change[change["population"] == MATCHED_PAIR[1]].set_index("controller")["change"]
    got = {c: float(sel.get(c, np.nan)) for c in expected}
    holds = all(np.sign(got[c]) == s for c, s in expected.items())
    return Finding("Matched deadline shift lowers delay under reactive and robot_orca and "
                   "raises it under early_yield", bool(holds), got, "matched_direction")


def paper_findings(table1: pd.DataFrame, outcomes: pd.DataFrame, widths: dict[str, pd.DataFrame],
                   change: pd.DataFrame) -> list[Finding]:
    """The paper's qualitative findings (§V), each with whether it holds on our tables.

    Args:
      table1: :func:`reversal_table`.
      outcomes: :func:`controller_outcomes`.
      widths: label → :func:`sensitivity_by_width` with ``by=()`` (e.g. "pooled",
        "sidewalk", "bottleneck").
      change: :func:`delay_change` of mean delay.
    """
    return available_findings(table1, outcomes, widths, change)[0]


def available_findings(table1: pd.DataFrame, outcomes: pd.DataFrame,
                       widths: dict[str, pd.DataFrame], change: pd.DataFrame, *,
                       pairs: bool = True, matched: bool = True,
                       delays: bool = True) -> tuple[list[Finding], list[str]]:
    """:func:`paper_findings` on a study that may lack some inputs: the findings whose
    inputs exist, in the paper's order, and what was left out. ``pairs``: Table I has the
    all-pairs rows; ``matched``: its matched rows; ``delays``: every controller has a
    mean delay; the controller findings need the paper's three controllers, the width
    findings a width series."""
    ctrl = set(PAPER_CONTROLLERS) <= set(outcomes.index)
    controllers = "the controller findings (all three built-in controllers)"
    controller_delays = "the controller delay findings"

    def extreme(column: str, controller: str, highest: bool, among=None) -> list[Finding]:
        return [controller_extreme(outcomes, column, controller, highest=highest, among=among)]

    checks: list[tuple[bool, str, Callable[[], list[Finding]]]] = [
        (matched, "the matched-pair reversal finding",
         lambda: [burden_exceeds_time(_rates(table1, "matched", "all"), "matched, all cells")]),
        (pairs, "the all-pairs reversal findings", lambda: [
            burden_exceeds_time(_rates(table1, "all_pairs", "all"), "all pairs, all cells"),
            burden_exceeds_time(_rates(table1, "all_pairs", "completed"),
                                "all pairs, completed"),
            completed_lower(_rates(table1, "all_pairs", "all"),
                            _rates(table1, "all_pairs", "completed"), "all pairs")]),
        (bool(widths), "the width findings (sidewalks or bottlenecks at 2+ widths)",
         lambda: [width_decreases(w, label) for label, w in widths.items()]),
        (delays, "the tail-to-mean finding", lambda: [tail_ratio(outcomes, TAIL_TO_MEAN_RATIO)]),
        (ctrl, controllers, lambda: extreme("success_pct", "reactive", True)),
        (ctrl and delays, controller_delays, lambda: extreme("mean_delay", "robot_orca", False)
         + extreme("worst_decile", "robot_orca", False)),
        (ctrl, controllers, lambda: extreme("timeout_pct", "early_yield", True)),
        (ctrl and delays, controller_delays,
         lambda: extreme("mean_delay", "early_yield", False, ("reactive", "early_yield"))),
        (ctrl and matched, "the matched-shift direction finding",
         lambda: [matched_change_direction(change, MATCHED_CHANGE_SIGN)]),
    ]
    found = [f for ok, _, make in checks if ok for f in make()]
    left = list(dict.fromkeys(what for ok, what, _ in checks if not ok))
    return found, left
