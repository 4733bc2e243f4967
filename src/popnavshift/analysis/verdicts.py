"""Verdicts on a rate against its null replicates, with a known false-positive rate.

A headline rate R (the reversal rate of the observed population pairs) is set beside
P null replicates R₁ … R_P computed on the same episodes, slots and controllers (swap
permutations of the matched personas; size-matched random subsets of mixed). Given the
episodes, a replicate is a draw of the rate when the population label carries no
information; under that null the observed rate is one more draw. What decides is
therefore the spread *between* replicates, not the episode bootstrap (which holds the
replicates fixed and so misses that spread: docs/analysis.md §10).

* **Prediction t** (the raw rule, whose rates are sums over hundreds of comparisons):
  excess δ = R − mean(R_k); its scale is s·√(1 + 1/P), s the SD between replicates
  (R is a new draw, the mean is estimated from P); t = δ / (s·√(1 + 1/P)) on P − 1
  degrees of freedom. s is never taken below the binomial spread √(p(1−p)/n) of a share
  of the replicates' n comparable comparisons at their pooled rate p
  (:func:`binomial_floor`): a rate over few comparisons is discrete, and a handful of
  replicates that happen to sit on the same few values (0, 1/12, …) would otherwise make
  a tiny s and a huge t (on 20 synthetic cards of pure noise with 12 comparisons a rate,
  4 read population-sensitive without it, tests/test_evaluate_verdict.py). The two-sided
  95 % interval δ ± t_{P−1, 0.975}·s·√(1 + 1/P) decides: *above the null* (interval
  above 0), *below the null* (below 0), *no excess ≥ 5 pp* (its upper end under 5
  percentage points), else *undecided*. Exact when the
  replicate rates are normal; how close is measured on placebos (:mod:`.calibrate`).
* **Exact permutation** (the significant rule, whose rates are small counts — mostly 0
  and skewed, where the t rejects too often): p = (1 + #{R_k ≥ R}) / (1 + P), exact for
  exchangeable replicates whatever their shape. *Above the null* when p ≤ 0.05, which
  needs P ≥ 19; otherwise *not shown above the null*; with P < 19 the rate is
  *descriptive* (p cannot reach 0.05).

Pure functions of numbers; definitions in ``docs/analysis.md`` §10.
"""

from __future__ import annotations

import numpy as np
from scipy import stats

ALPHA = 0.05  # two-sided level of the prediction interval; one-sided level of the permutation
#: The smallest excess over the null worth a claim (rate units: 5 percentage points).
MIN_EFFECT = 0.05
MIN_NULLS_T = 3  # the prediction t needs an SD on at least 2 degrees of freedom

ABOVE, BELOW, SMALL = "above the null", "below the null", "no excess ≥ 5 pp"
UNDECIDED, NOT_SHOWN, DESCRIPTIVE = "undecided", "not shown above the null", "descriptive"
#: The verdicts that claim something about the population (for calibration and the text).
CLAIMS = (ABOVE, BELOW, SMALL)
TEST_OF_RULE = {"raw": "prediction t", "sig": "permutation"}


#: relative tolerance under which a null statistic counts as equal to the observed: statistics
#: equal in exact arithmetic (rank means are often) can differ in the last bits with the
#: order they were summed in, and a tie must count as "at least as large"
TIE = 1e-12


def permutation_p(observed: float, null: np.ndarray) -> float:
    """(1 + #{null ≥ observed}) / (1 + P): the permutation p-value of P null replicates
    (a null within :data:`TIE` of the observed counts as a tie, so as at least as large)."""
    level = observed - TIE * max(1.0, abs(observed))
    return (1 + int((np.asarray(null) >= level).sum())) / (1 + len(null))


def min_nulls_permutation(alpha: float = ALPHA) -> int:
    """The fewest replicates with which the permutation p can reach ``alpha`` (19 at 0.05)."""
    return int(np.ceil(1 / alpha - 1 - 1e-9))


#: a rate over n̄ comparisons is treated as normal (no floor) when n̄·p(1−p) reaches this:
#: the usual condition for the normal approximation of a binomial
NORMAL_COUNT = 5.0


def binomial_floor(reversals: object, comparable: object) -> float:
    """The least SD to take between null replicates whose rates are too coarse for the
    prediction t's normal model: √(p(1−p)/n̄), p the replicates' pooled rate
    (Σ reversals + ½) / (Σ comparable + 1) and n̄ their mean number of comparable
    comparisons, when n̄·p(1−p) < :data:`NORMAL_COUNT`; 0 otherwise (the replicates' own
    spread is then the reference, smaller than the binomial SD when they share episodes)
    and without counts. ``reversals``, ``comparable``: one count per replicate."""
    k = np.asarray(reversals, float)
    n = np.asarray(comparable, float)
    ok = np.isfinite(k) & np.isfinite(n) & (n > 0)
    if not ok.any():
        return 0.0
    p = (k[ok].sum() + 0.5) / (n[ok].sum() + 1)
    if n[ok].mean() * p * (1 - p) >= NORMAL_COUNT:
        return 0.0
    return float(np.sqrt(p * (1 - p) / n[ok].mean()))


def prediction_test(observed: float, null: np.ndarray, *, alpha: float = ALPHA,
                    min_effect: float = MIN_EFFECT, floor: float = 0.0) -> dict:
    """The prediction t of ``observed`` against the finite ``null`` rates (module doc).

    Returns ``excess``, ``t``, ``df``, ``p_t`` (two-sided), ``ci_low``, ``ci_high`` (the
    deciding 1 − ``alpha`` interval of the excess) and ``verdict``; NaN and
    *undecided* with fewer than 3 replicates or no spread. ``floor``: the least SD between
    replicates to take (:func:`binomial_floor`).
    """
    null = np.asarray(null, float)
    null = null[np.isfinite(null)]
    p = null.size
    out = {"excess": observed - float(null.mean()) if p else np.nan, "t": np.nan,
           "df": max(p - 1, 0), "p_t": np.nan, "ci_low": np.nan, "ci_high": np.nan,
           "verdict": UNDECIDED}
    if p < MIN_NULLS_T or not np.isfinite(observed):
        return out
    scale = max(float(null.std(ddof=1)), floor) * np.sqrt(1 + 1 / p)
    if scale == 0:  # every replicate equal: no spread to judge an excess against
        return out
    t = out["excess"] / scale
    half = stats.t.ppf(1 - alpha / 2, p - 1) * scale
    low, high = out["excess"] - half, out["excess"] + half
    verdict = (ABOVE if low > 0 else BELOW if high < 0 else SMALL if high < min_effect
               else UNDECIDED)
    return {**out, "t": float(t), "p_t": float(2 * stats.t.sf(abs(t), p - 1)),
            "ci_low": float(low), "ci_high": float(high), "verdict": verdict}


def permutation_test(observed: float, null: np.ndarray, *, alpha: float = ALPHA,
                     floor: float = 0.0) -> dict:
    """The exact one-sided permutation test of ``observed`` against ``null`` (module doc):
    ``p_value``, ``n_null_above`` (replicates ≥ observed) and ``verdict``. Exact whatever
    the replicates' shape: ``floor`` is taken for a common signature and not used."""
    null = np.asarray(null, float)
    null = null[np.isfinite(null)]
    if not np.isfinite(observed) or null.size == 0:
        return {"p_value": np.nan, "n_null_above": 0, "verdict": UNDECIDED}
    p = permutation_p(observed, null)
    verdict = (ABOVE if p <= alpha else NOT_SHOWN if null.size >= min_nulls_permutation(alpha)
               else DESCRIPTIVE)
    return {"p_value": p, "n_null_above": int((null >= observed).sum()), "verdict": verdict}


def decide(observed: float, null: np.ndarray, rule: str, *, alpha: float = ALPHA,
           min_effect: float = MIN_EFFECT, floor: float = 0.0) -> dict:
    """Both tests of one rate and the verdict of the test its ``rule`` rests on
    (``TEST_OF_RULE``: the raw rule on the prediction t, the significant rule on the exact
    permutation). Every field of both tests is returned; ``verdict`` and ``test`` are the
    deciding one's; for the permutation rule the interval is the prediction t's, shown as
    a description only."""
    pred = prediction_test(observed, null, alpha=alpha, min_effect=min_effect, floor=floor)
    perm = permutation_test(observed, null, alpha=alpha)
    test = TEST_OF_RULE[rule]
    verdict = pred["verdict"] if test == "prediction t" else perm["verdict"]
    return {**pred, **perm, "verdict": verdict, "test": test}


def clopper_pearson(k: int, n: int, level: float = 0.95) -> tuple[float, float]:
    """The exact (Clopper–Pearson) interval of a binomial proportion k/n; (NaN, NaN) if n = 0."""
    if n == 0:
        return float("nan"), float("nan")
    a = 1 - level
    low = stats.beta.ppf(a / 2, k, n - k + 1) if k > 0 else 0.0
    high = stats.beta.ppf(1 - a / 2, k + 1, n - k) if k < n else 1.0
    return float(low), float(high)
