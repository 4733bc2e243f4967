"""Respondent audit, the power of each check: the smallest effect it could detect at this
number of personas (and samples), against the effect a usable respondent shows.

A check that fails says something only when it could have passed: a respondent that
follows the persona, asked too few personas, fails the sensitivity test as surely as
one that does not. Each check's **smallest detectable effect** (``mde``) is the true
effect it detects with probability :data:`POWER` at the audit's size, by the usual
normal-theory approximations of the test it runs; the check is **powered** when that is
at most the effect a usable respondent shows (:data:`USABLE`, declared below, not
fitted), and ``needs`` is the size at which it would be. A failure of an unpowered check
makes the verdict "not enough personas to tell (needs ≈ N)", never "weak".

* Sensitivity (R² on the persona fields, ``columns`` of them, against the shuffled null
  at p ≤ α / family and an excess of at least ``min_excess``): the F test of a linear
  regression, whose statistic follows a non-central F with non-centrality
  n · ρ² / (1 − ρ²) for a population R² ρ² (Cohen 1988, ch. 9); the permutation test
  approximates it.
* Expected direction (Spearman ρ, 95 % interval excluding 0): Fisher's z of ρ with
  variance 1.06 / (n − 3) (Fieller, Hartley & Pearson 1957).
* Manipulation (the mean deadline − baseline urgency shift of m matched personas at least
  half a level, its 95 % interval above 0): a normal mean with the observed standard
  deviation of the paired shifts.
* Test–retest (ICC(1) of n records × k samples at least :data:`~.audit_verdict.MIN_ICC`):
  MSB / MSW follows (1 + kρ/(1 − ρ)) · F(n − 1, n(k − 1)) for a true ICC ρ (Shrout &
  Fleiss 1979).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from scipy import stats

#: the probability with which a check must detect a usable respondent's effect
POWER = 0.8
_Z_POWER = float(stats.norm.ppf(POWER))
_Z_95 = float(stats.norm.ppf(0.975))
#: the effects a usable respondent shows, per check: Cohen's (1988) medium effects for
#: a regression (f² = 0.15, R² = 0.13) and a correlation (0.3); one level of the block
#: (0.25) for the deadline's shift of urgency; Koo & Li's (2016) "good" reliability
USABLE: dict[str, float] = {"sensitivity": 0.15 / 1.15, "direction": 0.3,
                            "manipulation": 0.25, "retest": 0.75}
#: the largest size searched for ``needs`` (a check that needs more is "not measurable")
MAX_SIZE = 1_000_000


def r2_power(r2: float, n: int, columns: int, alpha: float, min_excess: float) -> float:
    """Probability that the sensitivity test finds a target of population R² ``r2``
    persona-sensitive among ``n`` personas and ``columns`` persona-field columns."""
    d2 = n - columns - 1
    if d2 <= 0 or columns <= 0:
        return 0.0
    cut = max(float(stats.beta.ppf(1 - alpha, columns / 2, d2 / 2)),
              columns / (n - 1) + min_excess)
    if cut >= 1:
        return 0.0
    f_cut = (cut / columns) / ((1 - cut) / d2)
    return float(stats.ncf.sf(f_cut, columns, d2, n * r2 / (1 - r2)))


def _smallest(power: Callable[[float], float], top: float) -> float:
    """The smallest effect in (0, ``top``] detected with :data:`POWER` (power grows with
    the effect); NaN when even ``top`` is not."""
    if power(top) < POWER:
        return math.nan
    low, high = 0.0, top
    for _ in range(40):
        mid = (low + high) / 2
        low, high = (low, mid) if power(mid) >= POWER else (mid, high)
    return high


def _needs(powered: Callable[[int], bool], start: int) -> int | None:
    """The smallest size from ``start`` at which ``powered(size)`` (monotone); None beyond
    :data:`MAX_SIZE`."""
    high = max(start, 2)
    while not powered(high):
        if high >= MAX_SIZE:
            return None
        high = min(2 * high, MAX_SIZE)
    low = start - 1
    while high - low > 1:
        mid = (low + high) // 2
        low, high = (low, mid) if powered(mid) else (mid, high)
    return high


def sensitivity_mde(n: int, columns: int, alpha: float, min_excess: float) -> float:
    """Smallest population R² the sensitivity test detects (NaN: none below 0.999)."""
    return _smallest(lambda r2: r2_power(r2, n, columns, alpha, min_excess), 0.999)


def sensitivity_needs(columns: int, alpha: float, min_excess: float) -> int | None:
    """Personas at which the sensitivity test detects a usable respondent's R²."""
    usable = USABLE["sensitivity"]
    return _needs(lambda n: r2_power(usable, n, columns, alpha, min_excess) >= POWER,
                  columns + 2)


def rho_mde(n: int) -> float:
    """Smallest |Spearman ρ| whose 95 % interval excludes 0 with :data:`POWER`."""
    return math.tanh((_Z_95 + _Z_POWER) * math.sqrt(1.06 / (n - 3))) if n > 3 else math.nan


def rho_needs() -> int:
    """Personas at which an expected direction of a usable size is seen."""
    z = math.atanh(USABLE["direction"])
    return math.ceil(3 + 1.06 * ((_Z_95 + _Z_POWER) / z) ** 2)


def shift_mde(sd: float, m: int, least: float) -> float:
    """Smallest true mean shift that passes (observed shift ≥ ``least``, 95 % interval
    above 0) with :data:`POWER`, for paired shifts of standard deviation ``sd`` over
    ``m`` matched personas."""
    if m < 2 or not np.isfinite(sd):
        return math.nan
    se = sd / math.sqrt(m)
    return max(least, _Z_95 * se) + _Z_POWER * se


def shift_needs(sd: float, least: float) -> int | None:
    """Matched personas at which a usable shift passes."""
    if not np.isfinite(sd):
        return None
    return _needs(lambda m: shift_mde(sd, m, least) <= USABLE["manipulation"], 2)


def icc_power(icc: float, n: int, k: int, least: float) -> float:
    """Probability that the ICC(1) of ``n`` records × ``k`` samples reaches ``least``
    when the true ICC is ``icc``."""
    if n < 2 or k < 2 or icc >= 1:
        return 1.0 if icc >= 1 else 0.0
    cut = (1 + (k - 1) * least) / (1 - least)  # MSB / MSW at which the estimate is least
    theta = 1 + k * icc / (1 - icc)
    return float(stats.f.sf(cut / theta, n - 1, n * (k - 1)))


def icc_mde(n: int, k: int, least: float) -> float:
    """Smallest true ICC that test–retest finds at least ``least`` with :data:`POWER`."""
    return _smallest(lambda icc: icc_power(icc, n, k, least), 0.999)


def icc_needs(k: int, least: float) -> int | None:
    """Records (× ``k`` samples) at which a usable reliability passes."""
    return _needs(lambda n: icc_power(USABLE["retest"], n, k, least) >= POWER, 2)
