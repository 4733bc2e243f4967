"""The card's verdict: is the controller's standing robust to the population, beyond noise?

Pipeline (pure): runs + pedestrians → the paired episode bootstrap
(:mod:`popnavshift.analysis.resample`) → per metric, every controller ordering with
its interval (:func:`popnavshift.analysis.significance.orderings`) → for the
evaluated controller against each baseline:

* **ranks**: its rank per population among the compared controllers, with the rank
  interval over resamples (:func:`popnavshift.analysis.evidence.controller_ranks`);
* **wins / losses**: per (population, baseline, metric), the cells where it is
  significantly better (lower), significantly worse, or tied;
* **significant reversals**: (cell, population pair) where its ordering against a
  baseline is significant under both populations with opposite signs, beside the
  raw (tie-tolerance) count — descriptive: over hundreds of comparisons, noise alone
  makes a few;
* **crossovers**: per (cell, baseline, metric), the paired intersection–union test of a
  qualitative interaction across the populations (valid for populations that share
  episodes and personas), Holm-adjusted over the card's whole table (valid whatever the
  dependence between cells) — the test the verdict rests on — with the crossover size each
  could detect;
* **safety** (:mod:`.safety`): per failure kind and scene, its rate beside every
  baseline's on the same runs, and whether it is less safe than the least safe baseline
  (paired, with an interval) — each unsafe finding names its failure;
* **verdict**: ``fails every run`` > ``unsafe`` > ``population-sensitive`` (a
  crossover survives multiplicity control) > ``robust in this study`` (none, with at
  least half of its orderings decided and tests that would see a crossover of
  ``CROSSOVER_OF_INTEREST`` with 80 % power) > ``inconclusive`` (no crossover detected
  with that power, or too few decided: the seed sets that would decide the median
  undecided ordering are given).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from itertools import combinations

import numpy as np
import pandas as pd
from scipy import stats

from ..analysis.delay import cell_metrics, paired_delays
from ..analysis.evidence import controller_ranks
from ..analysis.resample import build_design, episode_weights, resampled_metrics
from ..analysis.reversals import METRICS
from ..analysis.significance import (
    ALPHA,
    LEVEL,
    crossover_tests,
    detectable_crossover,
    holm,
    orderings,
)
from ..populations.build import population_order

#: The card's one metric set, the paper's three: the verdict, tables and figure all use it.
VERDICT_METRICS: tuple[str, ...] = METRICS
DECIDED_SHARE = 0.5  # orderings that must be significant before "robust" can be said
#: The largest crossover (s, ± under two populations in one cell) the tests must be able to see
#: with 80 % power before "no crossover" reads as robust.
CROSSOVER_OF_INTEREST = 1.0


@dataclass
class Verdict:
    label: str
    text: str
    safety: list[str] = field(default_factory=list)
    seed_sets_to_decide: float = float("nan")


@dataclass
class Evidence:
    """The card's significance tables (see the module doc)."""

    ranks: pd.DataFrame  # metric, population, controller, value, rank, rank_low, rank_high, …
    wins: pd.DataFrame  # metric, baseline, population, better, worse, tied
    reversals: pd.DataFrame  # metric, baseline, sig_reversals, sig_comparable, raw_…, decided…
    crossovers: pd.DataFrame  # metric, baseline, cell…, p, p_adj (BH over the table), crossover
    undecided_seed_sets: float  # median over undecided orderings (NaN if none)


def _oriented(table: pd.DataFrame, controller: str) -> pd.DataFrame:
    """Rows comparing ``controller`` with another, with diff/sig/sign as controller − other."""
    mine = (table["ctrl_1"] == controller) | (table["ctrl_2"] == controller)
    t = table[mine].copy()
    flip = (t["ctrl_2"] == controller).to_numpy()
    t["baseline"] = np.where(flip, t["ctrl_1"], t["ctrl_2"])
    for col in ("diff", "sig", "sign"):
        t[col] = np.where(flip, -t[col], t[col])
    return t


def card_evidence(runs: pd.DataFrame, pedestrians: pd.DataFrame, controller: str,
                  baselines: tuple[str, ...], *, rng: np.random.Generator, n_boot: int = 1000,
                  level: float = LEVEL, seed_sets: int = 1) -> Evidence:
    """Ranks, wins/losses and significant reversals of ``controller`` (module doc)."""
    paired = paired_delays(pedestrians)
    cells = cell_metrics(runs, paired)
    design = build_design(runs, paired)
    weights = episode_weights(design, n_boot, rng)
    pops = population_order(cells["population"].unique())
    z = stats.norm.ppf(0.5 + level / 2)
    ranks, wins, revs, undecided, cross = [], [], [], [], []
    for metric in VERDICT_METRICS:
        boot = resampled_metrics(design, weights, (metric,))
        o = orderings(cells, design, boot, metric, level=level, populations=pops)
        t = _oriented(o.table(), controller)
        t = t[t["baseline"].isin(baselines) & t["diff"].notna()]
        ranks.append(controller_ranks(cells, boot[metric], metric, pops, level=level))
        g = t.groupby(["baseline", "population"], sort=False)["sig"]
        w = pd.DataFrame({"better": g.apply(lambda s: int((s == -1).sum())),
                          "worse": g.apply(lambda s: int((s == 1).sum())),
                          "tied": g.apply(lambda s: int((s == 0).sum()))}).reset_index()
        wins.append(w.assign(metric=metric))
        for b in baselines:
            counts = _reversal_counts(t[t["baseline"] == b])
            revs.append({"metric": metric, "baseline": b, **counts})
        c = crossover_tests(o, pops)
        mine = (c["ctrl_1"] == controller) | (c["ctrl_2"] == controller)
        c = c[mine].assign(metric=metric, baseline=np.where(c.loc[mine, "ctrl_1"] == controller,
                                                            c.loc[mine, "ctrl_2"],
                                                            c.loc[mine, "ctrl_1"]))
        cross.append(c[c["baseline"].isin(baselines)])
        open_ = t[(t["sig"] == 0) & (t["diff"] != 0) & (t["se"] > 0)]
        undecided.append(seed_sets * (z * open_["se"] / open_["diff"].abs()) ** 2)
    need = pd.concat(undecided)
    tests = pd.concat(cross, ignore_index=True)
    tests["p_adj"] = holm(tests["p"].to_numpy(float))  # over the card's whole table
    tests["crossover"] = tests["p_adj"] <= ALPHA
    tests["detectable"] = detectable_crossover(  # at the card's table size
        tests["se"].to_numpy(float), tests["n_episodes"].to_numpy(float),
        tests["n_populations"].to_numpy(float), int(tests["p"].notna().sum()))
    return Evidence(pd.concat(ranks, ignore_index=True), pd.concat(wins, ignore_index=True),
                    pd.DataFrame(revs), tests,
                    float(np.ceil(need.median())) if len(need) else float("nan"))


def _reversal_counts(t: pd.DataFrame) -> dict[str, int]:
    """Significant and raw reversals of one (baseline, metric) over population pairs."""
    key = ["backend", "mapping", "cell"]
    sig = t.pivot_table(index=key, columns="population", values="sig", aggfunc="first")
    raw = t.pivot_table(index=key, columns="population", values="sign", aggfunc="first")
    out = {"sig_reversals": 0, "sig_comparable": 0, "raw_reversals": 0, "raw_comparable": 0}
    for a, b in combinations(sig.columns, 2):
        for name, wide in (("sig", sig), ("raw", raw)):
            prod = (wide[a] * wide[b]).to_numpy(float)
            out[f"{name}_reversals"] += int((prod == -1).sum())
            out[f"{name}_comparable"] += int((np.abs(prod) == 1).sum())
    out["orderings"] = int(t["sig"].notna().sum())
    out["decided"] = int((t["sig"].abs() == 1).sum())
    return out


def crossover_power(tests: pd.DataFrame) -> dict:
    """The crossover size the card's tests could see: per metric the median over cells of
    ``detectable`` (80 % power at the card's table size), and the metric where it is
    largest (what "no crossover" can least rule out)."""
    by = tests.groupby("metric")["detectable"].median().dropna()
    if by.empty:
        return {"metric": "", "size": float("inf")}
    return {"metric": str(by.idxmax()), "size": float(by.max())}


def verdict(runs: pd.DataFrame, controller: str, ev: Evidence, *, seed_sets: int = 1,
            safety: list[str] | tuple[str, ...] = ()) -> Verdict:
    """The card's one-line verdict and its explanation (module doc); ``safety`` are the
    unsafe findings of :func:`.safety.safety_findings` (each names its failure)."""
    own = runs[runs["controller"] == controller]
    safety = list(safety)
    r = ev.reversals
    sig, sig_n = int(r["sig_reversals"].sum()), int(r["sig_comparable"].sum())
    raw, raw_n = int(r["raw_reversals"].sum()), int(r["raw_comparable"].sum())
    decided = float(r["decided"].sum() / r["orderings"].sum()) if r["orderings"].sum() else 0.0
    counts = (f"{sig} significant reversal{'s' if sig != 1 else ''} in {sig_n} comparisons "
              f"significant under both populations (raw rule incl. near-ties: {raw}/{raw_n}); "
              f"{100 * decided:.0f}% of its orderings against the baselines are significant")
    if len(own) == 0 or not (own["outcome"] == "success").any():
        return Verdict("fails every run", f"It reached the goal in none of its {len(own)} runs: "
                       "its rankings mean nothing.", safety, ev.undecided_seed_sets)
    if not r["orderings"].sum():
        untestable = ("This design cannot support the tests: with one episode per cell an "
                      "ordering has no spread to be judged by, so no ranking, win or reversal "
                      "is tested. Run a study with several variants per cell (the paper study, "
                      "`make run`, has 3; add `seeds:` for more) and evaluate against it.")
        if safety:
            return Verdict("unsafe", "Safety first: " + "; ".join(safety) + ". " + untestable,
                           safety, ev.undecided_seed_sets)
        return Verdict("inconclusive", untestable, safety, ev.undecided_seed_sets)
    if safety:
        return Verdict("unsafe", "Safety first: " + "; ".join(safety)
                       + f". Rankings: {counts}.", safety, ev.undecided_seed_sets)
    x = ev.crossovers
    found = x[x["crossover"]]
    tests = (f"{len(found)} of {int(x['p'].notna().sum())} crossover tests (one per cell, "
             "baseline and metric across the populations; paired, valid for populations that "
             f"share episodes and personas) survive Holm's control at {ALPHA:g}")
    counts = f"{tests}; {counts}"
    if len(found):
        top = found.groupby(["baseline", "metric"]).size().sort_values(ascending=False)
        (b, m), n = top.index[0], int(top.iloc[0])
        return Verdict("population-sensitive",
                       f"Its ranking changes with the population beyond noise: {counts}. Most "
                       f"against {b} on {m.replace('_', ' ')} ({n} cells).", safety,
                       ev.undecided_seed_sets)
    power = crossover_power(x)
    if decided >= DECIDED_SHARE and power["size"] <= CROSSOVER_OF_INTEREST:
        return Verdict("robust in this study", f"No crossover beyond noise: {counts}; the "
                       f"tests would have found a crossover of ±{power['size']:.2f} s on "
                       f"{power['metric'].replace('_', ' ')} with 80% power.", safety,
                       ev.undecided_seed_sets)
    if decided >= DECIDED_SHARE:
        return Verdict("inconclusive", f"No crossover detected, but the tests had little power: "
                       f"80% power only for a crossover of ±{power['size']:.2f} s on "
                       f"{power['metric'].replace('_', ' ')} in a cell (median over cells; "
                       f"{CROSSOVER_OF_INTEREST:g} s is the size that matters here). {counts}.",
                       safety, ev.undecided_seed_sets)
    need = ev.undecided_seed_sets
    advice = (f" About {int(need)} episode seed sets per cell (now {seed_sets}) would decide the "
              "median undecided ordering: add `seeds:` to the study's main part."
              if np.isfinite(need) else "")
    return Verdict("inconclusive", f"Too few orderings are decided to call it robust: {counts}."
                   + advice, safety, need)
