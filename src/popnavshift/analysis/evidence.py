"""What a study's runs can decide: significance, nulls and ranks in one pass.

``test_comparisons(runs, pedestrians, designs, ...)`` runs the paired episode
bootstrap once over the given runs (every population, controller and cell) and,
per metric, lays out every controller ordering (:mod:`.significance`), then for
each comparison design (observed pairs + null replicates, :func:`.nulls.headline_designs`)
tests the observed reversal rates against the null (:mod:`.nulls`, verdicts from
:mod:`.verdicts`) and runs the crossover test over the observed populations and, as
placebos, over every null replicate's. ``controller_ranks``
gives each controller's rank per population with rank intervals from the same
resamples.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from .delay import cell_metrics, paired_delays
from .interaction import interaction_test
from .nulls import CI_LEVEL, Design, null_test
from .pair_excess import pair_counts
from .ranked import RANKED_NAMES
from .resample import build_design, episode_weights, resampled_metrics
from .significance import ALPHA, LEVEL, Orderings, crossover_tests, orderings

N_BOOT = 1000


@dataclass
class Tested:
    """Tables of :func:`test_comparisons` (each has a ``comparison`` column where it applies).

    ``headline``: observed vs null per (comparison, metric, rule) with its verdict;
    ``null_rates``: every null replicate's rate (and its placebo flag); ``crossovers``:
    crossover tests per (comparison, metric, unit, controller pair); ``orderings``: every
    ordering of the observed populations; ``placebo_crossovers``: the crossover test on
    every null replicate's populations.
    """

    headline: pd.DataFrame
    null_rates: pd.DataFrame
    crossovers: pd.DataFrame
    orderings: pd.DataFrame
    ranks: pd.DataFrame
    placebo_crossovers: pd.DataFrame
    n_boot: int
    level: float
    #: (comparison, metric, rule) → the excess over the null in every resample (B,)
    boot_excess: dict[tuple[str, str, str], np.ndarray] = field(default_factory=dict)
    #: with a ``controller``: ``headline`` and ``null_rates`` of each of its pairs alone
    #: (column ``baseline``: the other controller of the pair)
    pair_headline: pd.DataFrame = field(default_factory=pd.DataFrame)
    pair_null_rates: pd.DataFrame = field(default_factory=pd.DataFrame)
    #: the interaction test (:mod:`.interaction`) per (comparison, metric), before its
    #: family's verdicts (:func:`.interaction.interaction_verdicts`), and every null
    #: replicate's statistic with its leave-one-out placebo
    interaction: pd.DataFrame = field(default_factory=pd.DataFrame)
    interaction_nulls: pd.DataFrame = field(default_factory=pd.DataFrame)
    #: raw reversal counts of every observed pair of a comparison of several pairs, observed
    #: and in every null replicate (:func:`.pair_excess.pair_counts`)
    pair_counts: pd.DataFrame = field(default_factory=pd.DataFrame)
    #: (comparison, metric, rule) → the rates of the designs recombined from the observed
    #: and its replicates, where the raw rule is decided against them (:mod:`.recombine`)
    references: dict[tuple[str, str, str], np.ndarray] = field(default_factory=dict)
    #: with a ``controller``: the same per (comparison, baseline, metric, rule)
    pair_references: dict[tuple[str, str, str, str], np.ndarray] = field(
        default_factory=dict)


def test_comparisons(runs: pd.DataFrame, pedestrians: pd.DataFrame,
                     designs: dict[str, Design], observed: Sequence[str], *,
                     rng: np.random.Generator, n_boot: int = N_BOOT, level: float = LEVEL,
                     alpha: float = ALPHA, method: str = "holm",
                     metrics: Sequence[str] = RANKED_NAMES,
                     ci_level: float = CI_LEVEL, rates_only: bool = False,
                     controller: str | None = None,
                     null_sizes: dict[str, int] | None = None,
                     interaction: bool = True) -> Tested:
    """Every comparison design of ``designs`` tested on ``runs`` (see the module doc).

    Args:
      runs, pedestrians: the runs analysed (observed and null populations, every seed
        set to pool: a cell pools all its episodes).
      designs: label → its :class:`.nulls.Design` (observed pairs, one list of pairs per
        null replicate).
      observed: the observed populations (orderings, crossover tests and ranks).
      rng: draws the episode resamples (shared by every metric and population).
      rates_only: only the rates against their nulls (``headline``, ``null_rates``): the
        crossover tests, orderings and ranks are left empty (the replicate curve needs
        no more).
      controller: count only the orderings of this controller against the others (a
        card: never the others' among themselves), pooled and, in ``pair_headline`` and
        ``pair_null_rates``, pair by pair.
      null_sizes: per design label, the replicates each placebo of a test that computes
        its own (the interaction test; the raw rule against recombined designs) is judged
        against (the study's own design on more placebos; default all others).
      interaction: run the interaction test (:mod:`.interaction`), with ``rates_only`` too
        (a card's second question); False leaves ``interaction`` empty.
    """
    paired = paired_delays(pedestrians)
    cells = cell_metrics(runs, paired)
    design = build_design(runs, paired)
    weights = episode_weights(design, n_boot, rng)
    boot_excess: dict[tuple[str, str, str], np.ndarray] = {}
    references: dict[tuple[str, str, str], np.ndarray] = {}
    pair_references: dict[tuple[str, str, str, str], np.ndarray] = {}
    frames: dict[str, list[pd.DataFrame]] = {k: [] for k in ("head", "null", "cross", "ord",
                                                           "rank", "placebo", "pair_head",
                                                           "pair_null", "inter",
                                                           "inter_null", "pairs")}
    for metric in metrics:
        boot = resampled_metrics(design, weights, (metric,))
        o = orderings(cells, design, boot, metric, level=level)
        if controller is not None:
            o = o.involving(controller)
        for label, d in designs.items():
            obs_pairs, null_pairs = d.observed, d.nulls
            # the raw rule against recombined designs where the null has several units
            # (docs/analysis.md §10), for the headline and a card's rates alike
            rows, reps = null_test(o, obs_pairs, null_pairs, ci_level=ci_level,
                                   units=d.units, null_size=(null_sizes or {}).get(label))
            for row in rows:
                boot_excess[(label, metric, row["rule"])] = row.pop("boot_excess")
                if "reference" in row:
                    references[(label, metric, row["rule"])] = row.pop("reference")
            frames["head"].append(pd.DataFrame(rows).assign(comparison=label))
            frames["null"].append(reps.assign(comparison=label))
            for other in _others(o, controller):
                assert controller is not None
                one, one_reps = null_test(o.involving(controller, other), obs_pairs, null_pairs,
                                          ci_level=ci_level, units=d.units)
                for row in one:
                    if "reference" in row:
                        pair_references[(label, other, metric, row["rule"])] = \
                            row.pop("reference")
                frames["pair_head"].append(pd.DataFrame(one).drop(columns="boot_excess")
                                           .assign(comparison=label, baseline=other))
                frames["pair_null"].append(one_reps.assign(comparison=label, baseline=other))
            if null_pairs and interaction:
                row, reps = interaction_test(o, obs_pairs, null_pairs,
                                             null_size=(null_sizes or {}).get(label),
                                             units=d.units)
                frames["inter"].append(pd.DataFrame([row]).assign(comparison=label))
                frames["inter_null"].append(reps.assign(comparison=label))
            if rates_only:
                continue
            if null_pairs and len(obs_pairs) > 1 and controller is None:
                frames["pairs"].append(pair_counts(o, d).assign(comparison=label))
            frames["cross"].append(crossover_tests(o, _populations(obs_pairs), method=method,
                                                   alpha=alpha)
                                   .assign(comparison=label, metric=metric))
            frames["placebo"].append(placebo_crossovers(o, null_pairs, method=method,
                                                        alpha=alpha)
                                     .assign(comparison=label, metric=metric))
        if rates_only:
            continue
        table = o.table()
        frames["ord"].append(table[table["population"].isin(observed)])
        frames["rank"].append(controller_ranks(cells, boot[metric], metric, observed,
                                               level=level))
        del boot, o
    cat = {k: pd.concat(v, ignore_index=True) if v else pd.DataFrame() for k, v in frames.items()}
    return Tested(cat["head"], cat["null"], cat["cross"], cat["ord"], cat["rank"],
                  cat["placebo"], n_boot, level, boot_excess, cat["pair_head"], cat["pair_null"],
                  cat["inter"], cat["inter_null"], cat["pairs"], references, pair_references)


def _others(o: Orderings, controller: str | None) -> list[str]:
    """The controllers ``controller`` is ordered against in ``o`` (none without one)."""
    if controller is None:
        return []
    return [a if b == controller else b for a, b in o.pairs]


def _populations(pairs: Sequence[tuple[str, str]]) -> list[str]:
    return sorted({p for pair in pairs for p in pair})


def placebo_crossovers(o: Orderings, nulls: Sequence[Sequence[tuple[str, str]]], *,
                       method: str = "holm", alpha: float = ALPHA) -> pd.DataFrame:
    """The crossover test run on each null replicate's populations as if they were the
    observed (a placebo: none of them differs from another but by chance), one row per
    replicate: ``tests``, ``crossovers`` (surviving the table's control) and ``any``."""
    rows = []
    for k, pairs in enumerate(nulls, start=1):
        c = crossover_tests(o, _populations(pairs), method=method, alpha=alpha)
        rows.append({"replicate": k, "tests": int(c["p"].notna().sum()),
                     "crossovers": int(c["crossover"].sum()),
                     "any": bool(c["crossover"].any())})
    return pd.DataFrame(rows, columns=["replicate", "tests", "crossovers", "any"])


def controller_ranks(cells: pd.DataFrame, boot: np.ndarray, metric: str,
                     populations: Sequence[str], *, level: float = LEVEL) -> pd.DataFrame:
    """Each controller's rank (1 = best, lowest) per population on the grid mean of
    ``metric`` (mean over the population's cells, as Table II), with the interval of
    its rank over the resamples (``boot``: (B, R) aligned with ``cells``) and the
    share of resamples in which it ranks first. Units where a controller has no value
    are left out for every controller of that population, so means are paired."""
    rows = []
    for pop in populations:
        sel = (cells["population"] == pop).to_numpy()
        sub = cells.loc[sel, ["backend", "mapping", "cell", "controller", metric]]
        wide = sub.pivot(index=["backend", "mapping", "cell"], columns="controller",
                         values=metric)
        keep_units = wide.notna().all(axis=1)
        if not keep_units.any():
            continue
        ctrl = list(wide.columns)
        idx = np.flatnonzero(sel)
        pos = sub.reset_index(drop=True).assign(i=idx).pivot(
            index=["backend", "mapping", "cell"], columns="controller", values="i")
        pos = pos[keep_units].to_numpy(np.int64)  # (U, K)
        point = wide[keep_units].to_numpy(float).mean(axis=0)
        with np.errstate(all="ignore"):
            means = np.nanmean(boot[:, pos], axis=1)  # (B, K)
        ranks = means.argsort(axis=1).argsort(axis=1) + 1
        a = (1 - level) / 2
        for j, c in enumerate(ctrl):
            lo, hi = np.quantile(ranks[:, j], [a, 1 - a])
            rows.append({"metric": metric, "population": pop, "controller": c,
                         "value": float(point[j]),
                         "rank": int(point.argsort().argsort()[j] + 1),
                         "rank_low": int(lo), "rank_high": int(hi),
                         "p_first": float((ranks[:, j] == 1).mean()),
                         "n_cells": int(keep_units.sum())})
    return pd.DataFrame(rows)


def complete_design(runs: pd.DataFrame, pedestrians: pd.DataFrame, populations: Sequence[str]
                    ) -> tuple[pd.DataFrame, pd.DataFrame]:
    """The runs and pedestrians of ``populations`` on the episodes (per backend and
    mapping) where every one of them was run, with every controller the others have:
    an observed comparison and its nulls are then computed on the same design."""
    r = runs[runs["population"].isin(populations)]
    key = ["episode", "backend", "mapping"]
    per = r.groupby([*key, "population"]).size().unstack("population")
    full = per.reindex(columns=list(populations)).notna().all(axis=1)
    keep = per.index[full & per.nunique(axis=1).eq(1)]  # same run count everywhere
    ok = pd.MultiIndex.from_frame(r[key]).isin(keep)
    r = r[ok]
    p = pedestrians[pedestrians["population"].isin(populations)]
    p = p[pd.MultiIndex.from_frame(p[key]).isin(keep)]
    return r, p
