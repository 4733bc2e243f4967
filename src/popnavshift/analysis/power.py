"""What would decide an undecided headline rate, from the study's own data, and its cost.

The verdict of a raw rate rests on the prediction t (:mod:`.verdicts`): its interval's
half-width is t_{P−1, 0.975} · s · √(1 + 1/P), s the SD between the P null replicates at
S episode seed sets. Two things narrow it: more null replicates (P: the t quantile and
√(1 + 1/P) fall, s does not) and more seed sets (S: s falls — by how much is *measured*
on the replicate curve, the same test on the first 1, 2, … S seed sets, by a least-squares
fit of log s on log S; never assumed to be 1/√S: a rate over at most a few hundred
comparisons has a floor). Assuming the excess stays at its estimate δ, the verdict is
decided with probability ``power`` once

    s(S′) · √(1 + 1/P′) · (t_{P′−1, 0.975} + z_power) ≤ max(|δ|, 5 pp − δ),

the first term on the right deciding *above* or *below the null*, the second *no excess
≥ 5 pp* (the same two-sided interval as the verdict, at the level the headline's
multiplicity control gives each verdict: t_{P′−1, 1−α/(2m)} for a table of m rates). The
cheapest (S′ ≥ S, P′ ≥ P) that meets it is advised, with its runs and minutes; when
nothing within ``MAX_SEED_SETS`` and ``MAX_NULLS`` meets it, or the study ran one seed set
(the curve cannot say how s falls) and more replicates alone cannot, the advice says so
instead of naming a number. Two assumptions are stated, not checked: the excess stays at
its estimate (raw rates include near-ties that thin out with more episodes), and b, fitted
on 2–4 nested points each from P replicates, is itself noisy.

The significant rule rests on the exact permutation test: it needs P ≥ 1/α − 1 to reach α
at all (19 at 0.05; 159 at 0.05/8), and can decide only while the observed exceeds every
replicate.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd
from scipy import stats

from .verdicts import ALPHA, CLAIMS, MIN_EFFECT, min_nulls_permutation

POWER = 0.80
MAX_SEED_SETS = 20
MAX_NULLS = 99


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


def half_scale(p: int, power: float = POWER, alpha: float = ALPHA) -> float:
    """√(1 + 1/P) · (t_{P−1, 1−α/2} + z_power): the multiple of s the decision needs."""
    return float(np.sqrt(1 + 1 / p) * (stats.t.ppf(1 - alpha / 2, p - 1) + stats.norm.ppf(power)))


def advise_prediction(excess: float, sd: float, s0: int, p0: int, b: float, costs: Costs, *,
                      power: float = POWER, min_effect: float = MIN_EFFECT,
                      alpha: float = ALPHA) -> dict:
    """The cheapest (seed sets, null replicates) that decides a raw rate (module doc)."""
    target = max(abs(excess), min_effect - excess)
    if not (np.isfinite(excess) and np.isfinite(sd) and p0 >= 2):
        return {"limit": "cannot estimate (too few null replicates)"}
    if sd == 0:
        return {"limit": "cannot estimate (every null replicate has the same rate)"}
    s_range = range(s0, MAX_SEED_SETS + 1) if np.isfinite(b) else range(s0, s0 + 1)
    best = None
    for s1 in s_range:
        sd1 = sd * (s1 / s0) ** (-b) if np.isfinite(b) else sd
        for p1 in range(max(p0, 3), MAX_NULLS + 1):
            if sd1 * half_scale(p1, power, alpha) <= target:
                cost = costs.runs(s0, p0, s1, p1)
                if best is None or cost < best[0]:
                    best = (cost, s1, p1)
                break  # more replicates at this S only cost more
    if best is None:
        ratio = f"the decisive margin is {target / sd:.1f} null SDs"
        fall = (f"the null's SD falls as S^−{b:.2f}" if b >= 0.05 else
                f"the null's SD does not fall with seed sets on this study's curve, b = {b:.2f}")
        why = (f"nothing reachable within {MAX_SEED_SETS} seed sets and {MAX_NULLS} null "
               f"replicates ({ratio}; {fall})" if np.isfinite(b) else
               f"nothing reachable with null replicates alone ({ratio}); with one seed set the "
               "study cannot say how more would help (run ≥ 2)")
        return {"limit": why}
    cost, s1, p1 = best
    limit = ("null replicates" if s1 == s0 else "seed sets" if p1 == p0 else
             "seed sets and null replicates")
    return {"limit": limit, "seed_sets_needed": s1, "nulls_needed": p1, "runs_needed": cost,
            "minutes_needed": cost / costs.runs_per_second / 60}


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


def design_advice(headline: pd.DataFrame, curve: pd.DataFrame | None, costs: Costs, *,
                  power: float = POWER, alpha: float = ALPHA) -> pd.DataFrame:
    """Per headline row (one comparison design): its verdict and, where undecided, what
    limits it and the cheapest design that would decide it at ``alpha`` (the level each
    verdict is decided at: the table's share, :func:`.nulls.family_verdicts`; module doc).
    Columns added:
    ``limit``, ``sd_exponent``, ``seed_sets_needed``, ``nulls_needed``, ``runs_needed``,
    ``minutes_needed`` (NaN where nothing is advised)."""
    rows = []
    for _, r in headline.iterrows():
        s0 = int(r["seed_sets"])
        c = (curve[(curve["metric"] == r["metric"]) & (curve["rule"] == r["rule"])]
             if curve is not None and not curve.empty else pd.DataFrame())
        b = sd_exponent(c) if not c.empty else float("nan")
        if r["verdict"] in CLAIMS:
            adv = {"limit": "decided"}
        elif r["test"] == "permutation":
            adv = advise_permutation(r, costs, s0, alpha=alpha)
        else:
            adv = advise_prediction(float(r["excess"]), float(r["null_sd"]), s0,
                                    int(r["n_null"]), b, costs, power=power, alpha=alpha)
        rows.append({"seed_sets_needed": np.nan, "nulls_needed": np.nan, "runs_needed": np.nan,
                     "minutes_needed": np.nan, **adv, "sd_exponent": b})
    return pd.concat([headline.reset_index(drop=True), pd.DataFrame(rows)], axis=1)
