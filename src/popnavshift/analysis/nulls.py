"""Headline rates as their excess over a null computed at the same design.

For a comparison (the matched pair, or every pair of the eight populations) and
its null design (:mod:`popnavshift.populations.nulls`: swap permutations of the
matched pair, size-matched subsets of mixed), with the orderings of every
population laid out together (:func:`popnavshift.analysis.significance.orderings`,
so one paired episode bootstrap is shared by the observed and null populations):

* **observed** rate and each null replicate's rate, raw and significant;
* **verdict** on the excess = observed − mean of the null rates, from the spread
  *between* replicates (:mod:`.verdicts`: the prediction t for the raw rule — where the
  null is made of several units, the exact randomization test over recombined designs,
  :mod:`.recombine` — and the exact permutation p = (1 + #{null_k ≥ observed}) / (1 + P)
  for the significant rule);
* a second, labelled figure: the excess's **episode-only interval** ("beyond episode
  noise for these personas"), from the shared episode bootstrap (excess_b = obs_b −
  mean_k null_{k,b}): excess ± z · √(n/(n−1)) · SD_b(excess_b), n the episodes per cell.
  It holds the replicates fixed, so it misses their spread and is no test against the
  null (on placebos it excludes 0 far more often than 5 %: :mod:`.calibrate`). Centred
  on the estimate: a resample that repeats an episode reverses more, which shifts the
  resampled rates (their spread is sound, their centre is not).

Pure functions; definitions in ``docs/analysis.md`` §7 and §10.
"""

from __future__ import annotations

import warnings
from collections.abc import Collection, Mapping, Sequence
from typing import NamedTuple

import numpy as np
import pandas as pd
from scipy import stats

from ..populations.identity import MATCHED_PAIR, NULL_KINDS, NullKind, PopulationSpec
from .calibrate import placebo_nulls
from .recombine import (
    DRAWS,
    PLACEBO_PS,
    RECOMBINED,
    RecombinedRates,
    recombined_decide,
    recombined_interval,
    recombined_verdict,
    tail_ps,
)
from .reversals import population_pairs
from .significance import Orderings, PairCounts, pair_counts
from .verdicts import binomial_floor, decide

RULES: tuple[str, ...] = ("sig", "raw")
CI_LEVEL = 0.95  # coverage of the excess interval


def null_test(o: Orderings, observed: Sequence[tuple[str, str]],
              nulls: Sequence[Sequence[tuple[str, str]]], *,
              ci_level: float = CI_LEVEL, units: Sequence[int] = (),
              null_size: int | None = None, draws: int = DRAWS
              ) -> tuple[list[dict], pd.DataFrame]:
    """Observed vs null rates of one metric, for both rules.

    ``observed`` is a list of population pairs; ``nulls`` one list of pairs per null
    replicate (the same design). Returns one dict per rule — ``observed``, the counts,
    ``null_mean``, ``null_sd``, ``null_min``, ``null_max``, the verdict and its test
    (:func:`.verdicts.decide`), the episode-only interval ``episode_ci_low/high`` and its
    resamples ``boot_excess`` — and the replicates' table (:func:`replicate_table`).

    With ``units`` of two or more units (:class:`Design`) the raw rule is decided by the
    exact randomization test over ``draws`` designs recombined unit by unit
    (:func:`.recombine.recombined_decide`; the dict's ``reference`` holds the recombined
    rates, which :func:`family_verdicts` decides at the table's level), and every
    replicate's raw row gets its placebo's randomization p-values (:data:`PLACEBO_PS`),
    judged against the ``null_size`` replicates after it (default all others,
    :func:`.calibrate.placebo_nulls`).
    """
    obs = pair_counts(o, observed)
    reps = [pair_counts(o, pairs) for pairs in nulls]
    n = episodes_per_cell(o)
    rec = (RecombinedRates(o, [list(observed), *map(list, nulls)], units)
           if len(set(units)) > 1 and draws > 0 and nulls else None)
    seed = list(o.metric.encode())
    out = []
    for rule in RULES:
        row, boot = excess_over(obs, reps, rule, ci_level=ci_level, n_episodes=n)
        if rule == "raw" and rec is not None:
            pool = range(1, 1 + min(null_size or len(nulls), len(nulls)))
            rate, ref = rec.reference(0, pool, draws=draws, seed=[0, 1, *seed])
            row.update(recombined_decide(rate, ref, null_mean=row["null_mean"],
                                         alpha=1 - ci_level), reference=ref)
        out.append({"metric": o.metric, "rule": rule, **row, "boot_excess": boot})
    table = replicate_table(o.metric, reps, ci_level=ci_level, n_episodes=n)
    if rec is not None:
        table = _with_placebo_ps(table, rec, len(nulls), null_size, draws, seed)
    return out, table


def _with_placebo_ps(table: pd.DataFrame, rec: RecombinedRates, n_nulls: int,
                     null_size: int | None, draws: int, seed: list[int]) -> pd.DataFrame:
    """``table`` with, on each replicate's raw row, its placebo's :data:`PLACEBO_PS`: the
    replicate as the tested design against designs recombined from it and the replicates
    it is judged against (:func:`.calibrate.placebo_nulls`)."""
    ps = np.full((n_nulls, len(PLACEBO_PS)), np.nan)
    for j in range(n_nulls):
        rest = placebo_nulls(n_nulls, j, null_size)
        rate, ref = rec.reference(j + 1, rest + 1, draws=draws, seed=[j + 1, 1, *seed])
        ps[j] = [tail_ps(rate, ref, shift)[side] for side, shift in PLACEBO_PS.values()]
    raw = (table["rule"] == "raw").to_numpy()
    out = table.copy()
    for i, col in enumerate(PLACEBO_PS):
        out[col] = np.nan
        out.loc[raw, col] = ps[table.loc[raw, "replicate"].to_numpy() - 1, i]
    return out


def episodes_per_cell(o: Orderings) -> float:
    """The median number of episodes per cell of a design (the bootstrap's sample size)."""
    n = o.n_episodes[o.n_episodes > 0]
    return float(np.median(n)) if n.size else float("nan")


def _boot_excess(obs: PairCounts, reps: Sequence[PairCounts], rule: str) -> np.ndarray:
    """(B,) observed − mean null rate in every episode resample (NaN-skipping)."""
    with np.errstate(all="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        return obs.boot_rate(rule) - np.nanmean(np.vstack([r.boot_rate(rule) for r in reps]),
                                                axis=0)


def excess_over(obs: PairCounts, reps: Sequence[PairCounts], rule: str, *,
                ci_level: float = CI_LEVEL, n_episodes: float = np.inf
                ) -> tuple[dict, np.ndarray]:
    """The excess of ``obs`` over the null replicates ``reps`` under ``rule``: its verdict
    (:func:`.verdicts.decide`, on the spread between replicates) and, as a second figure,
    its episode-only interval (module doc) with the resampled values (B,) behind it (NaN
    where a resample has no comparable comparison)."""
    rate = obs.rate(rule)
    null = np.array([r.rate(rule) for r in reps], dtype=float)
    finite = null[np.isfinite(null)]
    row = {"observed": rate, "reversals": int(getattr(obs, f"{rule}_reversals").sum()),
           "comparable": int(getattr(obs, f"{rule}_comparable").sum()),
           "n_null": int(finite.size), "n_episodes": n_episodes,
           **decide(rate, finite, rule, alpha=1 - ci_level, floor=_floor(reps, rule))}
    if finite.size == 0 or not np.isfinite(rate):
        return {**row, "null_mean": np.nan, "null_sd": np.nan, "null_min": np.nan,
                "null_max": np.nan, "episode_ci_low": np.nan, "episode_ci_high": np.nan
                }, np.full(len(obs.boot_raw_reversals), np.nan)
    boot = _boot_excess(obs, reps, rule)
    low, high = centred_interval(row["excess"], boot, ci_level, n_episodes)
    return {**row, "null_mean": float(finite.mean()),
            "null_sd": float(finite.std(ddof=1)) if finite.size > 1 else np.nan,
            "null_min": float(finite.min()), "null_max": float(finite.max()),
            "episode_ci_low": float(low), "episode_ci_high": float(high)}, boot


def _floor(reps: Sequence[PairCounts], rule: str) -> float:
    """The binomial floor of the replicates' spread (:func:`.verdicts.binomial_floor`)."""
    return binomial_floor([getattr(r, f"{rule}_reversals").sum() for r in reps],
                          [getattr(r, f"{rule}_comparable").sum() for r in reps])


def replicate_table(metric: str, reps: Sequence[PairCounts], *, ci_level: float = CI_LEVEL,
                    n_episodes: float = np.inf) -> pd.DataFrame:
    """One row per (null replicate, rule): its rate and counts, and — the replicate taken as
    the observed against the others (a placebo) — whether the episode-only interval of its
    excess excludes 0 (``episode_excludes_zero``: how often that interval, which is not a
    verdict rule, claims an effect where there is none)."""
    rows = []
    for rule in RULES:
        for k, c in enumerate(reps):
            others = [r for j, r in enumerate(reps) if j != k]
            rate = c.rate(rule)
            rest = np.array([r.rate(rule) for r in others], float)
            rest = rest[np.isfinite(rest)]
            excludes = np.nan
            if rest.size and np.isfinite(rate):
                low, high = centred_interval(rate - rest.mean(), _boot_excess(c, others, rule),
                                             ci_level, n_episodes)
                excludes = float(low > 0 or high < 0) if np.isfinite(low) else np.nan
            rows.append({"metric": metric, "replicate": k + 1, "rule": rule, "rate": rate,
                         "reversals": int(getattr(c, f"{rule}_reversals").sum()),
                         "comparable": int(getattr(c, f"{rule}_comparable").sum()),
                         "episode_excludes_zero": excludes})
    return pd.DataFrame(rows, columns=["metric", "replicate", "rule", "rate", "reversals",
                                       "comparable", "episode_excludes_zero"])


def centred_interval(estimate: float, samples: np.ndarray, level: float,
                     n_episodes: float = np.inf) -> tuple[float, float]:
    """estimate ± z · √(n/(n−1)) · SD of the finite ``samples`` (NaN, NaN if < 2)."""
    x = np.asarray(samples, float)
    x = x[np.isfinite(x)]
    if x.size < 2 or not np.isfinite(estimate):
        return float("nan"), float("nan")
    inflate = np.sqrt(n_episodes / (n_episodes - 1)) if n_episodes > 1 else np.nan
    half = stats.norm.ppf(0.5 + level / 2) * inflate * float(x.std(ddof=1))
    return estimate - half, estimate + half


def burden_beyond_time(headline: pd.DataFrame, null_rates: pd.DataFrame,
                       boot_excess: dict[tuple[str, str, str], np.ndarray], *,
                       burden: str = "mean_delay", ci_level: float = CI_LEVEL,
                       alpha: float = 1 - CI_LEVEL) -> pd.DataFrame:
    """"Burden reverses more than robot time", tested against the null.

    Per (comparison, rule): the difference d = rate(burden) − rate(robot time),
    observed and per null replicate; its excess over the null (observed d − mean
    null d) decided like a rate (:func:`.verdicts.decide` on the replicates' d, at
    ``alpha``: the caller's share of its table's level), with the episode-only interval
    beside it (excess_b(burden) − excess_b(time)). Every null also
    reverses burden more often than robot time, so only an excess of d says the
    population does.
    """
    rows = []
    for (comp, rule), h in headline.groupby(["comparison", "rule"], sort=False):
        h = h.set_index("metric")
        if not {burden, "robot_time"} <= set(h.index):
            continue
        d_obs = h.at[burden, "observed"] - h.at["robot_time", "observed"]
        n = null_rates[(null_rates["comparison"] == comp) & (null_rates["rule"] == rule)]
        wide = n.pivot(index="replicate", columns="metric", values="rate")
        d_null = (wide[burden] - wide["robot_time"]).to_numpy(float) if len(wide) else np.array([])
        d_null = d_null[np.isfinite(d_null)]
        boot = (boot_excess[(comp, burden, rule)] - boot_excess[(comp, "robot_time", rule)])
        test = decide(d_obs, d_null, rule, alpha=alpha)
        n_eps = float(h.at[burden, "n_episodes"]) if "n_episodes" in h else np.inf
        low, high = (centred_interval(test["excess"], boot, ci_level, n_eps) if d_null.size
                     else (np.nan, np.nan))
        rows.append({"comparison": comp, "rule": rule, "metric": burden,
                     "observed_difference": d_obs,
                     "null_difference": d_null.mean() if d_null.size else np.nan,
                     **test, "episode_ci_low": low, "episode_ci_high": high,
                     "n_null": int(d_null.size)})
    return pd.DataFrame(rows)


def family_verdicts(headline: pd.DataFrame, null_rates: pd.DataFrame, *,
                    alpha: float = 1 - CI_LEVEL,
                    references: Mapping[tuple[str, str, str], np.ndarray] | None = None
                    ) -> pd.DataFrame:
    """The headline's verdicts with multiplicity control over its table: per rule, every row
    with null replicates is one test of a family of m, decided at ``alpha``/m (Bonferroni),
    so its interval is a simultaneous 1 − ``alpha`` interval and every claim of the table —
    above, below, no excess ≥ 5 pp — holds together with probability ≥ 1 − ``alpha``.
    Adds ``family`` (m), ``level`` (each interval's coverage) and ``p_adj`` (m·p, capped at
    1, of the rule's test); the per-test p-values are kept. A row decided against
    recombined designs (:data:`.recombine.RECOMBINED`) is decided from its one-sided
    p-values, its interval from its recombined rates in ``references`` (by (comparison,
    metric, rule); NaN without them)."""
    out = headline.reset_index(drop=True).copy()
    key = ["comparison", "metric", "rule"]
    groups = dict(list(null_rates.groupby(key, sort=False)))
    rates = {k: g["rate"].to_numpy(float) for k, g in groups.items()}
    floors = {k: binomial_floor(g["reversals"], g["comparable"]) if "comparable" in g else 0.0
              for k, g in groups.items()}
    for rule, rows in out.groupby("rule", sort=False):
        tested = rows[rows["n_null"] > 0]
        m = max(len(tested), 1)
        for i, r in tested.iterrows():
            k = (r["comparison"], r["metric"], rule)
            if r.get("test") == RECOMBINED:  # its p-values were computed with the row
                d = {"verdict": recombined_verdict(r["p_above"], r["p_below"], r["p_small"],
                                                   alpha / (2 * m)),
                     **recombined_interval(float(r["observed"]), (references or {}).get(k),
                                           alpha / m)}
            else:
                d = decide(float(r["observed"]), rates[k], rule, floor=floors[k],
                           alpha=alpha / m)
            for col in ("ci_low", "ci_high", "verdict"):
                out.at[i, col] = d[col]
        p = tested["p_t"] if rule == "raw" else tested["p_value"]
        out.loc[tested.index, "p_adj"] = np.minimum(1.0, m * p.to_numpy(float))
        out.loc[rows.index, "family"] = m
        out.loc[rows.index, "level"] = 1 - alpha / m
    return out


class Design(NamedTuple):
    """A headline comparison: its observed population pairs, one list of null pairs per
    null replicate (empty when the study ran none) and the kind of null design
    (:data:`popnavshift.populations.identity.NULL_KINDS`) it is tested against.

    ``units``: per population of the observed pairs, two per pair in order, the unit of
    the null design it belongs to — the populations drawn together, which a replicate
    index moves as one (a size-matched subset standing in for one population, in every
    pair it is in; both arms of a swap permutation). Units are drawn independently of one
    another, so a design recombined from several replicates (unit by unit) is a null
    design too: the interaction test's randomization reference
    (:func:`.interaction.interaction_test`). Empty without null replicates."""

    observed: list[tuple[str, str]]
    nulls: list[list[tuple[str, str]]]
    null: str
    units: tuple[int, ...] = ()


def headline_designs(populations: Collection[PopulationSpec],
                     observed_populations: Sequence[str]) -> dict[str, Design]:
    """The study's headline comparisons and their nulls, by label. ``populations``: those
    the study ran (``Study.population_specs``).

    ``matched``: the matched pair against a null kind of the same personas (swap
    permutations); ``all_pairs``: every pair of ``observed_populations`` (left out when it
    would be the matched pair alone), each pair against the first null kind that the study
    ran for it (:func:`comparison_design`: the matched pair among them gets swap permutation
    k where the study ran it, the others size-matched subsets). Two approximations remain,
    both documented (docs/analysis.md §7): cohorts that share personas get independent
    subsets, and ``homogeneous`` (the median profile, not a member of mixed) gets one
    random member.
    """
    out: dict[str, Design] = {}
    if set(MATCHED_PAIR) <= {s.name for s in populations}:
        out["matched"] = comparison_design([MATCHED_PAIR], populations, same_personas=True)
    obs = list(observed_populations)
    if len(obs) >= 2 and not (len(obs) == 2 and set(obs) == set(MATCHED_PAIR) and out):
        out["all_pairs"] = comparison_design(population_pairs(obs), populations)
    return out


def comparison_design(pairs: Sequence[tuple[str, str]], populations: Collection[PopulationSpec],
                      *, same_personas: bool = False) -> Design:
    """The comparison of observed ``pairs`` against the null replicates among ``populations``.

    Each pair stands in by the first kind of :data:`NULL_KINDS` (only kinds of the same
    personas with ``same_personas``) whose ``pair`` the study ran for it; replicate k is a
    null of the comparison when every pair's populations of k are present. The comparison's
    null kind is that of its first pair other than the matched pair (or of the matched
    pair alone); without replicates, the first kind that stands in for every pair.
    """
    have = {s.name for s in populations}
    reps = sorted({s.replicate for s in populations if s.is_null})
    kinds = {n: k for n, k in NULL_KINDS.items() if k.same_personas or not same_personas}

    def ran(kind: NullKind, pair: tuple[str, str], k: int) -> bool:
        null = kind.pair(pair, k)
        return null is not None and all(s.name in have for s in null)

    chosen = [next((n for n, kind in kinds.items() if any(ran(kind, p, k) for k in reps)),
                   "") for p in pairs]
    covered = [k for k in reps if all(c and ran(NULL_KINDS[c], p, k)
                                      for c, p in zip(chosen, pairs, strict=True))]
    if covered:
        i = next((j for j, p in enumerate(pairs) if set(p) != set(MATCHED_PAIR)), 0)
        nulls = [[_names(NULL_KINDS[c].pair(p, k)) for c, p in zip(chosen, pairs, strict=True)]
                 for k in covered]
        return Design(list(pairs), nulls, chosen[i], _units(chosen, pairs, covered[0]))
    default = next((n for n, kind in kinds.items() if all(kind.pair(p, 1) for p in pairs)), "")
    return Design(list(pairs), [], default)


def _units(chosen: Sequence[str], pairs: Sequence[tuple[str, str]], k: int
           ) -> tuple[int, ...]:
    """The unit of every population of ``pairs`` (two per pair): its null stand-in's role
    and what it stands in for (the same in every replicate: a sized subset of one
    population; both arms of a swap permutation, which stand in for the pair), numbered
    in order of appearance."""
    keys: dict[tuple[str, tuple[str, ...]], int] = {}
    out = []
    for c, p in zip(chosen, pairs, strict=True):
        null = NULL_KINDS[c].pair(p, k)
        assert null is not None  # a pair the chosen kind stands in for
        out += [keys.setdefault((s.role, s.bases), len(keys)) for s in null]
    return tuple(out)


def _names(null: tuple[PopulationSpec, PopulationSpec] | None) -> tuple[str, str]:
    assert null is not None  # a pair the chosen kind stands in for
    return null[0].name, null[1].name


def design_populations(design: Design) -> list[str]:
    """Every population a comparison design needs, observed first."""
    pops = [p for pair in design.observed for p in pair]
    pops += [p for pairs in design.nulls for pair in pairs for p in pair]
    return list(dict.fromkeys(pops))
