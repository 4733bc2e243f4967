"""How closely the all-pairs null matches the cohorts it stands in for.

The all-pairs comparison judges each cohort pair (P, Q) against (P_sized k, Q_sized k):
random subsets of ``mixed`` of the cohorts' sizes (``populations/identity.py``, kind
``sized``). That null is exchangeable with the cohorts only if a cohort looks like a random
subset of ``mixed``. Two measurements say how far it does, from the populations table alone
(no runs; deterministic for a seed):

* ``cohort_dispersion``: per cohort and motion parameter, the SD of the cohort's profiles
  against the SDs of ``draws`` random subsets of ``mixed`` of the cohort's size (the null's
  own construction): their ratio and the share of random subsets at or below the cohort's
  SD (the subsets of a cohort drawn from a seed of the study seed, its mapping and its
  name). A cohort selected on a persona field is usually *less* dispersed than a random subset
  (ratio < 1, share near 0). ``in_source``: the share of its members whose profile is one of
  ``mixed`` (``homogeneous``, the median profile, and the deadline arm are not).
* ``cohort_overlaps``: per cohort pair, the personas the two share against what two
  independent random subsets of their sizes share (hypergeometric: mean n_P n_Q / N), with
  the probability of an overlap at most / at least as extreme.

Definitions in ``docs/analysis.md`` §7.
"""

from __future__ import annotations

from collections.abc import Sequence
from itertools import combinations

import numpy as np
import pandas as pd
from scipy import stats

from ..hashing import stable_seed
from ..populations.identity import SIZED_SOURCE
from ..tables import PARAMS

DRAWS = 2000  # random subsets per cohort: the share below is known to ±1.1 pp (SE at 50 %)


def _profiles(populations: pd.DataFrame, mapping: str, population: str) -> pd.DataFrame:
    p = populations[(populations["mapping"] == mapping) & (populations["population"] == population)]
    return p[["persona_id", *PARAMS]].reset_index(drop=True)


def _in_source(members: pd.DataFrame, source: pd.DataFrame) -> float:
    """Share of ``members`` whose (persona, profile) is a row of ``source``."""
    if members.empty:
        return float("nan")
    hit = members.merge(source.drop_duplicates(), on=["persona_id", *PARAMS], how="inner")
    return float(len(hit) / len(members))


def random_subset_sds(source: np.ndarray, size: int, draws: int,
                      rng: np.random.Generator) -> np.ndarray:
    """(draws, K) the SD (ddof 1) of each column of ``draws`` random subsets of ``size`` rows
    of ``source`` (N, K), drawn without replacement as the sized null draws them."""
    keys = rng.random((draws, len(source)))
    pick = np.argpartition(keys, size - 1, axis=1)[:, :size]
    return source[pick].std(axis=1, ddof=1)


def cohort_dispersion(populations: pd.DataFrame, cohorts: Sequence[str], *,
                      draws: int = DRAWS, seed: int = 0) -> pd.DataFrame:
    """One row per (mapping, cohort, parameter) of the populations table (module doc):
    ``n``, ``in_source``, ``sd`` (the cohort's), ``random_sd`` (mean over ``draws`` random
    subsets of mixed of size n), ``sd_ratio`` = sd / random_sd, ``share_below`` (share of the
    random subsets whose SD is at or below the cohort's). NaN SDs for a cohort of one
    member; cohorts absent from a mapping are skipped, and so is mixed (its own subset)."""
    rows = []
    cohorts = [c for c in cohorts if c != SIZED_SOURCE]
    for mapping in sorted(populations["mapping"].unique()):
        source = _profiles(populations, mapping, SIZED_SOURCE)
        if len(source) < 2:
            continue
        values = source[list(PARAMS)].to_numpy(float)
        for cohort in cohorts:
            members = _profiles(populations, mapping, cohort)
            n = len(members)
            if n == 0:
                continue
            sd = members[list(PARAMS)].std(ddof=1).to_numpy(float)
            rng = np.random.default_rng(stable_seed(seed, mapping, cohort))
            rand = (random_subset_sds(values, n, draws, rng) if 2 <= n <= len(values)
                    else np.full((1, len(PARAMS)), np.nan))
            mean_sd = rand.mean(axis=0)
            below = (rand <= sd).mean(axis=0)
            share = _in_source(members, source)
            for j, param in enumerate(PARAMS):
                ok = np.isfinite(sd[j]) and np.isfinite(mean_sd[j]) and mean_sd[j] > 0
                rows.append({"mapping": mapping, "cohort": cohort, "parameter": param, "n": n,
                             "in_source": share, "sd": sd[j], "random_sd": mean_sd[j],
                             "sd_ratio": sd[j] / mean_sd[j] if ok else np.nan,
                             "share_below": below[j] if ok else np.nan,
                             "draws": draws if ok else 0})
    return pd.DataFrame(rows, columns=["mapping", "cohort", "parameter", "n", "in_source", "sd",
                                       "random_sd", "sd_ratio", "share_below", "draws"])


def dispersion_summary(dispersion: pd.DataFrame) -> pd.DataFrame:
    """Per (mapping, cohort): ``n``, ``in_source``, the mean and range of its parameters'
    SD ratios and how many parameters lie below 2.5 % of the random subsets
    (``params_below``: share_below < 0.025) or above 97.5 % (``params_above``)."""
    g = dispersion.dropna(subset=["sd_ratio"]).groupby(["mapping", "cohort"], sort=False)
    return g.agg(n=("n", "first"), in_source=("in_source", "first"),
                 sd_ratio_mean=("sd_ratio", "mean"), sd_ratio_min=("sd_ratio", "min"),
                 sd_ratio_max=("sd_ratio", "max"),
                 params_below=("share_below", lambda s: int((s < 0.025).sum())),
                 params_above=("share_below", lambda s: int((s > 0.975).sum()))).reset_index()


def cohort_overlaps(populations: pd.DataFrame, pairs: Sequence[tuple[str, str]]
                    ) -> pd.DataFrame:
    """One row per (mapping, cohort pair) of ``pairs``: ``n_a``, ``n_b``, ``shared`` (persona
    ids in both), ``expected`` and ``expected_sd`` of the overlap of two independent random
    subsets of mixed of those sizes (hypergeometric on N = |mixed|), ``p_low`` = P(overlap ≤
    shared) and ``p_high`` = P(overlap ≥ shared) under those subsets."""
    rows = []
    for mapping in sorted(populations["mapping"].unique()):
        n_source = len(_profiles(populations, mapping, SIZED_SOURCE))
        if n_source == 0:
            continue
        ids = {c: set(_profiles(populations, mapping, c)["persona_id"])
               for pair in pairs for c in pair}
        for a, b in pairs:
            na, nb = len(ids[a]), len(ids[b])
            if na == 0 or nb == 0:
                continue
            shared = len(ids[a] & ids[b])
            h = stats.hypergeom(n_source, min(na, n_source), min(nb, n_source))
            rows.append({"mapping": mapping, "cohort_a": a, "cohort_b": b, "n_a": na, "n_b": nb,
                         "n_source": n_source, "shared": shared, "expected": float(h.mean()),
                         "expected_sd": float(h.std()), "p_low": float(h.cdf(shared)),
                         "p_high": float(h.sf(shared - 1))})
    return pd.DataFrame(rows, columns=["mapping", "cohort_a", "cohort_b", "n_a", "n_b",
                                       "n_source", "shared", "expected", "expected_sd", "p_low",
                                       "p_high"])


def cohort_pairs(cohorts: Sequence[str]) -> list[tuple[str, str]]:
    """Every pair of ``cohorts`` other than the sized null's source (mixed stands for
    itself: its overlap with a cohort is the same in the null)."""
    return list(combinations([c for c in cohorts if c != SIZED_SOURCE], 2))
