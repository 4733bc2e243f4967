"""Robustness analyses (paper §IV-C, §V-D, §V-E): mappings, profile structure,
pedestrian dynamics and respondent.

Each function takes the cell-metrics table (``cell_metrics``) restricted by the
caller to one study part's episodes, and returns rates with cluster-bootstrap
intervals, one row per (metric, profile set or backend). Profile sets live in
the ``mapping`` column (``A``–``D``, ``A~shuffle``, ``A~rule-2``, …).
"""

from __future__ import annotations

from collections.abc import Sequence
from itertools import combinations

import numpy as np
import pandas as pd

from ..populations.identity import MATCHED_PAIR
from .bootstrap import rate_intervals
from .ranked import TOLERANCES, names
from .reversals import comparisons, population_pairs, tie_sign

#: the paper's ranked metrics, and those of them that are pedestrian burden
ALL_METRICS = names(paper=True)
BURDEN = names("burden", paper=True)


def rates_by_set(
    cells: pd.DataFrame,
    *,
    rng: np.random.Generator,
    metrics: Sequence[str] = ALL_METRICS,
    pairs: Sequence[tuple[str, str]] | None = None,
    n_boot: int = 1000,
    completed_only: bool = False,
) -> pd.DataFrame:
    """Reversal rate per (metric, backend, mapping) over ``pairs`` (default: all pairs of
    the populations present). Columns: metric, backend, mapping, reversals,
    comparisons, rate, ci_low, ci_high."""
    pops = sorted(cells["population"].unique())
    comps = comparisons(cells, pairs or population_pairs(pops), metrics=metrics)
    return rate_intervals(
        comps,
        ("metric", "backend", "mapping"),
        rng=rng,
        n_boot=n_boot,
        completed_only=completed_only,
    )


def ordering_signs(
    cells: pd.DataFrame, metric: str, tolerances: dict[str, float] = TOLERANCES
) -> pd.DataFrame:
    """Sign of metric(ctrl_1) − metric(ctrl_2) per (backend, mapping, cell, population,
    ctrl pair): ±1, 0 for a tie within the metric's tolerance, NaN when missing."""
    wide = cells.pivot_table(
        index=["backend", "mapping", "cell", "population"],
        columns="controller",
        values=metric,
        aggfunc="first",
    )
    ctrl = sorted(wide.columns)
    frames = []
    for c1, c2 in combinations(ctrl, 2):
        diff = (wide[c1] - wide[c2]).to_numpy(float)
        frames.append(
            pd.DataFrame(
                {"ctrl_1": c1, "ctrl_2": c2, "sign": tie_sign(diff, tolerances[metric])},
                index=wide.index,
            )
        )
    return pd.concat(frames).reset_index()


def agreement_with(
    cells: pd.DataFrame, reference: str = "A", metrics: Sequence[str] = BURDEN
) -> pd.DataFrame:
    """Share of controller orderings a profile set shares with ``reference``.

    Eligible comparisons are (cell, population, controller pair) orderings that are
    non-tied under both the set and the reference; agreement = same sign / eligible.
    Columns: metric, mapping, agree, eligible, agreement (in [0, 1]).
    """
    rows = []
    for metric in metrics:
        s = ordering_signs(cells, metric)
        key = ["backend", "cell", "population", "ctrl_1", "ctrl_2"]
        ref = s[s["mapping"] == reference].set_index(key)["sign"]
        for mapping, group in s[s["mapping"] != reference].groupby("mapping"):
            other = group.set_index(key)["sign"]
            a, b = ref.align(other, join="inner")
            eligible = (np.abs(a) == 1) & (np.abs(b) == 1)
            agree = int(((a == b) & eligible).sum())
            n = int(eligible.sum())
            rows.append(
                {
                    "metric": metric,
                    "mapping": mapping,
                    "agree": agree,
                    "eligible": n,
                    "agreement": agree / n if n else np.nan,
                }
            )
    return pd.DataFrame(rows, columns=["metric", "mapping", "agree", "eligible", "agreement"])


def completed_under_all(cells: pd.DataFrame, by: str = "backend") -> pd.Series:
    """Per (cell, population): every controller completed every variant under every
    value of ``by`` (e.g. both backends)."""
    done = cells.groupby(["cell", "population", by])["completed"].all()
    n_values = cells[by].nunique()
    grouped = done.groupby(["cell", "population"])
    return grouped.all() & (grouped.size() == n_values)


def backend_rates(
    cells: pd.DataFrame, *, rng: np.random.Generator, n_boot: int = 1000
) -> pd.DataFrame:
    """Reversal rates per backend on the cells completed by all controllers under every
    backend and both populations of a pair (paper §V-E); tie tolerances per backend."""
    ok = completed_under_all(cells, "backend")
    pops = sorted(cells["population"].unique())
    comps = comparisons(cells, population_pairs(pops))
    key = pd.MultiIndex.from_frame(comps[["cell", "pop_a"]])
    key_b = pd.MultiIndex.from_frame(comps[["cell", "pop_b"]])
    both = ok.reindex(key).fillna(False).to_numpy() & ok.reindex(key_b).fillna(False).to_numpy()
    comps = comps.assign(completed=both)
    return rate_intervals(comps, ("metric", "backend"), rng=rng, n_boot=n_boot, completed_only=True)


def matched_rates(
    cells: pd.DataFrame,
    *,
    rng: np.random.Generator,
    n_boot: int = 1000,
    matched: tuple[str, str] = MATCHED_PAIR,
) -> pd.DataFrame:
    """The matched intervention's reversal rates per profile set (e.g. per respondent)."""
    pair = cells[cells["population"].isin(matched)]
    return rates_by_set(pair, rng=rng, pairs=[matched], n_boot=n_boot)
