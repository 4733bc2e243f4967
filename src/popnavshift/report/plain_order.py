"""Does the controllers' overall order change with the population? Said only as far as the
rank intervals resolve it.

The overall order is each population's order of the controllers' grid means
(``evidence_ranks``), with each rank's 90 % interval over episode resamples. A change is
*resolved* when some controller's rank interval under one population is disjoint from its
interval under another (it ranks differently beyond episode noise); point orders that
differ while every controller's intervals overlap are not a resolved change, and the
sentence says so. The intervals hold the personas fixed (they are not a test against the
null) and are not adjusted for the many population pairs compared: a resolved change is
stated as such, with the controller and the two intervals that show it.
"""

from __future__ import annotations

from itertools import combinations
from typing import Any

import pandas as pd

from ..analysis.reversals import COMPARISONS
from ..viz.style import controller_label
from .figures import pop_label
from .plain_words import METRIC_ORDER, join, label, phrase


def _span(r: Any) -> str:
    low, high = int(r["rank_low"]), int(r["rank_high"])
    return f"[{low}]" if low == high else f"[{low}–{high}]"


def separations(sub: pd.DataFrame) -> list[str]:
    """One metric's rank table of one comparison → every controller whose rank intervals
    under two populations are disjoint, in words (widest gap first)."""
    found: list[tuple[int, str]] = []
    for ctrl, g in sub.groupby("controller", sort=True):
        rows = list(g.sort_values("population").itertuples(index=False))
        for a, b in combinations(rows, 2):
            lo, hi = (a, b) if a.rank_high < b.rank_low else (b, a)
            gap = int(hi.rank_low) - int(lo.rank_high)
            if gap > 0:
                found.append((gap, f"{controller_label(str(ctrl))} ranks {_span(lo._asdict())} "
                                   f"in {pop_label(lo.population)} and {_span(hi._asdict())} "
                                   f"in {pop_label(hi.population)}"))
    return [text for _, text in sorted(found, key=lambda x: -x[0])]


def _point_orders(sub: pd.DataFrame) -> pd.Series:
    return sub.sort_values(["rank", "controller"]).groupby("population", sort=True)[
        "controller"].agg(tuple)


def metric_order(sub: pd.DataFrame) -> tuple[str, str]:
    """One metric of one comparison: ``("changes" | "unresolved" | "same", words)``."""
    orders = _point_orders(sub)
    n = len(orders)
    modal = orders.value_counts().index[0]
    text = " < ".join(controller_label(c) for c in modal)
    split = separations(sub)
    if split:
        more = f", and {len(split) - 1} more such" if len(split) > 1 else ""
        return "changes", f"{split[0]}{more}"
    if orders.nunique() == 1:
        return "same", f"{text} in {'both' if n == 2 else f'all {n}'} populations"
    other = [pop_label(p) for p in orders.index[orders != modal]]
    return "unresolved", (f"{text} in {n - len(other)} of {n}, another point order in "
                          f"{join(other)}, every controller's rank intervals overlapping")


def order_sentence(ranks: pd.DataFrame | None) -> dict[str, str] | None:
    """Whether the controllers' overall (grid-mean) order changes with the population, per
    comparison and metric, only as far as the rank intervals resolve it (module doc)."""
    if ranks is None or ranks.empty:
        return None
    words: dict[str, dict[str, list[str]]] = {"changes": {}, "unresolved": {}, "same": {}}
    comps = [c for c in COMPARISONS if c in set(ranks["comparison"])]
    changes: dict[str, list[str]] = {}
    for comp in comps:
        r = ranks[ranks["comparison"] == comp]
        for metric in sorted(set(r["metric"]), key=lambda m: METRIC_ORDER.get(m, 99)):
            kind, text = metric_order(r[r["metric"] == metric])
            if kind == "changes":
                changes.setdefault(comp, []).append(label(metric))
            words[kind].setdefault(comp, []).append(f"{label(metric)} ({text})")
    parts = []
    intro = {"changes": "the order changes beyond the rank intervals for ",
             "unresolved": "point orders differ, but no change is resolved, for ",
             "same": "the point order is the same in every population for "}
    for comp in comps:
        bits = [intro[k] + join(words[k][comp]) for k in intro if comp in words[k]]
        parts.append(f"{phrase(comp)}, " + "; ".join(bits))
    changed = [f"for {join(changes[c])} {phrase(c)}" for c in comps if changes.get(c)]
    lead = ("The overall order changes " + "; ".join(changed) + "."
            if changed else "No change of the overall order is resolved.")
    return {"lead": lead,
            "text": "The controllers' grid-mean order (lowest first) counts as changed only "
                    "where a controller's 90% rank intervals (over episode resamples, not a "
                    "test against the null) under two populations do not overlap: "
                    + "; ".join(parts) + "."}
