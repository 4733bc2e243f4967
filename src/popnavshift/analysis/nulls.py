"""Headline rates as their excess over a null computed at the same design.

For a comparison (the matched pair, or every pair of the eight populations) and
its null design (:mod:`popnavshift.populations.nulls`: swap permutations of the
matched pair, size-matched subsets of mixed), with the orderings of every
population laid out together (:func:`popnavshift.analysis.significance.orderings`,
so one paired episode bootstrap is shared by the observed and null populations):

* **observed** rate and each null replicate's rate, raw and significant;
* **excess** = observed − mean of the null rates, with an interval from the shared
  episode bootstrap (observed and null rates recomputed on every resample:
  excess_b = obs_b − mean_k null_{k,b}): excess ± z · √(n/(n−1)) · SD_b(excess_b), n the
  episodes per cell. Centred on the estimate, not the percentile interval: with few
  episodes per cell a resample that repeats an episode carries more noise and so
  reverses more, which shifts the resampled rates (their spread is sound, their centre
  is not); √(n/(n−1)) undoes the plug-in variance's bias;
* **p-value** = (1 + #{null_k ≥ observed}) / (1 + P), the permutation p-value of
  P null replicates (exact for the swap null, whose replicates are exchangeable
  with the observed pair under the null).

Pure functions; definitions in ``docs/analysis.md`` §7.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence

import numpy as np
import pandas as pd
from scipy import stats

from ..populations.nulls import SIZED_SOURCE, parse_null, sized_name, swap_name
from .reversals import MATCHED, population_pairs
from .significance import Orderings, PairCounts, pair_counts

RULES: tuple[str, ...] = ("sig", "raw")
CI_LEVEL = 0.95  # coverage of the excess interval


def swap_replicates(populations: Sequence[str]) -> list[int]:
    """The swap permutations whose two arms are both among ``populations``, sorted."""
    arms: dict[int, set[str]] = {}
    for p in populations:
        null = parse_null(p)
        if null is not None and null.kind == "swap":
            arms.setdefault(null.replicate, set()).add(null.arm)
    return sorted(k for k, a in arms.items() if a == {"a", "b"})


def sized_replicates(populations: Sequence[str], observed: Sequence[str]) -> list[int]:
    """The size-matched replicates that hold a subset for every one of ``observed``
    (``mixed`` stands for itself), sorted."""
    have = set(populations)
    reps = {n.replicate for p in populations if (n := parse_null(p)) and n.kind == "sized"}
    need = [p for p in observed if p != SIZED_SOURCE]
    return sorted(k for k in reps if all(sized_name(p, k) in have for p in need))


def swap_pairs(k: int) -> list[tuple[str, str]]:
    return [(swap_name(k, "a"), swap_name(k, "b"))]


def sized_pairs(observed_pairs: Sequence[tuple[str, str]], k: int) -> list[tuple[str, str]]:
    """The null of each observed pair: both populations replaced by replicate ``k`` of
    their size-matched subsets (``mixed`` by itself)."""
    def sub(p: str) -> str:
        return p if p == SIZED_SOURCE else sized_name(p, k)

    return [(sub(a), sub(b)) for a, b in observed_pairs]


def null_test(o: Orderings, observed: Sequence[tuple[str, str]],
              nulls: Sequence[Sequence[tuple[str, str]]], *,
              ci_level: float = CI_LEVEL) -> list[dict]:
    """Observed vs null rates of one metric, for both rules.

    ``observed`` is a list of population pairs; ``nulls`` one list of pairs per null
    replicate (the same design). Returns one dict per rule with ``observed``,
    ``null_mean``, ``null_sd``, ``null_min``, ``null_max``, ``excess``, ``ci_low``,
    ``ci_high``, ``p_value``, ``n_null`` and the counts of the observed rate.
    """
    obs = pair_counts(o, observed)
    reps = [pair_counts(o, pairs) for pairs in nulls]
    n = episodes_per_cell(o)
    out = []
    for rule in RULES:
        row, boot = excess_over(obs, reps, rule, ci_level=ci_level, n_episodes=n)
        out.append({"metric": o.metric, "rule": rule, **row, "boot_excess": boot})
    return out


def episodes_per_cell(o: Orderings) -> float:
    """The median number of episodes per cell of a design (the bootstrap's sample size)."""
    n = o.n_episodes[o.n_episodes > 0]
    return float(np.median(n)) if n.size else float("nan")


def excess_over(obs: PairCounts, reps: Sequence[PairCounts], rule: str, *,
                ci_level: float = CI_LEVEL, n_episodes: float = np.inf
                ) -> tuple[dict, np.ndarray]:
    """The excess of ``obs`` over the null replicates ``reps`` under ``rule``, and its
    resampled values (B,) (NaN where a resample has no comparable comparison);
    ``n_episodes`` per cell scales the interval (module doc)."""
    rate = obs.rate(rule)
    null = np.array([r.rate(rule) for r in reps], dtype=float)
    finite = null[np.isfinite(null)]
    row = {"observed": rate, "reversals": int(getattr(obs, f"{rule}_reversals").sum()),
           "comparable": int(getattr(obs, f"{rule}_comparable").sum()),
           "n_null": int(finite.size), "n_episodes": n_episodes}
    if finite.size == 0 or not np.isfinite(rate):
        return {**row, "null_mean": np.nan, "null_sd": np.nan, "null_min": np.nan,
                "null_max": np.nan, "excess": np.nan, "ci_low": np.nan, "ci_high": np.nan,
                "p_value": np.nan}, np.full(len(obs.boot_raw_reversals), np.nan)
    with np.errstate(all="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        boot = obs.boot_rate(rule) - np.nanmean(np.vstack([r.boot_rate(rule) for r in reps]),
                                                axis=0)
    excess = rate - float(finite.mean())
    low, high = centred_interval(excess, boot, ci_level, n_episodes)
    return {**row, "null_mean": float(finite.mean()),
            "null_sd": float(finite.std(ddof=1)) if finite.size > 1 else np.nan,
            "null_min": float(finite.min()), "null_max": float(finite.max()),
            "excess": excess, "ci_low": float(low),
            "ci_high": float(high),
            "p_value": permutation_p(rate, finite)}, boot


def permutation_p(observed: float, null: np.ndarray) -> float:
    """(1 + #{null ≥ observed}) / (1 + P): the permutation p-value of P null replicates."""
    return (1 + int((np.asarray(null) >= observed).sum())) / (1 + len(null))


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
                       burden: str = "mean_delay", ci_level: float = CI_LEVEL) -> pd.DataFrame:
    """"Burden reverses more than robot time", tested against the null.

    Per (comparison, rule): the difference d = rate(burden) − rate(robot time),
    observed and per null replicate; its excess over the null (observed d − mean
    null d) with an interval from the shared resamples (excess_b(burden) −
    excess_b(time)) and the permutation p-value of d. Every null also reverses burden
    more often than robot time, so only an excess of d says the population does.
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
        excess = d_obs - d_null.mean() if d_null.size else np.nan
        n = float(h.at[burden, "n_episodes"]) if "n_episodes" in h else np.inf
        low, high = centred_interval(excess, boot, ci_level, n) if d_null.size else (np.nan,
                                                                                    np.nan)
        rows.append({"comparison": comp, "rule": rule, "metric": burden,
                     "observed_difference": d_obs,
                     "null_difference": d_null.mean() if d_null.size else np.nan,
                     "excess": excess, "ci_low": low, "ci_high": high,
                     "p_value": permutation_p(d_obs, d_null) if d_null.size else np.nan,
                     "n_null": int(d_null.size)})
    return pd.DataFrame(rows)


def null_rates(o: Orderings, nulls: Sequence[Sequence[tuple[str, str]]]) -> pd.DataFrame:
    """One row per (null replicate, rule): the null's rate and counts (for figures)."""
    rows = []
    for k, pairs in enumerate(nulls, start=1):
        c = pair_counts(o, pairs)
        for rule in RULES:
            rows.append({"metric": o.metric, "replicate": k, "rule": rule,
                         "rate": c.rate(rule),
                         "reversals": int(getattr(c, f"{rule}_reversals").sum()),
                         "comparable": int(getattr(c, f"{rule}_comparable").sum())})
    return pd.DataFrame(rows, columns=["metric", "replicate", "rule", "rate", "reversals",
                                       "comparable"])


def headline_designs(populations: Sequence[str],
                     observed_populations: Sequence[str]) -> dict[str, tuple[list, list]]:
    """The study's headline comparisons and their nulls: label → (observed pairs, one
    list of pairs per null replicate; empty when the study ran no null).

    ``matched``: the matched pair against the swap permutations present;
    ``all_pairs``: every pair of ``observed_populations`` against the size-matched
    replicates that cover them all (left out when it would be the matched pair alone).
    """
    out: dict[str, tuple[list, list]] = {}
    if set(MATCHED) <= set(populations):
        out["matched"] = ([MATCHED], [swap_pairs(k) for k in swap_replicates(populations)])
    obs = list(observed_populations)
    if len(obs) >= 2 and not (len(obs) == 2 and set(obs) == set(MATCHED) and out):
        pairs = population_pairs(obs)
        out["all_pairs"] = (pairs, [sized_pairs(pairs, k)
                                    for k in sized_replicates(populations, obs)])
    return out


def design_populations(observed: Sequence[tuple[str, str]],
                       nulls: Sequence[Sequence[tuple[str, str]]]) -> list[str]:
    """Every population a comparison design needs, observed first."""
    pops = [p for pair in observed for p in pair]
    pops += [p for pairs in nulls for pair in pairs for p in pair]
    return list(dict.fromkeys(pops))
