"""Replicates as a design axis: rates against seed sets, replicability and power.

A *seed set* is one draw of a part's episodes (ids ``<episode>@s<k>``; the study
seed's draw has no suffix); every cell gets 3 variants per seed set.

* ``replicate_curve``: the headline tests (:func:`.evidence.test_comparisons`) on
  the first 1, 2, … S seed sets (3, 6, … 3S variants per cell): how the observed
  rate, its null and the excess move as the design grows.
* ``replicability``: per seed set alone (3 variants per cell, the paper's design),
  the chance that a reversal seen in one seed set recurs, in the same direction, in
  another, beside the marginal reversal rate; for the observed pair and its null.

What would decide an undecided rate is :mod:`.power`'s, from this curve.
"""

from __future__ import annotations

from collections.abc import Sequence
from itertools import permutations

import numpy as np
import pandas as pd

from .cells import episode_cells
from .delay import cell_metrics, paired_delays
from .evidence import test_comparisons
from .nulls import Design
from .ranked import names
from .reversals import comparisons
from .significance import LEVEL

VARIANTS_PER_SEED_SET = 3  # the paper's grid; a study's own count: variants_per_cell


def variants_per_cell(runs: pd.DataFrame) -> int:
    """The episodes a cell holds in ``runs`` (its variants over every seed set: 3 per seed
    set in the paper's grid, but a study names its own episodes): the count most cells
    have."""
    if runs.empty:
        return 0
    counts = episode_cells(runs).groupby("cell").size()
    return int(counts.mode().max())
CURVE_BOOT = 200  # resamples per point of the curve (its last point is the headline's)


def seed_sets(table: pd.DataFrame) -> pd.Series:
    """The seed set of every row of a runs or pedestrians table (its ``seed_set`` column)."""
    return table["seed_set"].astype(np.int64)


def _ordered_sets(runs: pd.DataFrame, study_seed: int) -> list[int]:
    """Seed sets, the study's own first, then ascending."""
    have = sorted(set(seed_sets(runs)))
    return sorted(have, key=lambda s: (s != study_seed, s))


def replicate_curve(runs: pd.DataFrame, pedestrians: pd.DataFrame,
                    designs: dict[str, Design], observed: Sequence[str], *,
                    study_seed: int, seed: int = 0, n_boot: int = CURVE_BOOT,
                    level: float = LEVEL,
                    metrics: Sequence[str] = (*names("burden"), *names("robot")),
                    full: pd.DataFrame | None = None) -> pd.DataFrame:
    """Headline rows (:func:`.evidence.test_comparisons`) on the first k seed sets, for
    k = 1 … S; columns of the headline plus ``seed_sets`` and ``variants_per_cell``.
    Resample k uses ``numpy.random.default_rng([seed, k])``. ``full``, when given, is
    the headline already computed on all S seed sets (reused for k = S)."""
    order = _ordered_sets(runs, study_seed)
    run_sets = seed_sets(runs)
    ped_sets = seed_sets(pedestrians)
    frames = []
    for k in range(1, len(order) + 1):
        if k == len(order) and full is not None:
            frames.append(full[full["metric"].isin(metrics)].assign(
                seed_sets=k, variants_per_cell=variants_per_cell(runs)))
            continue
        use = set(order[:k])
        used = runs[run_sets.isin(use).to_numpy()]
        tested = test_comparisons(used,
                                  pedestrians[ped_sets.isin(use).to_numpy()], designs, observed,
                                  rng=np.random.default_rng([seed, k]), n_boot=n_boot,
                                  level=level, metrics=metrics, rates_only=True,
                                  interaction=False)
        frames.append(tested.headline.assign(seed_sets=k,
                                             variants_per_cell=variants_per_cell(used)))
    return pd.concat(frames, ignore_index=True)


def replicability(runs: pd.DataFrame, pedestrians: pd.DataFrame,
                  designs: dict[str, Design], *, study_seed: int,
                  metrics: Sequence[str] = names(paper=True)
                  ) -> pd.DataFrame:
    """Per (comparison, kind ∈ {observed, null design}, metric): the marginal raw reversal rate
    of one seed set and P(the reversal recurs in the same direction in another seed
    set | it reversed in one and is comparable in the other), over ordered pairs of
    distinct seed sets. Needs at least 2 seed sets (else empty)."""
    sets = seed_sets(runs)
    psets = seed_sets(pedestrians)
    order = _ordered_sets(runs, study_seed)
    if len(order) < 2:
        return pd.DataFrame()
    per_set = []
    for s in order:
        r = runs[(sets == s).to_numpy()]
        cells = cell_metrics(r, paired_delays(pedestrians[(psets == s).to_numpy()]))
        for label, d in designs.items():
            for kind, pairs in (("observed", d.observed),
                                ("null design", [p for n in d.nulls for p in n])):
                c = comparisons(cells, pairs, metrics=metrics)
                per_set.append(c.assign(seed_set=s, comparison=label, kind=kind))
    allc = pd.concat(per_set, ignore_index=True)
    key = ["comparison", "kind", "metric", "backend", "mapping", "cell", "pop_a", "pop_b",
           "ctrl_1", "ctrl_2"]
    allc["direction"] = np.where(allc["reversal"], allc["sign_a"], 0.0)
    rows = []
    for (label, kind, metric), g in allc.groupby(["comparison", "kind", "metric"], sort=False):
        rev = g.pivot_table(index=key[3:], columns="seed_set", values="direction",
                            aggfunc="first").reindex(columns=order)
        comp = g.pivot_table(index=key[3:], columns="seed_set", values="comparable",
                             aggfunc="first").reindex(columns=order)
        d, c = rev.to_numpy(float), comp.fillna(False).to_numpy(bool)
        recur = given = 0
        for i, j in permutations(range(len(order)), 2):
            seen = (d[:, i] != 0) & np.isfinite(d[:, i])
            given += int((seen & c[:, j]).sum())
            recur += int((seen & c[:, j] & (d[:, j] == d[:, i])).sum())
        n_rev, n_comp = int((np.nan_to_num(d) != 0).sum()), int(c.sum())
        rows.append({"comparison": label, "kind": kind, "metric": metric,
                     "marginal": n_rev / n_comp if n_comp else np.nan,
                     "recurrence": recur / given if given else np.nan,
                     "reversals": n_rev, "comparable": n_comp, "recurred": recur,
                     "opportunities": given, "seed_sets": len(order)})
    return pd.DataFrame(rows)
