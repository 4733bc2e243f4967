"""Calibration: each verdict rule's false-positive rate, measured on the study's own nulls.

A *placebo* takes one null replicate as if it were the observed population pairs and
the study's other replicates as its null (same episodes, slots, controllers and
design; P − 1 replicates). Its truth is known — no population effect — so every claim a
rule makes on a placebo is a false positive. Per rule and claim:

* **prediction t** (raw rule): claims an effect (above or below the null; nominal 5 %),
  claims *above the null* (2.5 %); and, on the placebo shifted up by 5 pp — a true excess
  of exactly 5 pp — claims *no excess ≥ 5 pp* (2.5 %). Its power is read off placebos
  shifted by 5 and 10 pp;
* **recombined designs** (the raw rule where the null has several units, across the
  population pairs: :mod:`.recombine`): the prediction t's claims, each made from the
  placebo's own randomization p-values (computed with the null replicates' table, against
  designs recombined from the placebo and the replicates it is judged against);
* **exact permutation** (significant rule): claims *above the null* (5 %; exact by
  construction — with P − 1 replicates it can reach 0.05 only when P ≥ 20, so a study
  with fewer has no placebo for it, and says so);
* **crossover test**: any crossover surviving the table's control between the two
  populations of a null replicate that hold the same personas (the arms of a swap
  permutation; 5 %). Those of any other null kind (size-matched subsets: one random persona
  and hundreds may truly order controllers differently) are no placebo for it, so their
  crossovers are reported as a diagnostic; each kind names its claim
  (:data:`popnavshift.populations.identity.NULL_KINDS`);
* **interaction test** (:mod:`.interaction`): replicate j as the observed against the
  other replicates (ranks recomputed among them); a claim that controller differences
  change more than under the null at the level its table decides at (0.05/m) and at 5 %;
* diagnostic, no verdict rests on it: the **episode-only interval** of the excess excludes
  0 (nominal 5 % if it were a test against the null; it is not: it holds the replicates
  fixed).

* **the headline table as a whole**, as the report decides it (every raw rate at α/m,
  Bonferroni over its m rates): placebo j takes replicate j of every comparison as the
  observed; any rate called above or below the null is a false claim (nominal 5 %), and
  on the placebo shifted by +5 pp any *no excess ≥ 5 pp* (2.5 %). Its placebos are the
  replicate indices, so there are few: it is the check of what the report's first
  paragraph claims together.

*At the study's own design* (``null_size``: ``popnavshift calibrate --replicates N`` runs
more replicates than the study judges against): placebo j is judged against the
``null_size`` replicates after it, cyclically (j + 1, …, j + ``null_size`` mod N), not all
N − 1 others — the rule as the study deploys it, on N placebos instead of P.

Each rate has its exact (Clopper–Pearson) 95 % interval. ``within``: its lower end is at
or below the nominal level (the data are consistent with a calibrated rule); ``status``:
*within* when, besides, its upper end is at most twice the nominal level, *above nominal*
when its lower end is above it, and *too few placebos to tell* otherwise. Placebos of one
study share replicates and episodes (and the pooled rows pool correlated metrics), so they
are not independent draws, and leave-one-out placebos are exchangeable by construction:
they check the tests' distributional assumptions, not whether the observed populations
are fair draws from the null (that is the null's construction, docs/analysis.md §7). The
synthetic studies of the test suite, with many independent replicates, are the stricter
check.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
import pandas as pd

from ..populations.identity import NULL_KINDS
from .recombine import RECOMBINED, placebo_ps, recombined_verdict
from .verdicts import (
    ABOVE,
    ALPHA,
    BELOW,
    MIN_EFFECT,
    MIN_NULLS_T,
    SMALL,
    binomial_floor,
    clopper_pearson,
    min_nulls_permutation,
    permutation_test,
    prediction_test,
)


@dataclass(frozen=True)
class Test:
    """A verdict rule's test: its ``name`` in the tables, its function of (a rate, the null
    replicates' rates) returning a dict with the ``verdict``, and the fewest null replicates
    with which it can claim anything (a placebo with fewer other replicates says nothing of
    its false-positive rate)."""

    name: str
    decide: Callable[..., dict]  # (rate, null rates, *, floor) → dict with ``verdict``
    min_nulls: int


PREDICTION_T = Test("prediction t", prediction_test, MIN_NULLS_T)
PERMUTATION = Test("exact permutation", permutation_test, min_nulls_permutation())


class Check(NamedTuple):
    """One claim of a verdict rule measured on placebos: its test, the rate rule it decides
    (``raw`` or ``sig``), the claim, its kind (false positive or power), the nominal rate,
    the shift added to the placebo's rate and whether a verdict makes the claim."""

    test: Test
    rule: str
    claim: str
    kind: str
    nominal: float
    shift: float
    made: Callable[[dict], bool]


CHECKS: tuple[Check, ...] = (
    Check(PREDICTION_T, "raw", "an effect (above or below)", "false positive", ALPHA,
          0.0, lambda d: d["verdict"] in (ABOVE, BELOW)),
    Check(PREDICTION_T, "raw", "above the null", "false positive", ALPHA / 2, 0.0,
          lambda d: d["verdict"] == ABOVE),
    Check(PREDICTION_T, "raw", "no excess ≥ 5 pp, at +5 pp", "false positive", ALPHA / 2,
          MIN_EFFECT, lambda d: d["verdict"] == SMALL),
    Check(PREDICTION_T, "raw", "above the null, at +5 pp", "power", np.nan, MIN_EFFECT,
          lambda d: d["verdict"] == ABOVE),
    Check(PREDICTION_T, "raw", "above the null, at +10 pp", "power", np.nan,
          2 * MIN_EFFECT, lambda d: d["verdict"] == ABOVE),
    Check(PERMUTATION, "sig", "above the null", "false positive", ALPHA, 0.0,
          lambda d: d["verdict"] == ABOVE),
)
#: every test of :data:`CHECKS`, by name
TESTS: dict[str, Test] = {c.test.name: c.test for c in CHECKS}
#: the crossover claims that are false positives: between populations of the same personas
#: (swap arms); any other null kind's populations (subsets of different sizes: one persona
#: against hundreds) may truly order controllers differently, so a crossover there is only
#: reported
FALSE_CROSSOVERS = frozenset(k.crossover for k in NULL_KINDS.values() if k.same_personas)
COLUMNS = ["comparison", "test", "rule", "claim", "kind", "nominal", "placebos", "claims",
           "rate", "cp_low", "cp_high", "within", "status"]
FAMILY_EFFECT = "any rate above or below the null"
FAMILY_SMALL = "any 'no excess ≥ 5 pp', at +5 pp"


def placebo_nulls(n: int, j: int, size: int | None = None) -> np.ndarray:
    """The positions of the replicates placebo ``j`` of ``n`` is judged against: every other
    one (leave-one-out), or, with ``size`` < n − 1, the ``size`` after it cyclically — the
    study's own design on more placebos (module doc)."""
    if size is None or size >= n - 1:
        return np.delete(np.arange(n), j)
    return (j + 1 + np.arange(size)) % n


def placebos(null_rates: pd.DataFrame, null_sizes: Mapping[str, int] | None = None
             ) -> pd.DataFrame:
    """Every (check, comparison, metric, replicate) placebo of ``null_rates`` (one row per
    null replicate and rule: ``comparison, metric, rule, replicate, rate``) with whether the
    check's claim was made (``claim_made``); ``null_sizes``: the replicates each
    comparison's placebo is judged against (:func:`placebo_nulls`; default all others)."""
    rows = []
    for (comp, metric, rule), g in null_rates.groupby(["comparison", "metric", "rule"],
                                                      sort=False):
        if recombined(g):
            rows += _recombined_placebos(g, comp, metric)
            continue
        rates = g["rate"].to_numpy(float)
        size = (null_sizes or {}).get(comp)
        for check in CHECKS:
            if check.rule != rule or min(len(rates) - 1, size or len(rates)) < \
                    check.test.min_nulls:
                continue  # with so few other replicates the rule can never claim anything
            for j in range(len(rates)):
                if not np.isfinite(rates[j]):
                    continue
                rest = placebo_nulls(len(rates), j, size)
                d = check.test.decide(rates[j] + check.shift, rates[rest],
                                      floor=_floor_of(g, rest))
                rows.append({"comparison": comp, "metric": metric, "test": check.test.name,
                             "rule": rule, "claim": check.claim,
                             "replicate": int(g["replicate"].iloc[j]),
                             "claim_made": bool(check.made(d))})
    return pd.DataFrame(rows)


def recombined(g: pd.DataFrame) -> bool:
    """Whether the null replicates ``g`` (one comparison, metric and rule) carry their
    placebos' randomization p-values (the raw rule against recombined designs)."""
    return "placebo_p_above" in g and bool(g["placebo_p_above"].notna().any())


def _recombined_placebos(g: pd.DataFrame, comp: str, metric: str) -> list[dict]:
    """The raw rule's checks (:data:`CHECKS`) on placebos decided against recombined
    designs: each claim from the placebo's one-sided p-values at α/2 (the test's own
    decision, :func:`.recombine.recombined_verdict`)."""
    rows = []
    for check in CHECKS:
        if check.rule != "raw":
            continue
        for r in g[g["placebo_p_above"].notna()].to_dict("records"):
            d = {"verdict": recombined_verdict(*placebo_ps(r, check.shift), ALPHA / 2)}
            rows.append({"comparison": comp, "metric": metric, "test": RECOMBINED,
                         "rule": "raw", "claim": check.claim,
                         "replicate": int(r["replicate"]), "claim_made": bool(check.made(d))})
    return rows


def _floor_of(g: pd.DataFrame, rows: np.ndarray) -> float:
    """The binomial floor (:func:`.verdicts.binomial_floor`) of replicates ``g``'s ``rows``."""
    if "comparable" not in g:
        return 0.0
    return binomial_floor(g["reversals"].to_numpy(float)[rows],
                          g["comparable"].to_numpy(float)[rows])


def family_placebos(null_rates: pd.DataFrame, family: int, *, alpha: float = ALPHA,
                    null_sizes: Mapping[str, int] | None = None) -> pd.DataFrame:
    """The headline table as the report decides it, on placebos: replicate j of every
    comparison taken as the observed (against that comparison's other replicates), every
    raw rate of the table decided at ``alpha``/``family`` (:func:`.nulls.family_verdicts`).
    One row per j with whether any rate was called above or below the null (false: the
    truth is no effect), and, on the placebo shifted up by 5 pp, whether any was called
    *no excess ≥ 5 pp* (false: the truth is +5 pp). ``null_sizes``: as :func:`placebos`."""
    raw = null_rates[null_rates["rule"] == "raw"]
    tables = {k: g.set_index("replicate") for k, g in
              raw.groupby(["comparison", "metric"], sort=False)}
    groups = {k: t["rate"] for k, t in tables.items()}
    if not groups or family < 1:
        return pd.DataFrame()
    common = sorted(set.intersection(*(set(g.index) for g in groups.values())))
    rows = []
    for pos, j in enumerate(common):
        effect = small = False
        for key, g in groups.items():
            keep = [common[i] for i in placebo_nulls(len(common), pos,
                                                     (null_sizes or {}).get(key[0]))]
            rest = g.loc[keep].to_numpy(float)
            if recombined(tables[key]):  # its placebo's own randomization p-values
                ps = tables[key].loc[j]
                a = alpha / (2 * family)
                effect |= recombined_verdict(*placebo_ps(ps, 0.0), a) in (ABOVE, BELOW)
                small |= recombined_verdict(*placebo_ps(ps, MIN_EFFECT), a) == SMALL
                continue
            if len(rest) < MIN_NULLS_T or not np.isfinite(g[j]):
                continue
            others = tables[key].loc[keep]
            floor = (binomial_floor(others["reversals"], others["comparable"])
                     if "comparable" in others else 0.0)
            effect |= prediction_test(g[j], rest, alpha=alpha / family,
                                      floor=floor)["verdict"] in (ABOVE, BELOW)
            small |= prediction_test(g[j] + MIN_EFFECT, rest, alpha=alpha / family,
                                     floor=floor)["verdict"] == SMALL
        rows += [{"comparison": "table", "test": "headline table", "rule": "raw",
                  "claim": FAMILY_EFFECT, "replicate": j, "claim_made": effect},
                 {"comparison": "table", "test": "headline table", "rule": "raw",
                  "claim": FAMILY_SMALL, "replicate": j, "claim_made": small}]
    return pd.DataFrame(rows)


def status(low: float, high: float, nominal: float) -> str:
    """What the placebos say of a rule at ``nominal``: *within* (its interval reaches down to
    the nominal level and rules out twice it), *above nominal* (the whole interval above),
    or *too few placebos to tell* (neither)."""
    if not np.isfinite(low):
        return "no placebos"
    if low > nominal:
        return "above nominal"
    return "within" if high <= 2 * nominal else "too few placebos to tell"


def calibration_table(null_rates: pd.DataFrame, placebo_crossovers: pd.DataFrame | None = None,
                      *, family: int = 0, null_kinds: Mapping[str, str] | None = None,
                      interaction: pd.DataFrame | None = None,
                      null_sizes: Mapping[str, int] | None = None) -> pd.DataFrame:
    """Per comparison (and ``all`` pooled) and check: placebos, claims, the claim rate with
    its Clopper–Pearson 95 % interval, the nominal level, ``within`` (the interval's lower
    end at or below it; NaN for power rows) and ``status`` (:func:`status`). Rows follow
    ``CHECKS``, then the headline table as a whole (with ``family`` raw rates, each decided
    at α/``family``), the crossover test (a placebo between populations of the same
    personas, a diagnostic among those of another null kind: ``null_kinds`` gives each
    comparison's kind of :data:`NULL_KINDS`, which names its claim), the interaction test
    (``interaction``: its leave-one-out placebos, each claim with its own ``nominal``,
    :func:`.interaction.interaction_placebos`) and the episode-only interval (a
    diagnostic). ``null_sizes``: per comparison, the replicates a placebo is judged against
    (the study's own design on more placebos, :func:`placebo_nulls`; default all others)."""
    if null_rates is None or null_rates.empty:
        return pd.DataFrame(columns=COLUMNS)
    p = placebos(null_rates, null_sizes)
    frames = [] if p.empty else [p]
    fam = family_placebos(null_rates, family, null_sizes=null_sizes)
    if not fam.empty:
        frames.append(fam)
    if placebo_crossovers is not None and not placebo_crossovers.empty:
        null_of = null_kinds or {}
        frames.append(placebo_crossovers.assign(
            test="crossover test", rule="—",
            claim=[NULL_KINDS[null_of[c]].crossover for c in placebo_crossovers["comparison"]],
            claim_made=placebo_crossovers["any"].astype(bool)))
    if interaction is not None and not interaction.empty:
        frames.append(interaction)
    if "episode_excludes_zero" in null_rates:
        e = null_rates[null_rates["episode_excludes_zero"].notna()]
        frames.append(e.assign(test="episode-only interval",
                               claim="an effect (excludes 0)",
                               claim_made=e["episode_excludes_zero"].astype(bool)))
    allp = pd.concat(frames, ignore_index=True)
    # the raw rule against recombined designs makes the prediction t's claims
    order: dict[tuple[str, str], float] = {(c.test.name, c.claim): i
                                           for i, c in enumerate(CHECKS)}
    order.update({(RECOMBINED, c.claim): i + 0.5 for i, c in enumerate(CHECKS)
                  if c.test is PREDICTION_T})
    kinds = {(c.test.name, c.claim): (c.kind, c.nominal) for c in CHECKS}
    kinds.update({(RECOMBINED, c.claim): (c.kind, c.nominal) for c in CHECKS
                  if c.test is PREDICTION_T})
    rows = []
    for comp in [*sorted(allp["comparison"].unique()), "all"]:
        sub = (allp[allp["comparison"] != "table"] if comp == "all"
               else allp[allp["comparison"] == comp])
        for (test, rule, claim), g in sub.groupby(["test", "rule", "claim"], sort=False):
            kind, nominal = kinds.get((test, claim), ("false positive", ALPHA))
            if claim == FAMILY_SMALL:
                nominal = ALPHA / 2
            if "nominal" in g and g["nominal"].notna().any():  # a claim that names its level
                nominal = float(g["nominal"].dropna().iloc[0])
            if test.startswith("episode") or (test == "crossover test"
                                               and claim not in FALSE_CROSSOVERS):
                kind = "diagnostic"
            k, n = int(g["claim_made"].sum()), len(g)
            low, high = clopper_pearson(k, n)
            rows.append({"comparison": comp, "test": test, "rule": rule, "claim": claim,
                         "kind": kind, "nominal": nominal, "placebos": n, "claims": k,
                         "rate": k / n if n else np.nan, "cp_low": low, "cp_high": high,
                         "within": (low <= nominal) if kind == "false positive" else np.nan,
                         "status": status(low, high, nominal) if kind == "false positive"
                         else kind,
                         "_order": (order.get((test, claim), 90)
                                    if test in TESTS or test == RECOMBINED else
                                    -1 if test == "headline table" else
                                    98 if test.startswith("episode") else
                                    96 if test.startswith("interaction") else 95)})
    have = {(r["test"], r["claim"]) for r in rows if r["comparison"] == "all"}
    for c in CHECKS:  # a rule no placebo could test
        if (c.test.name, c.claim) not in have:
            rows.append({"comparison": "all", "test": c.test.name, "rule": c.rule,
                         "claim": c.claim, "kind": c.kind, "nominal": c.nominal, "placebos": 0,
                         "claims": 0, "rate": np.nan, "cp_low": np.nan, "cp_high": np.nan,
                         "within": np.nan,
                         "status": "no placebos" if c.kind == "false positive" else c.kind,
                         "_order": order[(c.test.name, c.claim)]})
    out = pd.DataFrame(rows).assign(_pooled=lambda t: t["comparison"].isin(["all", "table"]))
    out = out.sort_values(["_pooled", "comparison", "_order", "rule"], kind="stable")
    return out.reset_index(drop=True)[COLUMNS]
