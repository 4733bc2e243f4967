"""Ranking reversals between populations (paper §IV-B, SPEC §7).

Pipeline: cell metrics (:func:`popnavshift.analysis.delay.cell_metrics`) →
``comparisons`` (one row per unit, metric, population pair and controller pair)
→ ``reversal_rates`` (pooled ratios), ``cluster_counts`` (per-cell counts for
the bootstrap) or ``ranking_tau`` (Kendall τ-b between population rankings).

Tie rule: two controllers are *tied* on a metric when |Δ| ≤ tol, so exactly at
the tolerance is a tie (SPEC: non-tied means |Δ| > tol). The test is
|Δ| > tol + 1e-9 s: cell metrics are means of floats, and a difference that is
0.02 s in decimal is often 0.020000000000000018 in binary (1.32 − 1.30); 1e-9 s
is far below any time resolution of the simulation (dt = 0.1 s).
"""

from __future__ import annotations

from collections.abc import Sequence
from itertools import combinations
from typing import NamedTuple

import numpy as np
import pandas as pd

from ..errors import InputError, UnknownNameError
from .delay import UNIT
from .ranked import TOLERANCES, names

#: The paper's three ranked metrics (Table I); each one's tie tolerance is declared with it.
METRICS: tuple[str, ...] = names(paper=True)
TIE_EPS = 1e-9  # [s] guard against binary rounding at exactly the tolerance


class Comparison(NamedTuple):
    """A comparison of populations whose reversals the study reports (the ``comparison``
    column), with its names on a page: its ``title`` (the answer's box), ``short`` (figure
    panels and sentences), ``phrase`` ("under the matched shift") and ``noun`` ("the
    matched intervention")."""

    title: str
    short: str
    phrase: str
    noun: str


#: Every comparison, in the order a page shows them: the matched pair, then every pair of
#: the main part's populations.
COMPARISONS: dict[str, Comparison] = {
    "matched": Comparison("Matched time-pressure shift (same personas)",
                          "Matched time-pressure shift", "under the matched shift",
                          "the matched intervention"),
    "all_pairs": Comparison("All population pairs of the main grid", "All population pairs",
                            "across the population pairs", "the population pairs"),
}


def population_pairs(populations: Sequence[str]) -> list[tuple[str, str]]:
    """Every unordered pair, in the given order (8 populations → 28 pairs)."""
    return list(combinations(populations, 2))


def tie_sign(diff: np.ndarray, tol: float) -> np.ndarray:
    """Sign of ``diff`` (any shape) with ties: ±1 if |diff| > tol (+1e-9), 0 if tied, NaN if NaN."""
    d = np.asarray(diff, dtype=float)
    return np.where(np.isnan(d), np.nan, np.where(np.abs(d) > tol + TIE_EPS, np.sign(d), 0.0))


def _controllers(cells: pd.DataFrame, controllers: Sequence[str] | None) -> list[str]:
    return sorted(cells["controller"].unique()) if controllers is None else list(controllers)


def _wide(cells: pd.DataFrame, column: str, controllers: list[str]) -> pd.DataFrame:
    """Index (*UNIT, population), one column per controller."""
    key = [*UNIT, "population", "controller"]
    if cells.duplicated(key).any():
        raise InputError(f"cell table: duplicate rows for key {key}")
    wide = cells.set_index(key)[column].unstack("controller")
    return wide.reindex(columns=controllers)


def completed_units(cells: pd.DataFrame, controllers: Sequence[str] | None = None) -> pd.Series:
    """Bool per (*UNIT, population): every controller completed every variant.

    A controller without a row in the unit counts as not completed.
    """
    ctrl = _controllers(cells, controllers)
    return _wide(cells, "completed", ctrl).eq(True).all(axis=1)


def _diffs_by_population(cells: pd.DataFrame, metric: str, ctrl: list[str]) -> pd.DataFrame:
    """Index (*UNIT, ctrl_1, ctrl_2), one column per population: metric(ctrl_1) − metric(ctrl_2)."""
    if len(ctrl) < 2:
        raise InputError(f"cell table: ranking needs at least 2 controllers, got {ctrl}")
    wide = _wide(cells, metric, ctrl).astype(float)
    parts = [
        pd.DataFrame({"ctrl_1": c1, "ctrl_2": c2, "diff": wide[c1] - wide[c2]}, index=wide.index)
        for c1, c2 in combinations(ctrl, 2)
    ]
    long = pd.concat(parts).set_index(["ctrl_1", "ctrl_2"], append=True)["diff"]
    return long.unstack("population")


def _check_names(pops: list[str], metrics: Sequence[str], cells: pd.DataFrame,
                 tolerances: dict[str, float]) -> None:
    """A misspelt population or metric would silently give no comparison: refuse it."""
    known = set(cells["population"])
    for p in pops:
        if p not in known:
            raise UnknownNameError("population", p, known)
    for m in metrics:
        if m not in tolerances:
            raise UnknownNameError("tolerance metric", m, tolerances)


def comparisons(
    cells: pd.DataFrame,
    pairs: Sequence[tuple[str, str]],
    *,
    metrics: Sequence[str] = METRICS,
    tolerances: dict[str, float] = TOLERANCES,
    controllers: Sequence[str] | None = None,
) -> pd.DataFrame:
    """Every controller comparison of every unit under every population pair.

    Args:
      cells: cell metrics, key (backend, mapping, cell, population, controller).
      pairs: population pairs (pop_a, pop_b).
      metrics: columns of ``cells`` to rank (lower is better; the sign is what matters).
      tolerances: tie tolerance per metric [s].
      controllers: the compared controllers (default: all in ``cells``, sorted).

    Returns:
      One row per (metric, backend, mapping, cell, pop_a, pop_b, ctrl_1, ctrl_2)
      with ``diff_a``/``diff_b`` = metric(ctrl_1) − metric(ctrl_2) under each
      population (NaN when either is missing), ``sign_a``/``sign_b`` (±1, 0 for
      a tie, NaN for missing), ``comparable`` (non-tied and present under both),
      ``reversal`` (comparable and opposite signs) and ``completed`` (every
      controller completed every variant of the cell under both populations).
    """
    ctrl = _controllers(cells, controllers)
    pops = sorted({p for pair in pairs for p in pair})
    _check_names(pops, metrics, cells, tolerances)
    ia = np.array([pops.index(a) for a, _ in pairs], dtype=int)  # int even when empty
    ib = np.array([pops.index(b) for _, b in pairs], dtype=int)
    done = completed_units(cells, ctrl).unstack("population").reindex(columns=pops)
    frames = []
    for metric in metrics:
        diffs = _diffs_by_population(cells, metric, ctrl).reindex(columns=pops)
        units = diffs.index.droplevel(["ctrl_1", "ctrl_2"])
        both_done = done.reindex(units).eq(True).to_numpy(bool)  # (n, n_pops)
        d = diffs.to_numpy(float)
        n, k = d.shape[0], len(pairs)
        f = diffs.index.to_frame(index=False).iloc[np.tile(np.arange(n), k)]
        f = f.reset_index(drop=True)
        f.insert(0, "metric", metric)
        f.insert(4, "pop_a", np.repeat([a for a, _ in pairs], n))
        f.insert(5, "pop_b", np.repeat([b for _, b in pairs], n))
        f["diff_a"] = d[:, ia].T.ravel()  # pair-major, like the rows
        f["diff_b"] = d[:, ib].T.ravel()
        f["completed"] = (both_done[:, ia] & both_done[:, ib]).T.ravel()
        frames.append(f)
    out = pd.concat(frames, ignore_index=True)
    tol = out["metric"].map(tolerances).to_numpy(float)
    out["sign_a"] = tie_sign(out["diff_a"].to_numpy(float), tol)
    out["sign_b"] = tie_sign(out["diff_b"].to_numpy(float), tol)
    sa, sb = out["sign_a"].to_numpy(), out["sign_b"].to_numpy()
    out["comparable"] = np.abs(sa * sb) == 1.0  # NaN and 0 both fail
    out["reversal"] = sa * sb == -1.0
    cols = [c for c in out.columns if c != "completed"] + ["completed"]
    return out[cols]


def _counted(comps: pd.DataFrame, completed_only: bool) -> pd.DataFrame:
    """``comps`` with reversal/comparable masked to completed cells when asked.

    Masking rather than dropping keeps every group and cluster in the output.
    """
    if not completed_only:
        return comps
    done = comps["completed"]
    return comps.assign(reversal=comps["reversal"] & done, comparable=comps["comparable"] & done)


def safe_ratio(numerator: np.ndarray, denominator: np.ndarray) -> np.ndarray:
    """``numerator / denominator`` elementwise (broadcast); NaN where the denominator is 0."""
    r = np.asarray(numerator, dtype=float)
    c = np.asarray(denominator, dtype=float)
    return np.divide(r, c, out=np.full(np.broadcast(r, c).shape, np.nan), where=c > 0)


def reversal_rates(
    comps: pd.DataFrame, by: Sequence[str] = ("metric",), *, completed_only: bool = False
) -> pd.DataFrame:
    """Pooled reversal rate per group of ``by``: Σ reversals / Σ comparable comparisons.

    Returns columns ``*by, reversals, comparisons, rate`` (rate in [0, 1], NaN
    when a group has no comparable comparison); ``by=()`` gives one row. Pooling
    sums counts over cells, controller pairs and population pairs, so every
    comparison weighs the same (not a mean of per-pair rates).
    """
    c = _counted(comps, completed_only)
    if by:
        out = c.groupby(list(by)).agg(reversals=("reversal", "sum"),
                                      comparisons=("comparable", "sum")).reset_index()
    else:
        out = pd.DataFrame({"reversals": [c["reversal"].sum()],
                            "comparisons": [c["comparable"].sum()]})
    out[["reversals", "comparisons"]] = out[["reversals", "comparisons"]].astype(np.int64)
    out["rate"] = safe_ratio(out["reversals"].to_numpy(), out["comparisons"].to_numpy())
    return out


def cluster_counts(
    comps: pd.DataFrame,
    by: Sequence[str] = ("metric",),
    *,
    cluster: str = "cell",
    completed_only: bool = False,
) -> tuple[np.ndarray, np.ndarray, pd.DataFrame]:
    """Per-cluster reversal and comparison counts: the cluster bootstrap's input.

    Returns ``(reversals, comparisons, groups)``: two int arrays of shape
    (n_clusters, n_groups) and a frame with one row of ``by`` values per group
    (``by=()`` gives one group, ``scope == "all"``). Every cluster in ``comps``
    is a row, including clusters with no comparable comparison (zeros): the
    bootstrap resamples all analysed cells, not only the informative ones.
    """
    c = _counted(comps, completed_only)
    if not by:
        c, by = c.assign(scope="all"), ("scope",)
    if c.empty:
        return np.zeros((0, 0), np.int64), np.zeros((0, 0), np.int64), pd.DataFrame(columns=by)
    counts = c.groupby([cluster, *by]).agg(
        reversals=("reversal", "sum"), comparisons=("comparable", "sum")
    )
    wide = counts.unstack(list(by), fill_value=0)
    rev = wide["reversals"]
    comp = wide["comparisons"].reindex(columns=rev.columns, fill_value=0)
    groups = rev.columns.to_frame(index=False)
    return rev.to_numpy(np.int64), comp.to_numpy(np.int64), groups


# --- Kendall τ-b ---------------------------------------------------------------------------


def tau_b_from_signs(sign_x: np.ndarray, sign_y: np.ndarray) -> float:
    """Kendall τ-b from the pairwise signs (±1, 0 for a tie) of two rankings.

    τ-b = Σ s_x s_y / √(Σ|s_x| · Σ|s_y|) = (C − D) / √((n0 − n1)(n0 − n2)):
    the concordant-minus-discordant pairs over the untied pairs of each
    ranking. NaN when either ranking is all ties.
    """
    sx, sy = np.asarray(sign_x, float), np.asarray(sign_y, float)
    den = np.sqrt(np.abs(sx).sum() * np.abs(sy).sum())
    return float(np.sum(sx * sy) / den) if den > 0 else float("nan")


def kendall_tau_b(x: np.ndarray, y: np.ndarray, tol: float = 0.0) -> float:
    """Kendall τ-b of two score vectors (n,) with ties at |Δ| ≤ ``tol``; scipy-free."""
    x, y = np.asarray(x, float), np.asarray(y, float)
    i, j = np.triu_indices(x.size, k=1)
    return tau_b_from_signs(tie_sign(x[i] - x[j], tol), tie_sign(y[i] - y[j], tol))


def ranking_tau(comps: pd.DataFrame) -> pd.DataFrame:
    """τ-b between the controller rankings of pop_a and pop_b, per unit and metric.

    Uses the tolerance-aware signs of :func:`comparisons`, so a tie within the
    metric's tolerance is a tie; controllers missing under either population are
    left out. Returns ``metric, backend, mapping, cell, pop_a, pop_b, tau,
    n_pairs``; average with ``groupby(["metric", "pop_a", "pop_b"])["tau"].mean()``.
    """
    c = comps[comps["sign_a"].notna() & comps["sign_b"].notna()]
    c = c.assign(prod=c["sign_a"] * c["sign_b"], abs_a=c["sign_a"].abs(), abs_b=c["sign_b"].abs())
    g = c.groupby(["metric", *UNIT, "pop_a", "pop_b"])
    out = g.agg(num=("prod", "sum"), na=("abs_a", "sum"), nb=("abs_b", "sum"),
                n_pairs=("prod", "size"))
    den = np.sqrt(out["na"] * out["nb"])
    out["tau"] = (out["num"] / den).where(den > 0)
    return out[["tau", "n_pairs"]].reset_index()
