"""The words the report's first paragraph (:mod:`.plain`) is built from: numbers, lists,
metric and comparison names, and each comparison's design as its tables say it is.

Nothing here decides anything: a verdict comes from a table, these functions only say it.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pandas as pd

from ..analysis.ranked import RANKED_METRICS, names
from ..analysis.reversals import COMPARISONS
from ..analysis.verdicts import MIN_EFFECT
from ..populations.identity import MATCHED_PAIR, NULL_KINDS

BURDEN = names("burden")
ROBOT = names("robot")
LABELS = {m.name: m.label for m in RANKED_METRICS}
#: the order in which a sentence names metrics: burden first, then robot time
METRIC_ORDER = {m: i for i, m in enumerate((*BURDEN, *ROBOT))}
#: the smallest excess worth a claim, in words ("5 pp")
MARGIN = f"{100 * MIN_EFFECT:g} pp"


def label(metric: str) -> str:
    return LABELS.get(metric, metric)


def by_metric(rows: pd.DataFrame) -> pd.DataFrame:
    """``rows`` in the order a sentence names their metrics."""
    return rows.sort_values("metric", key=lambda m: m.map(lambda x: METRIC_ORDER.get(x, 99)),
                            kind="stable")


def null_words(kind: str, otherwise: str) -> str:
    """A null design kind's replicates in words, as it declares them
    (:data:`popnavshift.populations.identity.NULL_KINDS`); ``otherwise`` for another kind."""
    return NULL_KINDS[kind].words if kind in NULL_KINDS else otherwise


#: the plural nouns of the null designs' words, and their singular (``1 swap permutation``)
_SINGULAR = {"permutations": "permutation", "subsets": "subset", "replicates": "replicate"}


def counted_nulls(n: int, kind: str, otherwise: str = "null replicates") -> str:
    """``9 swap permutations of their profiles``; ``1 swap permutation …`` for one."""
    words = null_words(kind, otherwise)
    if n == 1:
        head, *rest = words.split(" (", 1)
        for many, one in _SINGULAR.items():
            head = head.replace(many, one, 1)
        words = " (".join([head, *rest])
    return f"{n} {words}"


def pp(x: float, signed: bool = True) -> str:
    """A rate difference in percentage points: ``+8.6 pp``."""
    return "–" if not np.isfinite(x) else f"{100 * x:{'+' if signed else ''}.1f} pp"


def interval(r: Any) -> str:
    """``+9.0 pp [+3.6, +14.5]``: an excess and its deciding (simultaneous) interval."""
    if not (np.isfinite(r["ci_low"]) and np.isfinite(r["ci_high"])):
        return f"{pp(r['excess'])}, no interval"
    low, high = (pp(r[k]).removesuffix(" pp") for k in ("ci_low", "ci_high"))
    return f"{pp(r['excess'])} [{low}, {high}]"


def join(words: list[str]) -> str:
    return words[0] if len(words) == 1 else ", ".join(words[:-1]) + " and " + words[-1]


def phrase(comp: str) -> str:
    """A comparison in a sentence, as it is declared (:data:`.reversals.COMPARISONS`)."""
    return COMPARISONS[comp].phrase if comp in COMPARISONS else f"in {comp}"


def seed_sets(n: int) -> str:
    return f"{n} episode seed set{'s' if n != 1 else ''}"


def matched_pair_null(head: pd.DataFrame, populations: list[str]) -> str:
    """The null kind the matched pair is judged against when it is one of the population
    pairs, if it is not that of the other pairs; "" otherwise.

    The headline takes, for each pair, the first kind of :data:`NULL_KINDS` the study ran
    for it (:func:`popnavshift.analysis.nulls.comparison_design`): a kind that stands in
    for the matched pair alone (swap permutations) comes first, and the study ran it when
    the matched comparison has replicates of it."""
    if not set(MATCHED_PAIR) <= set(populations):
        return ""
    pairs = head[(head["comparison"] == "all_pairs") & (head["n_null"] > 0)]
    matched = head[(head["comparison"] == "matched") & (head["n_null"] > 0)]
    if pairs.empty:
        return ""
    others = str(pairs["null"].iloc[0])
    ran = set(matched["null"].astype(str))
    for name, kind in NULL_KINDS.items():
        if name == others:
            return ""
        if name in ran and kind.pair(MATCHED_PAIR, 1) is not None:
            return name
    return ""


def design_phrase(rows: pd.DataFrame, head: pd.DataFrame, populations: list[str]) -> str:
    """Where one comparison's rates come from (``rows``: its headline rows): its design and
    its null, the matched pair's own null named when it is one of the population pairs."""
    r = rows.iloc[0]
    n_null = int(rows["n_null"].max())
    kind = str(r["null"])
    design = (f"{seed_sets(int(r['seed_sets']))}, {int(r['variants_per_cell'])} variants per "
              f"cell")
    if r["comparison"] == "matched":
        return (f"under the matched time-pressure shift (same personas; {design}; against "
                f"{counted_nulls(n_null, kind)})")
    n_pops = len(populations)
    n_pairs = n_pops * (n_pops - 1) // 2
    where = (f"across the {n_pairs} pairs of the {n_pops} populations" if n_pops >= 2
             else "across the population pairs")
    own = matched_pair_null(head, populations)
    if not own:
        return f"{where} ({design}; against {counted_nulls(n_null, kind)})"
    return (f"{where} ({design}; against {counted_nulls(n_null, '')}: "
            f"{null_words(kind, kind)} for {n_pairs - 1} of the pairs, and for the matched "
            f"pair among them {null_words(own, own)})")
