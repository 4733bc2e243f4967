"""Which population pairs carry the all-pairs excess, with multiplicity control.

The all-pairs rate pools the raw reversals of every pair of the main part's populations
(28 for eight). Here each pair is tested on its own, as the headline tests the pool
(:mod:`.verdicts`): pair π's raw rate against the same pair's rate in every null
replicate k (π's null pair of replicate k: the size-matched subsets, or swap permutation k
for the matched pair), prediction t on P − 1 df with the binomial floor. The pairs of a
table are one family: Holm over every (pair, metric) row, so every claim of the table holds
together with probability ≥ 1 − α.

Beside the pairs, one pre-specified grouping by attribute (:data:`ATTRIBUTE`): the pairs
with a population under time pressure against the others, each group's pooled rate tested
against the same group's pooled rate in every replicate, and the difference of the two
groups' rates against the replicates' differences (which group carries the excess); Holm
over the groups' table.

A rule's false-positive rate is measured on placebos (:func:`placebos`): replicate j
taken as the observed against the other P − 1, every rule applied, a table with any claim
counted as a false claim (nominal: α per table).

``pair_counts`` also counts, for every pair with a population of :data:`SELF_NULL` (a fixed
profile, no persona sampling: ``homogeneous``), its null with that population itself in
place of its random member (``kind = "null_self"``), to measure which way the random
member moves the null (``docs/analysis.md`` §7).

Pure functions; definitions in ``docs/analysis.md`` §7.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Mapping, Sequence

import numpy as np
import pandas as pd

from ..populations.identity import NULL_KINDS, SIZED_SOURCE, PopulationSpec, spec_of
from .cohorts import cohort_dispersion, cohort_overlaps
from .nulls import Design
from .reversals import tie_sign
from .significance import Orderings, holm
from .verdicts import ABOVE, ALPHA, BELOW, binomial_floor, clopper_pearson, prediction_test

#: the attribute the pairs are grouped by: its name and the populations that carry it
ATTRIBUTE: tuple[str, tuple[str, ...]] = ("time-pressure",
                                          ("high_time_pressure", "matched_deadline"))
#: populations that hold one fixed profile (no persona sampling): their exact null is
#: themselves, while the size-matched null gives them one random member of mixed
SELF_NULL: tuple[str, ...] = ("homogeneous",)
NOT_SHOWN = "not shown"
COUNT_COLUMNS = ["metric", "pair", "pop_a", "pop_b", "kind", "replicate", "reversals",
                 "comparable"]


def _counts(signs: np.ndarray, o: Orderings, a: str, b: str) -> tuple[int, int]:
    prod = signs[o.index(a)] * signs[o.index(b)]
    return int((prod == -1).sum()), int((np.abs(prod) == 1).sum())


def pair_counts(o: Orderings, design: Design) -> pd.DataFrame:
    """Raw reversal counts of every observed pair of ``design`` (one metric's orderings
    ``o``): one row per (pair, kind, replicate) — kind ``observed`` (replicate 0), ``null``
    (replicate k: the pair's null pair of replicate k) and, for a pair with a population of
    :data:`SELF_NULL`, ``null_self`` (replicate k with that population itself; none when
    the other population stands for itself too)."""
    signs = tie_sign(o.diff, o.tolerance)
    have = set(o.populations)
    rows = []
    for i, (a, b) in enumerate(design.observed):
        label = f"{a} vs {b}"
        rows.append((o.metric, label, a, b, "observed", 0, *_counts(signs, o, a, b)))
        for k, nulls in enumerate(design.nulls, start=1):
            na, nb = nulls[i]
            rows.append((o.metric, label, a, b, "null", k, *_counts(signs, o, na, nb)))
            selfed = (a if a in SELF_NULL else na, b if b in SELF_NULL else nb)
            # a pair of two self-standing populations (homogeneous vs mixed) has no such
            # null: it would be the observed pair itself
            if selfed not in ((na, nb), (a, b)) and set(selfed) <= have:
                rows.append((o.metric, label, a, b, "null_self", k,
                             *_counts(signs, o, *selfed)))
    return pd.DataFrame(rows, columns=COUNT_COLUMNS)


def _rate(rev: np.ndarray, comp: np.ndarray) -> np.ndarray:
    with np.errstate(all="ignore"):
        return np.where(comp > 0, rev / np.where(comp > 0, comp, 1), np.nan)


def _test(x: np.ndarray, floor: float, reversals: float = 0, comparable: float = 0) -> dict:
    """The prediction t of ``x[0]`` (the observed rate) against ``x[1:]`` (its replicates),
    its SD at least ``floor``; ``_x`` and ``_floor`` are kept for the exact test."""
    null = x[1:]
    t = prediction_test(float(x[0]), null, floor=floor)
    finite = null[np.isfinite(null)]
    return {"observed": float(x[0]), "reversals": int(reversals), "comparable": int(comparable),
            "null_mean": float(finite.mean()) if finite.size else np.nan,
            "null_sd": float(finite.std(ddof=1)) if finite.size > 1 else np.nan,
            "n_null": int(finite.size), **{k: t[k] for k in ("excess", "t", "df", "p_t")},
            "_x": x, "_floor": floor}


def _counted(rev: np.ndarray, comp: np.ndarray) -> dict:
    """:func:`_test` of counts per arrangement (0: observed), with the binomial floor of all
    of them (a symmetric function, so the exact test stays exact)."""
    return _test(_rate(rev, comp), binomial_floor(rev, comp), rev[0], comp[0])


def _loo_t(x: np.ndarray, floors: np.ndarray) -> np.ndarray:
    """(R, A) |t| of every arrangement a of every row against the row's other A − 1
    arrangements (the prediction t's scale); NaN where undefined."""
    n_rows, n_arr = x.shape
    out = np.full((n_rows, n_arr), np.nan)
    with np.errstate(all="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        for a in range(n_arr):
            others = np.delete(x, a, axis=1)
            n = np.isfinite(others).sum(axis=1)
            sd = np.fmax(np.nanstd(others, axis=1, ddof=1), floors) * np.sqrt(1 + 1 / n)
            t = np.abs(x[:, a] - np.nanmean(others, axis=1)) / sd
            out[:, a] = np.where((n >= 3) & (sd > 0), t, np.nan)
    return out


def maxt_p(x: np.ndarray, floors: np.ndarray) -> np.ndarray:
    """Westfall–Young step-down max-|t| adjusted p-values of the rows of ``x`` (R, A): each
    row's rate in A exchangeable arrangements, the observed first and the null replicates
    after it. Every arrangement's |t| against the others is its statistic; row i's p is the
    share of arrangements whose largest |t| over the rows not yet rejected reaches the
    observed |t| of row i (monotone in the step-down order). Exact for exchangeable
    replicates whatever their shape and dependence across rows (family-wise error ≤ α);
    it cannot go below 1/A. NaN for a row without a statistic."""
    t = _loo_t(x, floors)
    p = np.full(len(x), np.nan)
    ok = np.flatnonzero(np.isfinite(t[:, 0]))
    if ok.size == 0:
        return p
    order = ok[np.argsort(-t[ok, 0], kind="stable")]
    filled = np.nan_to_num(t, nan=-np.inf)
    running = np.full(t.shape[1], -np.inf)
    raw = np.empty(len(order))
    for i in range(len(order) - 1, -1, -1):  # the max over rows i … m of the order
        running = np.maximum(running, filled[order[i]])
        raw[i] = float((running >= t[order[i], 0]).mean())
    p[order] = np.maximum.accumulate(raw)
    return p


#: how each table decides its claims: the exact step-down max-|t| over the replicates, or
#: Holm on the prediction t (for pooled rates over thousands of comparisons, where the
#: t's normal model holds and the exact test's floor 1/(P + 1) would leave nothing decided)
DECIDED_BY = {"pairs": "exact max-t", "groups": "prediction t, Holm"}


def _claims(rows: list[dict], alpha: float, rule: str) -> pd.DataFrame:
    """The table of ``rows`` with ``p_holm`` (Holm on p_t), ``p_maxt`` (:func:`maxt_p`),
    the ``claim`` of its rule (:data:`DECIDED_BY`) at family-wise ``alpha`` and ``family``."""
    out = pd.DataFrame(rows)
    width = max((len(r["_x"]) for r in rows), default=0)
    x = np.array([np.pad(r["_x"], (0, width - len(r["_x"])), constant_values=np.nan)
                  for r in rows]).reshape(len(rows), width)
    out = out.drop(columns=["_x", "_floor"], errors="ignore")
    out["p_holm"] = holm(out["p_t"].to_numpy(float)) if len(out) else []
    out["p_maxt"] = maxt_p(x, np.array([r["_floor"] for r in rows], float))
    deciding = out["p_maxt" if rule == "pairs" else "p_holm"].to_numpy(float)
    sure = deciding <= alpha
    out["claim"] = np.where(sure & (out["excess"] > 0), ABOVE,
                            np.where(sure & (out["excess"] < 0), BELOW, NOT_SHOWN))
    out["decided_by"] = DECIDED_BY[rule]
    out["family"] = int(out["p_t"].notna().sum()) if len(out) else 0
    return out


def _mean(x: np.ndarray) -> float:
    """The mean of the finite values of ``x``; NaN without one."""
    x = x[np.isfinite(x)]
    return float(x.mean()) if x.size else float("nan")


def _arrangements(g: pd.DataFrame, kind: str = "null") -> pd.DataFrame:
    """The observed row then the ``kind`` rows in replicate order."""
    return pd.concat([g[g["kind"] == "observed"], g[g["kind"] == kind].sort_values("replicate")])


def pair_verdicts(counts: pd.DataFrame, *, alpha: float = ALPHA) -> pd.DataFrame:
    """One row per (metric, pair) of :func:`pair_counts`' table: the observed raw rate with
    its counts, the null mean and SD, excess, prediction t, df, p_t, Holm's ``p_holm``, the
    exact ``p_maxt`` over every row, and the ``claim`` it decides (above / below the null at
    family-wise ``alpha``, else not shown); ``carries`` (the pair has a population of
    :data:`ATTRIBUTE`) and, for a pair with a population of :data:`SELF_NULL`,
    ``null_mean_self`` (the null with it itself)."""
    rows = []
    for (metric, pair), g in counts.groupby(["metric", "pair"], sort=False):
        arr = _arrangements(g)
        obs = arr.iloc[0]
        selfed = g[g["kind"] == "null_self"]
        rows.append({"metric": metric, "pair": pair, "pop_a": obs["pop_a"],
                     "pop_b": obs["pop_b"],
                     "carries": bool({obs["pop_a"], obs["pop_b"]} & set(ATTRIBUTE[1])),
                     **_counted(arr["reversals"].to_numpy(float),
                                arr["comparable"].to_numpy(float)),
                     "null_mean_self": _mean(_rate(selfed["reversals"].to_numpy(float),
                                                   selfed["comparable"].to_numpy(float)))})
    return _claims(rows, alpha, "pairs")


GROUP_WITH, GROUP_OTHERS, GROUP_DIFF = ("with", "others", "difference")


def group_verdicts(counts: pd.DataFrame, *, alpha: float = ALPHA) -> pd.DataFrame:
    """Per metric, the pairs with a population of :data:`ATTRIBUTE` (``with``), the others
    (``others``), each pooled and tested against the same pooling of every replicate, and
    their ``difference`` (rate with − rate others) against the replicates' differences; Holm
    over every row of the table decides (``p_maxt`` beside it)."""
    carriers = set(ATTRIBUTE[1])
    rows = []
    for metric, g in counts[counts["kind"] != "null_self"].groupby("metric", sort=False):
        has = g["pop_a"].isin(carriers) | g["pop_b"].isin(carriers)
        rates = {}
        for group, sel in ((GROUP_WITH, has), (GROUP_OTHERS, ~has)):
            s = g[sel].groupby("replicate")[["reversals", "comparable"]].sum().sort_index()
            rev, comp = s["reversals"].to_numpy(float), s["comparable"].to_numpy(float)
            rates[group] = _rate(rev, comp)
            rows.append({"metric": metric, "group": group, "pairs": int(g[sel]["pair"].nunique()),
                         **_counted(rev, comp)})
        rows.append({"metric": metric, "group": GROUP_DIFF, "pairs": int(g["pair"].nunique()),
                     **_test(rates[GROUP_WITH] - rates[GROUP_OTHERS], 0.0)})
    return _claims(rows, alpha, "groups")


def as_placebo(counts: pd.DataFrame, j: int) -> pd.DataFrame:
    """``counts`` with null replicate ``j`` taken as the observed and the true observed left
    out (the other replicates renumbered 1 … P − 1): a comparison where the truth is no
    effect."""
    c = counts[(counts["kind"] == "null") & (counts["replicate"] >= 1)].copy()
    others = sorted(set(c["replicate"]) - {j})
    c["kind"] = np.where(c["replicate"] == j, "observed", "null")
    c["replicate"] = c["replicate"].map({j: 0, **{k: i for i, k in enumerate(others, 1)}})
    return c.sort_values(["metric", "pair", "replicate"], kind="stable").reset_index(drop=True)


RULES: dict[str, Callable[..., pd.DataFrame]] = {"pairs": pair_verdicts,
                                                 "groups": group_verdicts}


def placebos(counts: pd.DataFrame, *, alpha: float = ALPHA,
             rules: Sequence[str] = tuple(RULES)) -> pd.DataFrame:
    """Each rule's false-claim rate on the study's placebos (:func:`as_placebo`, one per null
    replicate): per rule, ``placebos``, ``tables_with_claim`` (any row claimed above or below:
    a false claim, nominal ``alpha`` per table), its share with the Clopper–Pearson 95 %
    interval, ``rows`` tested and ``false_claims`` among them."""
    reps = sorted(set(counts.loc[counts["kind"] == "null", "replicate"]))
    out = []
    for rule in rules:
        hits, claims, tested = 0, 0, 0
        for j in reps:
            v = RULES[rule](as_placebo(counts, j), alpha=alpha)
            n = int((v["claim"] != NOT_SHOWN).sum())
            hits, claims, tested = hits + (n > 0), claims + n, tested + int(v["p_t"].notna().sum())
        low, high = clopper_pearson(hits, len(reps))
        out.append({"rule": rule, "placebos": len(reps), "null_replicates": max(len(reps) - 1, 0),
                    "tables_with_claim": hits,
                    "rate": hits / len(reps) if reps else np.nan, "ci_low": low, "ci_high": high,
                    "nominal": alpha, "rows": tested, "false_claims": claims})
    return pd.DataFrame(out)


def self_null_direction(pairs: pd.DataFrame) -> pd.DataFrame:
    """Per metric, over the pairs with a population of :data:`SELF_NULL`: the mean null rate
    with its random member (``null_mean``) and with itself (``null_mean_self``), their
    difference and in how many pairs the random member's null reverses less."""
    s = pairs.dropna(subset=["null_mean_self"])
    g = s.assign(diff=s["null_mean"] - s["null_mean_self"]).groupby("metric", sort=False)
    return g.agg(pairs=("pair", "size"), null_mean=("null_mean", "mean"),
                 null_mean_self=("null_mean_self", "mean"), difference=("diff", "mean"),
                 pairs_lower=("diff", lambda d: int((d < 0).sum()))).reset_index()


def sized_pairs(design: Design, specs: Mapping[str, PopulationSpec]) -> list[tuple[str, str]]:
    """The observed pairs of ``design`` judged against size-matched subsets of mixed, mixed's
    own pairs left out (it stands for itself: its overlap is the same in the null)."""
    role = NULL_KINDS["sized"].role
    return [p for i, p in enumerate(design.observed)
            if design.nulls and SIZED_SOURCE not in p
            and any(spec_of(specs, n).role == role for n in design.nulls[0][i])]


def pair_tables(counts: pd.DataFrame, populations: pd.DataFrame | None, design: Design,
                specs: Mapping[str, PopulationSpec], *, seed: int = 0,
                alpha: float = ALPHA) -> dict[str, pd.DataFrame]:
    """The tables of a comparison of several pairs, by name without the ``evidence_``
    prefix: ``pairs`` and ``pair_groups`` (the verdicts), ``pair_placebos`` (their
    false-claim rates on the study's placebos) and, from the ``populations`` table, how the
    size-matched null matches the cohorts (``cohorts``: dispersion; ``cohort_overlaps``: the
    personas shared by each pair judged against size-matched subsets, :func:`sized_pairs`).
    """
    out = {"pairs": pair_verdicts(counts, alpha=alpha),
           "pair_groups": group_verdicts(counts, alpha=alpha),
           "pair_placebos": placebos(counts, alpha=alpha)}
    if populations is not None and not populations.empty:
        cohorts = list(dict.fromkeys(p for pair in design.observed for p in pair))
        out["cohorts"] = cohort_dispersion(populations, cohorts, seed=seed)
        out["cohort_overlaps"] = cohort_overlaps(populations, sized_pairs(design, specs))
    return out
