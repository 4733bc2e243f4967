"""Do controller differences change with the population more than under the null?

The reversal rates (:mod:`.nulls`) ask whether orderings *flip*; this test asks the broader
question of a population × controller interaction: whether the difference between two
controllers changes from one population to the other more than it changes between
populations that differ only by chance (the comparison's null replicates, run on the same
episodes). It does not say that orderings cross.

Per design k (k = 0 the observed population pairs, k = 1 … P null replicate k) and term
(population pair π, unit u, controller pair c), with the orderings of one metric
(:func:`.significance.orderings`, one paired episode bootstrap shared by every population):

* dD = D_P − D_Q, the difference of the pair's controller differences;
* SE = √(n/(n−1)) · SD over the shared episode resamples of D_P,b − D_Q,b (n episodes in
  the cell), and z = dD / SE (terms without a positive, finite SE are left out);
* the statistic **rankz**: per term, the mid-rank of |z| among the designs compared, scaled
  (r − 1)/(n − 1) to [0, 1]; T_k = the mean over the terms. Ranks make every term weigh at
  most 1, so one cell whose z is huge in every design (z of a cell with 3 episodes has
  t₂-like tails) cannot decide the test — the flaw of mean z², whose false-positive rate
  on placebos was 3–6 % at 0.625 %.

The test is one-sided (a design whose differences change *less* than the null's says
nothing about the population). Where the comparison's null is made of several independent
units (across the population pairs: a subset per population, the swap of the matched pair)
the exact randomization test over designs recombined unit by unit decides
(:class:`Recombined`; the prediction t claimed there on 7.5 % of 375 placebos at 5 %).
Otherwise (the matched pair alone) the prediction t, t = (T₀ − mean T_k) / (s·√(1 + 1/P))
on P − 1 degrees of freedom, decides; the exact permutation p = (1 + #{T_k ≥ T₀})/(1 + P)
stands beside it (it cannot reach 0.05/10 with fewer than 199 replicates). Ranks depend on
the designs compared, so a placebo (replicate j as the observed against the other
replicates, the observed left out) recomputes them among its own designs.

rankz was chosen among eight statistics declared before any data was seen, by a rule
declared with them, on the seed-0 study, and confirmed on an independent seed-1 study
(docs/analysis.md §12; the research scripts live outside the package).
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pandas as pd
from scipy import stats

from .calibrate import placebo_nulls
from .recombine import DRAWS, PREDICTION, RECOMBINED, Recombination
from .significance import Orderings
from .verdicts import ALPHA, DESCRIPTIVE, MIN_NULLS_T, permutation_p

#: the statistic's name in the tables
STATISTIC = "rankz"
#: the claim, in the words the tables and the report use
CHANGES = "changes more than under the null"
NOT_SHOWN = "not shown to change more than under the null"
VERDICTS = (CHANGES, NOT_SHOWN, DESCRIPTIVE)
#: why a row with no term (``terms`` 0) is untested, whatever its null replicates: no
#: controller difference had an episode-bootstrap spread to scale it by
NO_TERMS = ("no controller difference varies over its cell's episodes; more episodes per "
            "cell would test it")


def _inflation(o: Orderings) -> np.ndarray:
    """(U, 1) √(n/(n−1)) of every unit's episode count (NaN below 2 episodes)."""
    n = o.n_episodes.astype(float)
    with np.errstate(all="ignore"):
        return np.where(n >= 2, np.sqrt(n / (n - 1)), np.nan)[:, None]


def _pair_z(o: Orderings, ia: Sequence[int] | np.ndarray, ib: Sequence[int] | np.ndarray,
            infl: np.ndarray) -> np.ndarray:
    """(len(ia), U, C) z = dD / SE of the population pairs (ia[i], ib[i]) (NaN where the
    term has no value or no positive SE)."""
    dd = o.diff[ia] - o.diff[ib]
    with np.errstate(all="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN terms → NaN
        # the resampled differences in float64, so that equal |z| tie exactly
        se = np.nanstd(o.boot[:, ia].astype(np.float64) - o.boot[:, ib], axis=0) * infl
        ok = np.isfinite(dd) & np.isfinite(se) & (se > 0)
        return np.where(ok, dd / np.where(ok, se, 1.0), np.nan)


def interaction_z(o: Orderings, groups: Sequence[Sequence[tuple[str, str]]]) -> np.ndarray:
    """(K, Π, U, C) z = dD / SE of every term of each design of ``groups`` (a list of
    population pairs per design, all of the same length Π): NaN where the term has no
    value or no positive SE."""
    infl = _inflation(o)
    out = np.full((len(groups), len(groups[0]), *o.diff.shape[1:]), np.nan)
    for k, pairs in enumerate(groups):
        out[k] = _pair_z(o, [o.index(a) for a, _ in pairs], [o.index(b) for _, b in pairs],
                         infl)
    return out


def _mean(total: np.ndarray, count: np.ndarray) -> np.ndarray:
    """total / count, NaN where count is 0 (a design with no finite term)."""
    with np.errstate(all="ignore"):
        return np.where(count > 0, total / np.where(count > 0, count, 1), np.nan)


def _mean_over_terms(scaled: np.ndarray) -> np.ndarray:
    """(K,) the mean of each design's finite scaled ranks (K, Π, T), summed pair by pair
    of the design (the order :meth:`Recombined.statistic` sums in, so both agree bit for
    bit)."""
    fin = np.isfinite(scaled)
    s = np.where(fin, scaled, 0.0).sum(axis=2)
    n = fin.sum(axis=2)
    total, count = np.zeros(len(s)), np.zeros(len(s))
    for j in range(s.shape[1]):
        total, count = total + s[:, j], count + n[:, j]
    return _mean(total, count)


def rank_statistic(z: np.ndarray) -> np.ndarray:
    """(K,) T of each design: the mean over terms of the normalized mid-rank of |z| among
    the K designs (terms finite in fewer than two designs are left out)."""
    flat = np.abs(z.reshape(z.shape[0], -1))
    finite = np.isfinite(flat)
    n = finite.sum(axis=0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # a column with no finite value
        r = stats.rankdata(np.where(finite, flat, np.nan), axis=0, nan_policy="omit")
    with np.errstate(all="ignore"):
        scaled = np.where(finite & (n >= 2), (r - 1) / (n - 1), np.nan)
    return _mean_over_terms(scaled.reshape(z.shape[0], z.shape[1], -1))


def weighted_midranks(v: np.ndarray, w: np.ndarray) -> np.ndarray:
    """(K, T) the mid-rank of each value of ``v`` (K, T) within its column among values
    repeated ``w`` (K, T) times each (NaN where ``v`` is not finite; ``w`` 0 there): the
    rank the value would have among all the repeats, ties sharing their mean rank."""
    fin = np.isfinite(v)
    last_if_missing = np.where(fin, v, np.inf)
    order = np.argsort(last_if_missing, axis=0, kind="stable")
    sv = np.take_along_axis(last_if_missing, order, axis=0)
    sw = np.take_along_axis(np.where(fin, w, 0), order, axis=0).astype(float)
    above = np.cumsum(sw, axis=0)  # repeats up to and including each sorted value
    k = np.arange(len(v))[:, None]
    first = np.ones(sv.shape, bool)
    first[1:] = sv[1:] != sv[:-1]
    last = np.ones(sv.shape, bool)
    last[:-1] = sv[1:] != sv[:-1]
    start = np.maximum.accumulate(np.where(first, k, 0), axis=0)  # each tie group's ends
    end = np.minimum.accumulate(np.where(last, k, len(v))[::-1], axis=0)[::-1]
    below = np.take_along_axis(above - sw, start, axis=0)
    level = np.take_along_axis(above, end, axis=0) - below
    r = np.empty(v.shape)
    np.put_along_axis(r, order, below + (level + 1) / 2, axis=0)
    return np.where(fin, r, np.nan)


def one_sided(t0: float, null: np.ndarray) -> dict:
    """The one-sided prediction t of ``t0`` against the finite ``null`` statistics, with the
    exact permutation p: ``null_mean``, ``null_sd``, ``t``, ``df``, ``p_t``, ``p_value``,
    ``n_null``. NaN with fewer than 3 null values or no spread."""
    null = np.asarray(null, float)
    null = null[np.isfinite(null)]
    p = int(null.size)
    out = {"null_mean": float(null.mean()) if p else np.nan,
           "null_sd": float(null.std(ddof=1)) if p > 1 else np.nan, "t": np.nan,
           "df": max(p - 1, 0), "p_t": np.nan,
           "p_value": permutation_p(t0, null) if p and np.isfinite(t0) else np.nan,
           "n_null": p}
    if p < MIN_NULLS_T or not np.isfinite(t0) or not out["null_sd"] > 0:
        return out
    t = (t0 - out["null_mean"]) / (out["null_sd"] * np.sqrt(1 + 1 / p))
    return {**out, "t": float(t), "p_t": float(stats.t.sf(t, p - 1))}


class Recombined:
    """The randomization reference of the interaction test of a comparison whose null
    designs are made of several independently drawn units (:mod:`.recombine`: exact
    whatever the shape of T's distribution — which is why it replaces the prediction t
    here, its placebo rate having been above nominal across the population pairs). z of a
    population pair is computed once and reused by every design and placebo that draws
    it."""

    def __init__(self, o: Orderings, groups: Sequence[Sequence[tuple[str, str]]],
                 units: Sequence[int]) -> None:
        self.o = o
        self.rec = Recombination(o.populations, groups, units)
        self.infl = _inflation(o)
        self.cache: dict[int, np.ndarray] = {}

    def _keys(self, designs: np.ndarray) -> np.ndarray:
        """(R, Π) the population pair (a · n + b) each design draws for each pair, with
        its z computed (once) into the cache."""
        n = self.rec.n_populations
        keys = self.rec.keys(designs)
        new = np.array([k for k in np.unique(keys).tolist() if k not in self.cache], int)
        chunks = [new[i:i + 64] for i in range(0, len(new), 64)]
        if not chunks:
            return keys
        # numpy releases the GIL in the resampled differences' reductions: two threads
        with ThreadPoolExecutor(max_workers=2) as pool:
            for ks, z in zip(chunks, pool.map(lambda k: _pair_z(self.o, k // n, k % n,
                                                                  self.infl), chunks),
                             strict=True):
                self.cache.update(zip(ks.tolist(), z, strict=True))
        return keys

    def z(self, designs: np.ndarray) -> np.ndarray:
        """(R, Π, U, C) z of the designs ``designs`` (R, units): each unit's design index."""
        keys = self._keys(designs)
        uniq, inv = np.unique(keys, return_inverse=True)
        return np.stack([self.cache[k] for k in uniq.tolist()])[inv.reshape(keys.shape)]

    def statistic(self, designs: np.ndarray) -> np.ndarray:
        """(R,) T of the designs: :func:`rank_statistic` of :meth:`z`, the same numbers,
        with each term's mid-ranks computed once per distinct population pair, weighted by
        how many designs draw it (:func:`weighted_midranks`), and each pair's sum over
        terms gathered per design: memory and time grow with the distinct pairs, not with
        R × terms."""
        keys = self._keys(designs)
        total, count = np.zeros(len(keys)), np.zeros(len(keys))
        for j in range(keys.shape[1]):
            uniq, inv, repeats = np.unique(keys[:, j], return_inverse=True,
                                           return_counts=True)
            v = np.abs(np.stack([self.cache[k].ravel() for k in uniq.tolist()]))  # (n, T)
            w = repeats[:, None] * np.isfinite(v)
            n = w.sum(axis=0)
            with np.errstate(all="ignore"):
                scaled = np.where(n >= 2, (weighted_midranks(v, w) - 1) / (n - 1), np.nan)
            fin = np.isfinite(scaled)
            total = total + np.where(fin, scaled, 0.0).sum(axis=1)[inv]
            count = count + fin.sum(axis=1)[inv]
        return _mean(total, count)

    def test(self, tested: int, pool: Sequence[int] | np.ndarray, *, draws: int,
             seed: Sequence[int]
             ) -> tuple[float, dict]:
        """T of design ``tested`` among ``draws`` designs recombined from it and ``pool``
        (design indices), and the test's fields (:func:`one_sided`'s, ``t`` the
        standardized excess over the recombined designs, ``p_t`` = ``p_value`` the
        randomization p)."""
        T = self.statistic(self.rec.draws(tested, pool, draws=draws, seed=seed))
        ref = T[1:][np.isfinite(T[1:])]
        t0, sd = float(T[0]), float(ref.std(ddof=1)) if ref.size > 1 else np.nan
        p = permutation_p(t0, ref) if ref.size and np.isfinite(t0) else np.nan
        return t0, {"null_mean": float(ref.mean()) if ref.size else np.nan, "null_sd": sd,
                    "t": (t0 - float(ref.mean())) / sd if sd > 0 else np.nan, "df": np.nan,
                    "p_t": p, "p_value": p, "n_null": len(pool)}


def interaction_test(o: Orderings, observed: Sequence[tuple[str, str]],
                     nulls: Sequence[Sequence[tuple[str, str]]], *,
                     null_size: int | None = None, units: Sequence[int] = (),
                     draws: int = DRAWS) -> tuple[dict, pd.DataFrame]:
    """The interaction test of one metric's orderings ``o``: the observed pairs against
    the null replicates' pairs (module doc). Returns the observed row (``metric``,
    ``statistic``, ``reference``, ``T``, ``terms``, :func:`one_sided`'s fields) and one row
    per replicate: its ``T`` among all designs and, as a placebo against the other
    replicates, ``placebo_t`` and ``placebo_p_t``; with ``null_size``, against the
    ``null_size`` replicates after it, cyclically (the study's own design on more
    placebos: :func:`.calibrate.placebo_nulls`). With ``units`` of two or more units
    (:class:`.nulls.Design`) each test is the randomization test over ``draws`` recombined
    designs (:class:`Recombined`; with ``null_size``, the observed's pool is the study's
    own, its first ``null_size`` replicates), else the prediction t, ranks among the designs
    compared."""

    groups = [list(observed), *map(list, nulls)]
    rec = Recombined(o, groups, units) if len(set(units)) > 1 and draws > 0 and nulls \
        else None
    # the designs' own z: from the recombinations' cache when there is one (computed once)
    z = interaction_z(o, groups) if rec is None else \
        rec.z(rec.rec.own(np.arange(len(groups))))
    T = rank_statistic(z)
    terms = int(np.isfinite(z[0]).sum())
    seed = list(o.metric.encode())
    if rec is not None:  # with null_size, against the study's own replicates (the first)
        t0, d = rec.test(0, range(1, 1 + min(null_size or len(nulls), len(nulls))),
                         draws=draws, seed=[0, *seed])
        row = {"metric": o.metric, "statistic": STATISTIC, "reference": RECOMBINED, "T": t0,
               "terms": terms, **d}
    else:
        row = {"metric": o.metric, "statistic": STATISTIC, "reference": PREDICTION,
               "T": float(T[0]), "terms": terms, **one_sided(float(T[0]), T[1:])}
    reps = []
    if len(nulls) >= 2:
        placebo = rank_statistic(z[1:]) if rec is None else None
        for j in range(len(nulls)):
            rest = placebo_nulls(len(nulls), j, null_size)
            if rec is not None:
                d = rec.test(j + 1, rest + 1, draws=draws, seed=[j + 1, *seed])[1]
            elif placebo is not None and len(rest) == len(nulls) - 1:
                d = one_sided(float(placebo[j]), placebo[rest])
            else:  # ranks among the placebo and its own null only
                own = rank_statistic(z[1:][[j, *rest]])
                d = one_sided(float(own[0]), own[1:])
            reps.append({"metric": o.metric, "replicate": j + 1, "T": float(T[j + 1]),
                         "placebo_t": d["t"], "placebo_p_t": d["p_t"]})
    cols = ["metric", "replicate", "T", "placebo_t", "placebo_p_t"]
    return row, pd.DataFrame(reps, columns=cols)


def interaction_verdicts(table: pd.DataFrame, *, alpha: float = ALPHA) -> pd.DataFrame:
    """The interaction rows decided together: each row with at least 3 null replicates is
    one test of a family of m, claimed at one-sided p ≤ ``alpha``/m (Bonferroni). Adds
    ``family``, ``alpha_row`` (the level each row is decided at), ``p_adj`` (m·p capped at
    1) and ``verdict`` (:data:`CHANGES`, :data:`NOT_SHOWN`, or *descriptive* without
    enough replicates)."""
    out = table.reset_index(drop=True).copy()
    tested = out["n_null"] >= MIN_NULLS_T
    m = max(int(tested.sum()), 1)
    p = out["p_t"].to_numpy(float)
    out["family"] = m
    out["alpha_row"] = alpha / m
    out["p_adj"] = np.where(tested, np.minimum(1.0, m * p), np.nan)
    out["verdict"] = np.where(~tested, DESCRIPTIVE,
                              np.where(np.nan_to_num(p, nan=1.0) <= alpha / m, CHANGES,
                                       NOT_SHOWN))
    return out


def interaction_placebos(nulls: pd.DataFrame, family: int, *, alpha: float = ALPHA
                         ) -> pd.DataFrame:
    """Every interaction placebo (one row of ``nulls`` per comparison, metric and replicate)
    with whether it claims a change at the table's level ``alpha``/``family`` and at
    ``alpha`` alone: the rows :func:`.calibrate.calibration_table` counts."""
    p = nulls[nulls["placebo_p_t"].notna()]
    if p.empty:
        return pd.DataFrame(columns=["comparison", "test", "rule", "claim", "nominal",
                                     "replicate", "claim_made"])
    m = max(int(family), 1)
    frames = [p.assign(claim=f"{CHANGES}, at the table's level", nominal=alpha / m,
                       claim_made=p["placebo_p_t"] <= alpha / m),
              p.assign(claim=f"{CHANGES}, at {alpha:g}", nominal=alpha,
                       claim_made=p["placebo_p_t"] <= alpha)]
    out = pd.concat(frames, ignore_index=True).assign(test=f"interaction ({STATISTIC})",
                                                      rule="—")
    return out[["comparison", "test", "rule", "claim", "nominal", "replicate", "claim_made"]]
