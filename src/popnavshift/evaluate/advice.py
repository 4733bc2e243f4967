"""What would decide an undecided card: more null replicates, more seed sets, their cost.

A rate's verdict rests on the prediction interval excess ± t_{P−1} · s · √(1 + 1/P) at the
card's level α/m (:mod:`popnavshift.analysis.verdicts`), s the spread between its P null
replicates. More replicates shrink the t quantile and the √(1 + 1/P) factor; more episode
seed sets shrink s itself — a rate is a share over the comparisons of every seed set, so
its spread falls as 1/√K with K seed sets (the comparisons of another seed set are new
episodes). A row is *expected to be decided* at (K, P) when the half-width there is below
the distance from its excess to what it must clear: 0 for "above the null", the 5 pp
margin for "no excess ≥ 5 pp". The excess is held at its estimate: on the paper study the
excess over the null of the tails grew with seed sets (docs/analysis.md §8), so this is a
conservative guide for an effect that exists and a neutral one for ruling one out.

Seed sets extend only the parts that already repeat their episodes (the matched pair and
its swap null: ``--seed-sets``); the population pairs' size-matched null runs on the main
grid, so only replicates help it (``--replicates``). The advice is the cheapest grid point
that is expected to decide every undecided row, or says that none up to the grid's end does.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd
from scipy import stats

from ..analysis.verdicts import ALPHA, MIN_EFFECT

#: the designs a card's robustness tests, and whether extra seed sets reach them
EXTENDS_BY_SEED_SETS = {"matched": True, "all_pairs": False}
REPLICATES = (9, 19, 29, 39, 59, 99)
MAX_SEED_SETS = 16


@dataclass(frozen=True)
class Advice:
    """The cheapest (``seed_sets``, ``replicates``) expected to decide every undecided row
    (None when no grid point does), and how many rows it decides."""

    seed_sets: int | None
    replicates: int | None
    rows: int


def half_width(sd: float, replicates: int, family: int, alpha: float = ALPHA) -> float:
    """Half-width of the deciding prediction interval with ``replicates`` null replicates
    of spread ``sd``, at the card's level α/``family`` (two-sided)."""
    return float(stats.t.ppf(1 - alpha / (2 * family), replicates - 1) * sd
                 * np.sqrt(1 + 1 / replicates))


def _spread(row) -> float:
    """The spread between replicates behind a decided row, from its interval."""
    return float((row.ci_high - row.ci_low) / 2 / (
        stats.t.ppf(1 - ALPHA / (2 * row.family), row.n_null - 1)
        * np.sqrt(1 + 1 / row.n_null)))


def decides(row, seed_sets: int, replicates: int) -> bool:
    """Whether ``row`` (a raw-rule row of the card's robustness table, with its
    ``seed_sets`` now) is expected to be decided at (``seed_sets``, ``replicates``)."""
    k = seed_sets if EXTENDS_BY_SEED_SETS.get(row.design, False) else row.seed_sets
    sd = _spread(row) * np.sqrt(row.seed_sets / k)
    h = half_width(sd, replicates, int(row.family))
    return bool(h < max(row.excess, MIN_EFFECT - row.excess))


def advise(head: pd.DataFrame) -> Advice:
    """The cheapest grid point expected to decide every undecided raw-rule row of the card's
    robustness table ``head`` (module doc). Cost: the runs a design adds grow with
    seed sets × (replicates + 1) for the matched pair, (replicates + 1) for the pairs."""
    raw = head[(head["rule"] == "raw") & (head["verdict"] == "undecided")
               & (head["n_null"] >= 3)]
    if raw.empty:
        return Advice(None, None, 0)
    k0 = int(raw["seed_sets"].max())
    p0 = int(raw["n_null"].max())
    best: tuple[float, int, int] | None = None
    for k in range(k0, MAX_SEED_SETS + 1):
        for p in [x for x in REPLICATES if x >= p0] or [p0]:
            if not all(decides(r, k, p) for r in raw.itertuples()):
                continue
            cost = (k / k0) * (p + 1) / (p0 + 1) + (p + 1) / (p0 + 1)
            if best is None or cost < best[0]:
                best = (cost, k, p)
    if best is None:
        return Advice(None, None, len(raw))
    return Advice(best[1] if best[1] != k0 else None, best[2] if best[2] != p0 else None,
                  len(raw))


def advice_text(advice: Advice, command: str, runs: int | None, minutes: float | None) -> str:
    """The advice in words: ``command`` (the evaluate command line with the options that
    extend the study), the runs it adds and their minutes at the study's measured pace."""
    if advice.rows == 0:
        return ""
    if advice.seed_sets is None and advice.replicates is None:
        return (f"No design up to {MAX_SEED_SETS} seed sets and {REPLICATES[-1]} null "
                f"replicates is expected to decide its {advice.rows} undecided rate"
                f"{'s' if advice.rows != 1 else ''} (its excess sits near the margin).")
    cost = "" if runs is None else f" (+{runs:,} runs" + (
        f", ~{minutes:.0f} min at this study's measured pace)" if minutes is not None else ")")
    return (f"`{command}`{cost} is expected to decide its {advice.rows} undecided rate"
            f"{'s' if advice.rows != 1 else ''} (excess held at its estimate).")
