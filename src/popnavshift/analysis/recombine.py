"""Null designs recombined unit by unit: the exact randomization reference of a comparison
whose null is made of several independently drawn units.

A comparison's null replicate is built from *units* (:class:`.nulls.Design` ``units``): a
size-matched subset standing in for one population, in every pair it is in; both arms of a
swap permutation. Units are drawn independently of one another, so a design that takes each
unit's populations from one index of a pool — the tested design and its null replicates —
drawn uniformly and independently per unit, is a null design too. Under the null every
unit's draws are exchangeable across the pool, so the tested design is exchangeable with
its recombinations (the per-unit relabelling group: Hemerik & Goeman 2018, exact with the
tested design among R random elements): p = (1 + #{S_r ≥ S₀}) / (1 + R) is exact whatever
the shape of the statistic S's distribution.

:class:`Recombination` draws the designs and names the population pair each design puts
in each slot; :class:`RecombinedRates` is the reference of the raw reversal rate
(:mod:`.nulls`); the interaction test's (:class:`.interaction.Recombined`) shares the draws.
Definitions and the measured calibration: ``docs/analysis.md`` §10 and §12.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from .reversals import tie_sign
from .significance import Orderings
from .verdicts import ABOVE, BELOW, MIN_EFFECT, SMALL, UNDECIDED, permutation_p

#: recombined designs each randomization test draws: its p is at least 1/(DRAWS + 1), and
#: its Monte-Carlo SD at p = 0.005 is 0.0005 (a tenth of the headline's level; 999 draws
#: left 0.002, enough for a seeded p near the level to read otherwise under another seed)
DRAWS = 19_999
#: how a row's p was computed: against recombined designs, or by the prediction t
RECOMBINED = "recombined designs"
PREDICTION = "prediction t"


class Recombination:
    """The designs of a comparison (``groups``: the tested pairs, then one list of pairs per
    null replicate, all of the same length Π) and its ``units`` (two per pair: the unit of
    each population), over the populations ``populations`` (an :class:`Orderings`' order).
    """

    def __init__(self, populations: Sequence[str], groups: Sequence[Sequence[tuple[str, str]]],
                 units: Sequence[int]) -> None:
        index = {p: i for i, p in enumerate(populations)}
        self.n_populations = len(populations)
        self.pa = np.array([[index[a] for a, _ in g] for g in groups])  # (K, Π)
        self.pb = np.array([[index[b] for _, b in g] for g in groups])
        u = np.asarray(units, int)
        self.u0, self.u1 = u[0::2], u[1::2]
        self.n_units = int(u.max()) + 1

    def keys(self, designs: np.ndarray) -> np.ndarray:
        """(R, Π) the population pair (a · n + b, n populations) each design of ``designs``
        (R, units: each unit's design index) puts in each slot."""
        pi = np.arange(self.pa.shape[1])
        return (self.pa[designs[:, self.u0], pi] * self.n_populations
                + self.pb[designs[:, self.u1], pi])

    def own(self, k: int | np.ndarray) -> np.ndarray:
        """(len(k), units) designs ``k`` themselves, every unit from its own index."""
        return np.repeat(np.atleast_1d(k)[:, None], self.n_units, axis=1)

    def draws(self, tested: int, pool: Sequence[int] | np.ndarray, *, draws: int,
              seed: Sequence[int]) -> np.ndarray:
        """(1 + ``draws``, units): design ``tested`` itself, then ``draws`` designs recombined
        from it and ``pool`` (design indices), each unit's index drawn uniformly."""
        idx = np.array([tested, *pool])
        picks = np.random.default_rng(list(seed)).integers(len(idx),
                                                           size=(draws, self.n_units))
        return idx[np.vstack([np.zeros((1, self.n_units), int), picks])]


class RecombinedRates:
    """The raw reversal rate (the paper's tie rule, pooled over a design's pairs) of
    recombined designs of one metric's orderings ``o``; each population pair's counts are
    computed once and reused by every design and placebo that draws it."""

    def __init__(self, o: Orderings, groups: Sequence[Sequence[tuple[str, str]]],
                 units: Sequence[int]) -> None:
        self.rec = Recombination(o.populations, groups, units)
        self.signs = tie_sign(o.diff, o.tolerance)  # (P, U, C)
        self.cache: dict[int, tuple[int, int]] = {}

    def _counts(self, keys: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        n = self.rec.n_populations
        uniq, inv = np.unique(keys, return_inverse=True)
        for i in range(0, len(uniq), 256):
            new = [k for k in uniq[i:i + 256].tolist() if k not in self.cache]
            if not new:
                continue
            k = np.array(new)
            prod = self.signs[k // n] * self.signs[k % n]
            rev = (prod == -1).sum(axis=(1, 2))
            comp = (np.abs(prod) == 1).sum(axis=(1, 2))
            self.cache.update(zip(new, zip(rev.tolist(), comp.tolist(), strict=True),
                                  strict=True))
        c = np.array([self.cache[k] for k in uniq.tolist()], np.int64).reshape(-1, 2)
        inv = inv.reshape(keys.shape)
        return c[inv, 0].sum(axis=1), c[inv, 1].sum(axis=1)

    def rates(self, designs: np.ndarray) -> np.ndarray:
        """(R,) the pooled raw reversal rate of each design (NaN without a comparable
        comparison)."""
        rev, comp = self._counts(self.rec.keys(designs))
        with np.errstate(all="ignore"):
            return np.where(comp > 0, rev / np.where(comp > 0, comp, 1), np.nan)

    def reference(self, tested: int, pool: Sequence[int] | np.ndarray, *, draws: int = DRAWS,
                  seed: Sequence[int]) -> tuple[float, np.ndarray]:
        """The rate of design ``tested`` and the finite rates of ``draws`` designs
        recombined from it and ``pool``."""
        r = self.rates(self.rec.draws(tested, pool, draws=draws, seed=seed))
        ref = r[1:]
        return float(r[0]), ref[np.isfinite(ref)]


def tail_ps(rate: float, ref: np.ndarray, shift: float = 0.0) -> tuple[float, float]:
    """(p↑, p↓) of ``rate`` + ``shift`` against the recombined rates ``ref``: (1 + #{R_r ≥
    R}) / (1 + R) and (1 + #{R_r ≤ R}) / (1 + R), a tie counting as at least as extreme."""
    if not np.isfinite(rate) or ref.size == 0:
        return np.nan, np.nan
    x = rate + shift
    return permutation_p(x, ref), permutation_p(-x, -ref)


#: the randomization p-values of a recombined placebo (:func:`tail_ps`), by column of the
#: null replicates' table: (which tail, 0 p↑ or 1 p↓; the shift added to the placebo's rate)
PLACEBO_PS: dict[str, tuple[int, float]] = {
    "placebo_p_above": (0, 0.0), "placebo_p_below": (1, 0.0),
    "placebo_p_above_5pp": (0, MIN_EFFECT), "placebo_p_below_5pp": (1, MIN_EFFECT),
    "placebo_p_above_10pp": (0, 2 * MIN_EFFECT)}


#: the column of :data:`PLACEBO_PS` by (tail, shift rounded to 1e-9)
_PS_COLUMN = {(side, round(at, 9)): c for c, (side, at) in PLACEBO_PS.items()}


def placebo_ps(row: Mapping[str, float], shift: float) -> tuple[float, float, float]:
    """(p↑, p↓, p₅) of a placebo's rate shifted by ``shift``, from its row's
    :data:`PLACEBO_PS` (p₅ is the p↓ of the shifted rate less 5 pp; NaN where not kept)."""

    def get(side: int, at: float) -> float:
        c = _PS_COLUMN.get((side, round(at, 9)))
        return float(row[c]) if c is not None and c in row else np.nan

    return get(0, shift), get(1, shift), get(1, shift - MIN_EFFECT)


def order_level(ref: np.ndarray, a: float) -> tuple[float, float]:
    """(q↑, q↓): the recombined rates a tested rate must exceed (lie under) for its one-sided
    p to reach ``a`` — the (k + 1)-th largest and smallest of ``ref``, k = ⌊a (R + 1)⌋ − 1
    (p = (1 + #{R_r ≥ R})/(1 + R) ≤ a ⇔ at most k of them at or above R). NaN when a is
    below 1/(R + 1)."""
    k = int(np.floor(a * (ref.size + 1) + 1e-9)) - 1
    if k < 0 or ref.size == 0:
        return np.nan, np.nan
    s = np.sort(ref)
    return float(s[-1 - k]), float(s[k])


def recombined_verdict(up: float, down: float, small: float, a: float) -> str:
    """The verdict of one-sided randomization p-values at one-sided level ``a``: *above
    the null* when p↑ ≤ a, else *below the null* when p↓ ≤ a, else *no excess ≥ 5 pp*
    when p₅ ≤ a, else *undecided*."""
    return (UNDECIDED if not np.isfinite(up) else ABOVE if up <= a else
            BELOW if down <= a else SMALL if small <= a else UNDECIDED)


def recombined_interval(rate: float, ref: np.ndarray | None, alpha: float) -> dict:
    """``ci_low``, ``ci_high``: the test inverted under a shift at two-sided ``alpha``,
    [R − q↑, R − q↓] (:func:`order_level`); NaN without the recombined rates ``ref``."""
    q_up, q_down = (np.nan, np.nan) if ref is None else order_level(ref, alpha / 2)
    return {"ci_low": rate - q_up, "ci_high": rate - q_down}


def recombined_decide(rate: float, ref: np.ndarray, *, null_mean: float, alpha: float,
                      min_effect: float = MIN_EFFECT) -> dict:
    """The raw rule's verdict on ``rate`` against its recombined reference ``ref`` at
    two-sided ``alpha`` (docs/analysis.md §10): :func:`recombined_verdict` of p↑, p↓ and p₅
    (the p↓ of the rate less ``min_effect``) at α/2, with :func:`recombined_interval`.
    ``excess`` stays the rate less ``null_mean`` (the study's replicates'); ``p_t`` is the
    two-sided p, min(1, 2·min(p↑, p↓)). The prediction t's ``t`` and ``df`` are left to the
    caller (they describe the excess on the replicates' spread)."""
    up, down = tail_ps(rate, ref)
    small = tail_ps(rate, ref, -min_effect)[1]
    return {"excess": rate - null_mean,
            "p_t": min(1.0, 2 * min(up, down)) if np.isfinite(up) else np.nan,
            **recombined_interval(rate, ref, alpha),
            "verdict": recombined_verdict(up, down, small, alpha / 2),
            "p_above": up, "p_below": down, "p_small": small, "test": RECOMBINED}
