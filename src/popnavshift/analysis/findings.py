"""The paper's qualitative findings (§V), each declared once and checked on our tables.

``CLAIMS`` lists them in the paper's order: a :class:`Claim` is a finding's statement,
the inputs it needs, its check on point estimates (from Table I
(:func:`popnavshift.analysis.summary.reversal_table`), Table II
(``controller_outcomes``), the width sensitivity and the Fig. 2 change in delay) and how
it is judged beyond noise (:mod:`.surviving`). :func:`paper_findings` turns them into
:class:`Finding` rows: a statement, whether it holds, and the numbers behind it. The
paper's own figures are in :mod:`popnavshift.analysis.paper_reference`.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from typing import NamedTuple

import numpy as np
import pandas as pd

from ..paper import PAPER_CONTROLLERS
from ..populations.identity import MATCHED_PAIR
from . import finding_stats as fs
from .paper_reference import MATCHED_CHANGE_SIGN, TAIL_TO_MEAN_RATIO
from .reversals import METRICS


class Finding(NamedTuple):
    """One qualitative claim of the paper checked on our numbers."""

    statement: str
    holds: bool
    numbers: dict
    #: the :class:`Claim` it checks (``CLAIM_BY_KEY``)
    key: str = ""


class Check(NamedTuple):
    """A point-estimate check: whether the claim holds, and the numbers behind it."""

    holds: bool
    numbers: dict


def _rates(table1: pd.DataFrame, comparison: str, cells: str) -> pd.Series:
    sel = table1[(table1["comparison"] == comparison) & (table1["cells"] == cells)]
    return sel.set_index("metric")["rate"]


def burden_exceeds_time(rates: pd.Series) -> Check:
    """Mean- and worst-decile-delay reversal rates both exceed the robot-time rate.

    ``rates`` is indexed by metric (fractions)."""
    time = rates["robot_time"]
    holds = rates["mean_delay"] > time and rates["worst_decile"] > time
    return Check(bool(holds), {m: float(rates[m]) for m in METRICS})


def completed_lower(all_cells: pd.Series, completed: pd.Series) -> Check:
    """Every metric's completed-cell reversal rate is below its all-cell rate."""
    holds = all(completed[m] < all_cells[m] for m in METRICS)
    return Check(bool(holds), {m: (float(all_cells[m]), float(completed[m])) for m in METRICS})


WIDTH_SCENES: tuple[str, ...] = ("sidewalk", "bottleneck")  # the two panels of the paper's Fig. 4


def width_decreases(by_width: pd.DataFrame) -> Check:
    """Sensitivity at the narrowest width exceeds the widest; ``monotonic`` reported too.

    ``by_width`` has one row per width (``width``, ``sensitivity``)."""
    s = by_width.sort_values("width").set_index("width")["sensitivity"]
    holds = len(s) >= 2 and s.iloc[0] > s.iloc[-1]
    numbers: dict = {float(w): float(v) for w, v in s.items()}
    numbers["monotonic"] = bool(len(s) >= 2 and (np.diff(s.to_numpy()) < 0).all())
    return Check(bool(holds), numbers)


#: our reading of "approximately": within this fraction of the paper's ratio
TAIL_REL_TOL = 0.25
#: the band of worst-decile / mean delay that counts as the paper's "about four times"
TAIL_BAND = (TAIL_TO_MEAN_RATIO * (1 - TAIL_REL_TOL), TAIL_TO_MEAN_RATIO * (1 + TAIL_REL_TOL))


def tail_ratio(outcomes: pd.DataFrame, k: float = TAIL_TO_MEAN_RATIO,
               rel_tol: float = TAIL_REL_TOL) -> Check:
    """Worst-decile delay ≈ k × mean delay: every controller's ratio within k (1 ± rel_tol)."""
    ratio = outcomes["worst_decile"] / outcomes["mean_delay"]
    holds = len(ratio) > 0 and ratio.between(k * (1 - rel_tol), k * (1 + rel_tol)).all()
    return Check(bool(holds), {c: float(r) for c, r in ratio.items()})


def controller_extreme(outcomes: pd.DataFrame, column: str, controller: str, *,
                       highest: bool, among: Sequence[str] | None = None) -> Check:
    """``controller`` has the highest (or lowest) ``column`` among ``among`` (default all)."""
    col = outcomes[column] if among is None else outcomes.loc[list(among), column]
    best = col.idxmax() if highest else col.idxmin()
    return Check(bool(best == controller), {c: float(v) for c, v in col.items()})


def matched_change_direction(change: pd.DataFrame, expected: dict[str, int]) -> Check:
    """The matched shift moves each controller's delay in the paper's direction (sign)."""
    sel = change[change["population"] == MATCHED_PAIR[1]].set_index("controller")["change"]
    got = {c: float(sel.get(c, np.nan)) for c in expected}
    return Check(all(np.sign(got[c]) == s for c, s in expected.items()), got)


class Inputs(NamedTuple):
    """What the point-estimate checks read (see :func:`paper_findings`)."""

    table1: pd.DataFrame
    outcomes: pd.DataFrame
    widths: dict[str, pd.DataFrame]
    change: pd.DataFrame


Band = Callable[[str | None], tuple[float, float]]


def _band(lo: float, hi: float) -> Band:
    return lambda controller: (lo, hi)


class Interval(NamedTuple):
    """How a claim is judged beyond noise: a statistic of the cell metrics whose paired
    bootstrap interval must lie inside ``band`` (:mod:`.surviving`).

    ``value(cells, values, controller)`` gets the cell rows and each metric's values
    (``METRICS_NEEDED`` of :mod:`.surviving`, point or resampled) and returns the
    statistic. ``per_controller``: one row per controller of the study that it lists
    (``None``: one row for the claim)."""

    statistic: str
    value: Callable[[pd.DataFrame, dict[str, np.ndarray], str | None], np.ndarray]
    band: Band
    per_controller: Callable[[set[str]], list[str]] | None = None


class Claim(NamedTuple):
    """One qualitative finding of the paper, declared once: the report's statement, the
    inputs it needs, its point-estimate check and how it is judged beyond noise — by an
    :class:`Interval`, or by the null of a headline comparison (``null``), or not at all."""

    key: str
    statement: str
    #: inputs it reads: ``pairs``, ``matched``, ``delays``, ``controllers`` (the paper's
    #: three), ``controller:<name>`` (one controller), ``width:<label>`` (a width series,
    #: see :func:`paper_findings`)
    needs: frozenset[str]
    #: what the report says is not checked when the inputs are absent
    missing: str
    check: Callable[[Inputs], Check]
    interval: Interval | None = None
    #: the headline comparison whose null judges it (:func:`.nulls.burden_beyond_time`)
    null: str | None = None


def _needs(*names: str) -> frozenset[str]:
    return frozenset(names)


def _burden(comparison: str, cells: str, label: str, null: str | None) -> Claim:
    return Claim(f"burden_vs_time:{label}",
                 f"Burden reversal rates exceed the robot-time rate ({label})",
                 _needs(comparison if comparison == "matched" else "pairs"),
                 "the matched-pair reversal finding" if comparison == "matched"
                 else "the all-pairs reversal findings",
                 lambda i: burden_exceeds_time(_rates(i.table1, comparison, cells)),
                 null=null)


def _width(label: str, scenes: tuple[str, ...] | None) -> Claim:
    interval = None if scenes is None else Interval(
        "sensitivity at narrowest − widest width [s]",
        lambda c, v, _: fs.width_gap(c, v["mean_delay"], scenes), _band(0, np.inf))
    return Claim(f"width:{label}", "Population sensitivity is larger at the narrowest than "
                 f"the widest width ({label})", _needs(f"width:{label}"),
                 "the width findings (sidewalks or bottlenecks at 2+ widths)",
                 lambda i: width_decreases(i.widths[label]), interval)


CONTROLLERS_MISSING = "the controller findings (all three built-in controllers)"
DELAYS_MISSING = "the controller delay findings"


def _extreme(column: str, controller: str, highest: bool, among: tuple[str, ...] | None,
             interval: Interval) -> Claim:
    word = "highest" if highest else "lowest"
    scope = "" if among is None else f" among {', '.join(among)}"
    delay = column in ("mean_delay", "worst_decile")
    return Claim(f"extreme:{controller}:{column}",
                 f"{controller} has the {word} {column}{scope}",
                 _needs("controllers", *(("delays",) if delay else ())),
                 DELAYS_MISSING if delay else CONTROLLERS_MISSING,
                 lambda i: controller_extreme(i.outcomes, column, controller, highest=highest,
                                              among=among), interval)


def _gap(metric: str, controller: str, highest: bool, statistic: str, scale: float = 1.0,
         among: tuple[str, ...] | None = None) -> Interval:
    return Interval(statistic, lambda c, v, _: scale * fs.extreme_gap(
        c, v[metric], controller, highest=highest, among=among), _band(0, np.inf))


def _matched_band(controller: str | None) -> tuple[float, float]:
    return (-np.inf, 0) if MATCHED_CHANGE_SIGN[str(controller)] < 0 else (0, np.inf)


#: The paper's qualitative findings (§V) in its order: the one declaration the
#: point-estimate table (:func:`paper_findings`), the intervals (:mod:`.surviving`) and
#: the report's summary iterate. A new finding is one entry (and its check).
CLAIMS: tuple[Claim, ...] = (
    _burden("matched", "all", "matched, all cells", "matched"),
    _burden("all_pairs", "all", "all pairs, all cells", "all_pairs"),
    _burden("all_pairs", "completed", "all pairs, completed", None),
    Claim("completed_lower:all pairs",
          "Completed-cell reversal rates are lower than all-cell rates (all pairs)",
          _needs("pairs"), "the all-pairs reversal findings",
          lambda i: completed_lower(_rates(i.table1, "all_pairs", "all"),
                                    _rates(i.table1, "all_pairs", "completed"))),
    _width("pooled", WIDTH_SCENES),
    *(_width(scene, None) for scene in WIDTH_SCENES),
    Claim("tail_ratio", f"Worst-decile delay is about {TAIL_TO_MEAN_RATIO:g}× the mean delay",
          _needs("delays"), "the tail-to-mean finding", lambda i: tail_ratio(i.outcomes),
          Interval("worst decile / mean delay",
                   lambda c, v, ctrl: fs.tail_to_mean(c, v["worst_decile"], v["mean_delay"],
                                                      str(ctrl)),
                   _band(*TAIL_BAND), sorted)),
    _extreme("success_pct", "reactive", True, None,
             _gap("success_share", "reactive", True, "success share gap to the next [pp]",
                  100.0)),
    _extreme("mean_delay", "robot_orca", False, None,
             _gap("mean_delay", "robot_orca", False, "next lowest minus robot_orca [s]")),
    _extreme("worst_decile", "robot_orca", False, None,
             _gap("worst_decile", "robot_orca", False, "next lowest minus robot_orca [s]")),
    _extreme("timeout_pct", "early_yield", True, None,
             _gap("timeout_share", "early_yield", True, "timeout share gap [pp]", 100.0)),
    _extreme("mean_delay", "early_yield", False, ("reactive", "early_yield"),
             _gap("mean_delay", "early_yield", False, "reactive − early_yield [s]",
                  among=("reactive", "early_yield"))),
    Claim("matched_direction", "Matched deadline shift lowers delay under reactive and "
          "robot_orca and raises it under early_yield", _needs("controllers", "matched"),
          "the matched-shift direction finding",
          lambda i: matched_change_direction(i.change, MATCHED_CHANGE_SIGN),
          Interval("deadline − base mean delay [s]",
                   lambda c, v, ctrl: fs.matched_change(c, v["mean_delay"], str(ctrl)),
                   _matched_band,
                   lambda ctrls: [c for c in MATCHED_CHANGE_SIGN if c in ctrls])),
)
CLAIM_BY_KEY: dict[str, Claim] = {c.key: c for c in CLAIMS}
assert len(CLAIM_BY_KEY) == len(CLAIMS), "two claims share a key"


def controller_needs(controllers: Iterable[str]) -> set[str]:
    """The :attr:`Claim.needs` a study's ``controllers`` serve: ``controller:<name>`` for
    each, and ``controllers`` when the paper's three are among them."""
    have = set(controllers)
    return {f"controller:{c}" for c in have} | (
        {"controllers"} if set(PAPER_CONTROLLERS) <= have else set())


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
    inputs exist, in the paper's order, and what was left out (a ``missing`` text once,
    when none of its claims could be checked). ``pairs``: Table I has the all-pairs rows;
    ``matched``: its matched rows; ``delays``: every controller has a mean delay; the
    controller findings need the paper's three controllers, the width findings a width
    series."""
    have = {name for name, ok in (("pairs", pairs), ("matched", matched), ("delays", delays))
            if ok} | {f"width:{label}" for label in widths} | controller_needs(outcomes.index)
    inputs = Inputs(table1, outcomes, widths, change)
    found = []
    for claim in CLAIMS:
        if claim.needs <= have:
            holds, numbers = claim.check(inputs)
            found.append(Finding(claim.statement, bool(holds), numbers, claim.key))
    ran = {CLAIM_BY_KEY[f.key].missing for f in found}
    left = list(dict.fromkeys(c.missing for c in CLAIMS if c.missing not in ran
                              and not c.needs <= have))
    return found, left
