"""What would decide an undecided headline rate, from a model of the study's own curve.

The verdict of a raw rate rests on the prediction t (:mod:`.verdicts`):
t = δ / (s·√(1 + 1/P)), δ the excess over the mean of P null replicates and s their SD, at
S episode seed sets. Both δ and s change with S. The replicate curve (the same test on the
first 1, 2, … S₀ seed sets, :func:`.replicates.replicate_curve`) measures how: on the
default study s sits at its floor (a rate over a few hundred comparisons) while δ *grows*,
because noise flips leave the null faster than the observed pair. So the advice fits both
curves (:func:`fit_curve`, least squares on the curve's points; the forms are
``EXCESS_FORMS`` and ``SD_FORMS``, the one used is ``MODEL``, chosen by hold-out on one
study seed and confirmed on another: docs/analysis.md §8a) and predicts the t of a design
(S′, P′), centred at t̂ + ``HOLDOUT_BIAS``·d, d = log₂(S′/S₀) the doublings ahead (the
growth the constant form leaves out, measured a doubling ahead), with a 10–90 % interval
from Normal(centre, σ·max(1, d)), σ = ``HOLDOUT_SD`` (the model's hold-out errors on the
seed it was chosen on; the study's own hold-out error when larger). A verdict is decided
when t > t_crit, t < −t_crit, or the *no excess ≥ 5 pp* interval holds (t < 5 pp/(s·√(1 +
1/P′)) − t_crit), t_crit = t_{P′−1, 1−α/2} at the level each verdict is decided at. The
cheapest (S′ ≥ S₀, P′ ≥ P) whose chance of a decision reaches ``POWER``, the realized t
falling around the centre with a t's unit noise, is advised with its runs and minutes and
the interval. When no design within ``MAX_SEED_SETS`` and ``MAX_NULLS``
reaches it and the fitted excess still grows, the advice says the most those limits can
promise (never "nothing reachable" while the excess rises). A study with ≥ 3 seed sets
also reports its own hold-out: the t predicted at S₀ from the curve's first 2 points
beside the t it measured (:func:`holdout`).

The significant rule rests on the exact permutation test: it needs P ≥ 1/α − 1 to reach α
at all (19 at 0.05; 159 at 0.05/8), and can decide only while the observed exceeds every
replicate.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pandas as pd
from scipy import stats

from .verdicts import ALPHA, CLAIMS, MIN_EFFECT, min_nulls_permutation

POWER = 0.80
MAX_SEED_SETS = 20
MAX_NULLS = 99
#: an excess that rises by less (rate units per doubling of seed sets) counts as flat
RISING = 0.001
#: the predicted t's interval: its 10–90 % quantiles
INTERVAL = (0.10, 0.90)

#: δ(S) = a + c·g(S) for the forms of the excess (``constant``: δ at the largest fitted S)
EXCESS_FORMS: dict[str, Callable[[np.ndarray], np.ndarray] | None] = {
    "constant": None,
    "log": np.log,
    "root": np.sqrt,
    "saturating": lambda s: -1.0 / np.sqrt(s),
}
#: s(S): ``constant`` (s at the largest fitted S) or ``power`` (s ∝ S^−b, b ∈ [0, 1])
SD_FORMS = ("constant", "power")
#: the forms chosen on seed 0 by hold-out (docs/analysis.md §8a: `python
#: benchmarks/power_holdout.py evaluate … --fit 2 --target 4 --fit 4 --target 8`): on one
#: study's nested curve a fitted slope carries more noise than growth, so the constant
#: forms predict best (mean absolute error 1.55 in t; the growth forms 1.70–2.81)
MODEL = ("constant", "constant")
#: the chosen model's hold-out errors (measured − predicted t) there, a doubling ahead:
#: mean and SD over 10,080 (path, metric) predictions. The mean is the growth the
#: constant form leaves out
HOLDOUT_BIAS = 0.873
HOLDOUT_SD = 1.709


@dataclass(frozen=True)
class Costs:
    """Runs one more seed set or null replicate costs, for one comparison design.

    ``per_population``: runs of one population on one seed set (its episodes × the
    controllers and the no-robot baseline); ``observed``: observed populations;
    ``per_replicate``: populations one null replicate adds; ``runs_per_second``: the
    study's measured simulation throughput (NaN if unknown). Repeated identical runs are
    simulated once, so run counts are upper bounds.
    """

    per_population: float
    observed: int
    per_replicate: int
    runs_per_second: float = float("nan")

    def runs(self, s0: int, p0: int, s1: int, p1: int) -> float:
        """Runs from (S = s0, P = p0) to (s1, p1): the observed populations on the new seed
        sets, every replicate on every seed set it lacks."""
        return self.per_population * (self.observed * (s1 - s0)
                                      + self.per_replicate * (p1 * s1 - p0 * s0))


@dataclass(frozen=True)
class CurveFit:
    """δ(S) = a + c·g(S) and s(S) = s_ref·(S/s_at)^−b, fitted on the curve up to ``s_at``."""

    excess_form: str
    sd_form: str
    a: float
    c: float
    s_ref: float
    s_at: int
    b: float
    points: int
    #: the slope of the curve's excess on ln S (per e-fold of seed sets; 0 with one point):
    #: whether the excess still rises, whatever form predicts it
    rise: float = 0.0

    def excess(self, s: float) -> float:
        g = EXCESS_FORMS[self.excess_form]
        return self.a if g is None else float(self.a + self.c * g(np.asarray(s, float)))

    def sd(self, s: float) -> float:
        return float(self.s_ref * (s / self.s_at) ** (-self.b))

    def t(self, s: float, p: int) -> float:
        """The predicted t at ``s`` seed sets and ``p`` null replicates."""
        return self.excess(s) / (self.sd(s) * np.sqrt(1 + 1 / p))

    @property
    def growing(self) -> bool:
        """The excess still rises with seed sets on the curve (a least-squares line on
        ln S, at least ``RISING`` per doubling), whatever form predicts it."""
        return self.rise * np.log(2) >= RISING


def fit_curve(seed_sets: np.ndarray, excess: np.ndarray, sd: np.ndarray,
              model: tuple[str, str] = MODEL) -> CurveFit:
    """The forms ``model`` = (excess form, SD form) fitted on the curve's points (module
    doc). With one usable point (one seed set) both are constant: the curve cannot say
    how they move."""
    s = np.asarray(seed_sets, float)
    e, v = np.asarray(excess, float), np.asarray(sd, float)
    ok = np.isfinite(s) & np.isfinite(e) & np.isfinite(v) & (s > 0)
    s, e, v = s[ok], e[ok], v[ok]
    order = np.argsort(s)
    s, e, v = s[order], e[order], v[order]
    if s.size == 0:  # no point with an excess and a spread: nothing to fit
        return CurveFit("constant", "constant", np.nan, 0.0, np.nan, 1, 0.0, 0)
    e_form, v_form = model
    if np.unique(s).size < 2:
        e_form, v_form = "constant", "constant"
    g = EXCESS_FORMS[e_form]
    a, c = (float(e[-1]), 0.0) if g is None else _line(g(s), e)
    b = 0.0
    if v_form == "power":
        pos = v > 0
        if np.unique(s[pos]).size >= 2:
            b = float(np.clip(-np.polyfit(np.log(s[pos]), np.log(v[pos]), 1)[0], 0.0, 1.0))
    rise = _line(np.log(s), e)[1] if np.unique(s).size >= 2 else 0.0
    return CurveFit(e_form, v_form, a, c, float(v[-1]), int(s[-1]), b, int(s.size), rise)


def _line(x: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    """Intercept and slope of y on x (least squares)."""
    slope, icpt = np.polyfit(x, y, 1)
    return float(icpt), float(slope)


def sd_exponent(curve: pd.DataFrame) -> float:
    """b in s(S) ∝ S^−b, from one (comparison, metric, rule) of the replicate curve
    (``seed_sets``, ``null_sd``): least squares on log–log over the points with s > 0,
    clipped to [0, 1]; NaN with fewer than two such points."""
    c = curve[(curve["null_sd"] > 0) & np.isfinite(curve["null_sd"])]
    if c["seed_sets"].nunique() < 2:
        return float("nan")
    slope = np.polyfit(np.log(c["seed_sets"].to_numpy(float)),
                       np.log(c["null_sd"].to_numpy(float)), 1)[0]
    return float(np.clip(-slope, 0.0, 1.0))


@dataclass(frozen=True)
class Spread:
    """The realized t around the predicted one: Normal(t̂ + bias·d, sd·max(1, d)),
    d = log₂(S′/S₀) the doublings of seed sets ahead (module doc): the bias was measured
    a doubling ahead, and no seed set added adds none of it."""

    bias: float = HOLDOUT_BIAS
    sd: float = HOLDOUT_SD

    def shift(self, s1: float, s0: float) -> float:
        return self.bias * max(0.0, float(np.log2(s1 / s0)))

    def scale(self, s1: float, s0: float) -> float:
        return self.sd * max(1.0, float(np.log2(s1 / s0)))


def chance(fit: CurveFit, s1: int, p1: int, s0: int, spread: Spread, *,
           alpha: float = ALPHA, min_effect: float = MIN_EFFECT) -> float:
    """The chance that a design of ``s1`` seed sets and ``p1`` replicates decides the verdict
    (above, below, or no excess ≥ ``min_effect``) if the t it realizes falls around the
    model's centre with a t's own unit noise (§8's z_power). The model's uncertainty is
    the interval (:func:`t_interval`), not a chance: a wider one would otherwise raise
    the chance of a lucky draw and advise a design for it."""
    crit = stats.t.ppf(1 - alpha / 2, p1 - 1)
    sd = fit.sd(s1) * np.sqrt(1 + 1 / p1)
    if not (sd > 0):
        return float("nan")
    mid = fit.t(s1, p1) + spread.shift(s1, s0)
    w = 1.0
    small = min_effect / sd - crit  # t below this: the interval's top is under min_effect
    return float(min(1.0, stats.norm.sf((crit - mid) / w) + stats.norm.cdf((small - mid) / w)))


def t_interval(fit: CurveFit, s1: int, p1: int, s0: int, spread: Spread
               ) -> tuple[float, float, float]:
    """The predicted t at (``s1``, ``p1``) (the model's, shifted by the growth it leaves
    out) and its ``INTERVAL`` quantiles."""
    mid = fit.t(s1, p1) + spread.shift(s1, s0)
    z = stats.norm.ppf(INTERVAL) * spread.scale(s1, s0)
    return float(mid), float(mid + z[0]), float(mid + z[1])


def advise_prediction(fit: CurveFit, s0: int, p0: int, costs: Costs, *,
                      spread: Spread = Spread(), power: float = POWER,
                      min_effect: float = MIN_EFFECT, alpha: float = ALPHA) -> dict:
    """The cheapest (seed sets, null replicates) whose chance of deciding a raw rate
    reaches ``power`` (module doc), or what the limits can promise."""
    if p0 < 2:
        return {"limit": "cannot estimate (too few null replicates)"}
    if not (np.isfinite(fit.a) and np.isfinite(fit.s_ref)):
        return {"limit": "cannot estimate (no seed-set count with both an excess and a "
                         "null spread)"}
    if fit.s_ref == 0:
        return {"limit": "cannot estimate (every null replicate has the same rate)"}
    sets = range(s0, MAX_SEED_SETS + 1) if fit.points >= 2 else range(s0, s0 + 1)
    best = None
    for s1 in sets:
        for p1 in range(max(p0, 3), MAX_NULLS + 1):
            if chance(fit, s1, p1, s0, spread, alpha=alpha, min_effect=min_effect) >= power:
                cost = costs.runs(s0, p0, s1, p1)
                if best is None or cost < best[0]:
                    best = (cost, s1, p1)
                break  # more replicates at this S only cost more
    if best is None:
        return _unreachable(fit, s0, p0, sets[-1], costs, spread, power, alpha, min_effect)
    cost, s1, p1 = best
    limit = ("null replicates" if s1 == s0 else "seed sets" if p1 == p0 else
             "seed sets and null replicates")
    return {"limit": limit, **_design(fit, s0, p0, s1, p1, costs, spread, alpha, min_effect)}


def _design(fit: CurveFit, s0: int, p0: int, s1: int, p1: int, costs: Costs, spread: Spread,
            alpha: float, min_effect: float) -> dict:
    """A design's columns: its size, cost, predicted t with its interval and chance."""
    cost = costs.runs(s0, p0, s1, p1)
    t, low, high = t_interval(fit, s1, p1, s0, spread)
    return {"seed_sets_needed": s1, "nulls_needed": p1, "runs_needed": cost,
            "minutes_needed": cost / costs.runs_per_second / 60, "t_predicted": t,
            "t_low": low, "t_high": high, "excess_predicted": fit.excess(s1),
            "chance": chance(fit, s1, p1, s0, spread, alpha=alpha, min_effect=min_effect)}


def _unreachable(fit: CurveFit, s0: int, p0: int, s_max: int, costs: Costs, spread: Spread,
                 power: float, alpha: float, min_effect: float) -> dict:
    """No design within the limits reaches ``power``: while the fitted excess grows, the
    most the largest design promises; otherwise nothing reachable, and why."""
    if fit.growing:
        best = _design(fit, s0, p0, s_max, MAX_NULLS, costs, spread, alpha, min_effect)
        return {"limit": f"under {power:.0%} within the limits (the excess is still "
                         f"growing: {100 * fit.rise * np.log(2):+.1f} pp per doubling of "
                         "seed sets on the curve)", **best}
    if fit.points < 2:
        return {"limit": "nothing reachable with null replicates alone; with one seed set "
                         "the study cannot say how more would help (run ≥ 2)"}
    head = f"nothing reachable within {MAX_SEED_SETS} seed sets and {MAX_NULLS} null replicates"
    figures = (f"(the fitted excess does not grow: {100 * fit.excess(s0):+.1f} pp at {s0} "
               f"seed sets, null SD {100 * fit.sd(s0):.1f} pp)")
    # the null SD under which unlimited replicates could rule out min_effect (normal limit)
    needed = (min_effect - fit.excess(s0)) / stats.norm.ppf(1 - alpha / 2)
    if fit.sd(s0) > needed:
        return {"limit": f"{head}: ruling out an excess of {100 * min_effect:.0f} pp needs a "
                         f"null SD under {100 * max(needed, 0):.1f} pp even with unlimited "
                         f"null replicates, and the null's spread does not fall with seed "
                         f"sets by the model of this study's curve {figures}"}
    return {"limit": f"{head} {figures}"}


def holdout(curve: pd.DataFrame, p: int, model: tuple[str, str] = MODEL) -> dict:
    """A study's own hold-out for one (comparison, metric, rule) of its curve: the t the
    model predicts at the largest S₀ (≥ 3) from the points S = 1–2, the t measured there,
    and the error (measured − predicted); NaN with fewer than 3 seed sets."""
    none = {"holdout_at": np.nan, "holdout_predicted": np.nan, "holdout_t": np.nan,
            "holdout_error": np.nan}
    c = curve.sort_values("seed_sets")
    s0 = int(c["seed_sets"].max()) if not c.empty else 0
    fit_rows = c[c["seed_sets"] <= 2]
    if s0 < 3 or fit_rows["seed_sets"].nunique() < 2 or p < 2:
        return none
    fit = fit_curve(fit_rows["seed_sets"], fit_rows["excess"], fit_rows["null_sd"], model)
    last = c[c["seed_sets"] == s0].iloc[-1]
    actual = float(last["excess"]) / (float(last["null_sd"]) * np.sqrt(1 + 1 / p))
    predicted = fit.t(s0, p)
    return {"holdout_at": s0, "holdout_predicted": predicted, "holdout_t": actual,
            "holdout_error": actual - predicted}


def advise_permutation(row: pd.Series, costs: Costs, s0: int, *, alpha: float = ALPHA) -> dict:
    """The exact permutation test needs 1/``alpha`` − 1 replicates to reach ``alpha`` (19 at
    0.05), and can decide only while the observed rate is above every replicate."""
    need = min_nulls_permutation(alpha)
    p0 = int(row["n_null"])
    if int(row.get("n_null_above", 0)) > 0:
        return {"limit": "nothing reachable (a null replicate is at or above the observed)"}
    if p0 >= need:
        return {"limit": "nothing reachable"}
    cost = costs.runs(s0, p0, s0, need)
    return {"limit": "null replicates", "seed_sets_needed": s0, "nulls_needed": need,
            "runs_needed": cost, "minutes_needed": cost / costs.runs_per_second / 60}


ADVICE_COLUMNS = ("seed_sets_needed", "nulls_needed", "runs_needed", "minutes_needed",
                  "t_predicted", "t_low", "t_high", "excess_predicted", "chance")


def _curve_of(curve: pd.DataFrame | None, row: pd.Series) -> pd.DataFrame:
    """The curve points of one headline row, or the row alone (one point) without a curve."""
    if curve is not None and not curve.empty:
        c = curve[(curve["metric"] == row["metric"]) & (curve["rule"] == row["rule"])]
        if not c.empty:
            return c
    return pd.DataFrame([{"seed_sets": row["seed_sets"], "excess": row["excess"],
                          "null_sd": row["null_sd"]}])


def design_advice(headline: pd.DataFrame, curve: pd.DataFrame | None, costs: Costs, *,
                  power: float = POWER, alpha: float = ALPHA,
                  model: tuple[str, str] = MODEL) -> pd.DataFrame:
    """Per headline row (one comparison design): its verdict and, where undecided, what
    limits it and the cheapest design that would decide it at ``alpha`` (the level each
    verdict is decided at: the table's share, :func:`.nulls.family_verdicts`; module doc).
    Columns added: ``limit``, the fitted model (``excess_form``, ``excess_slope``,
    ``sd_exponent``), the design (``ADVICE_COLUMNS``: NaN where nothing is advised) and
    the study's own hold-out (:func:`holdout`; ``holdout_*``)."""
    curves = [_curve_of(curve, r) for _, r in headline.iterrows()]
    holds = [holdout(c, int(r["n_null"]), model) if r["rule"] == "raw" else holdout(c.iloc[:0], 0)
             for c, (_, r) in zip(curves, headline.iterrows(), strict=True)]
    errors = np.array([h["holdout_error"] for h in holds], float)
    errors = errors[np.isfinite(errors)]
    own = float(np.sqrt(np.mean(errors ** 2))) if errors.size else 0.0
    spread = Spread(HOLDOUT_BIAS, max(HOLDOUT_SD, own))
    rows = []
    for (_, r), c, h in zip(headline.iterrows(), curves, holds, strict=True):
        s0 = int(r["seed_sets"])
        fit = fit_curve(c["seed_sets"], c["excess"], c["null_sd"], model)
        if r["verdict"] in CLAIMS:
            adv = {"limit": "decided"}
        elif r["test"] == "permutation":
            adv = advise_permutation(r, costs, s0, alpha=alpha)
        else:
            adv = advise_prediction(fit, s0, int(r["n_null"]), costs, spread=spread,
                                    power=power, alpha=alpha)
        rows.append({**dict.fromkeys(ADVICE_COLUMNS, np.nan), **adv,
                     "excess_form": fit.excess_form, "excess_slope": fit.c,
                     "sd_exponent": sd_exponent(c) if len(c) > 1 else np.nan,
                     "spread_sd": spread.sd, **h})
    return pd.concat([headline.reset_index(drop=True), pd.DataFrame(rows)], axis=1)
