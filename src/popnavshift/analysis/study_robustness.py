"""The robustness parts of a study (paper §IV-C, §V-D, §V-E) as tables.

Each part named in the study's manifest (``mapping``, ``structure``, ``backend``,
``respondent``) is selected from the runs table by its own episodes, populations,
backends and profile sets (:func:`popnavshift.engine.folder.part_runs`) and analysed with
:mod:`popnavshift.analysis.robustness`; parts repeated on extra seed sets give the
spread of their rates. Every table of profile sets carries the sets' columns of the
runs table (``profile_base``, ``perturbation``, ``perturbation_arg``) beside their
``mapping`` label, so readers never parse the label.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from ..engine.folder import StudyFolder, part_runs
from ..populations.perturb import with_profile_set_columns
from ..tables import PROFILE_SET_COLUMNS
from .delay import cell_metrics, paired_delays
from .robustness import agreement_with, backend_rates, matched_rates, rates_by_set

PARTS = ("mapping", "structure", "backend", "respondent")
#: the profile-set columns a table of sets carries beside ``mapping`` (``profile_set``
#: restates them)
SET_COLUMNS: tuple[str, ...] = tuple(c for c in PROFILE_SET_COLUMNS if c != "profile_set")


def part_cells(
    study: StudyFolder, name: str, seed: int | None = None
) -> tuple[pd.DataFrame, pd.DataFrame] | None:
    """Cell metrics of the study part ``name`` and its profile sets (one row per
    ``mapping`` with :data:`SET_COLUMNS`); None when the study has no such part or
    runs. ``seed`` selects one of the part's extra seed sets (default: the study's own)."""
    got = part_runs(study, name, seed)
    if got is None:
        return None
    runs, peds = got
    # a folder written before the columns existed gets them from its labels
    sets = with_profile_set_columns(runs.drop_duplicates("mapping"))[["mapping", *SET_COLUMNS]]
    return cell_metrics(runs, paired_delays(peds)), sets


def with_sets(table: pd.DataFrame, sets: pd.DataFrame) -> pd.DataFrame:
    """``table`` (one row per mapping and more) with its profile sets' columns appended."""
    return table.merge(sets, on="mapping", how="left", validate="many_to_one")


def robustness_tables(
    study: StudyFolder, *, rng_seed: int = 0, n_boot: int = 1000
) -> tuple[dict[str, pd.DataFrame], dict[str, str]]:
    """Tables ``robust_<part>`` (and ``robust_agreement``) and why parts are missing."""
    tables: dict[str, pd.DataFrame] = {}
    missing: dict[str, str] = {}
    for name in PARTS:
        got = part_cells(study, name)
        if got is None:
            missing[name] = f"the study has no {name!r} part (or it has no runs)"
            continue
        cells, sets = got
        rng = np.random.default_rng(rng_seed)
        if name == "mapping":
            tables["robust_mapping"] = with_sets(rates_by_set(cells, rng=rng, n_boot=n_boot),
                                                 sets)
            tables["robust_agreement"] = with_sets(agreement_with(cells, "A"), sets)
        elif name == "structure":
            tables["robust_structure"] = with_sets(
                rates_by_set(cells, rng=rng, n_boot=n_boot), sets)
        elif name == "backend":
            tables["robust_backend"] = backend_rates(cells, rng=rng, n_boot=n_boot)
        else:
            tables["robust_respondent"] = with_sets(
                matched_rates(cells, rng=rng, n_boot=n_boot), sets)
    spread = seed_spread(study, rng_seed=rng_seed, n_boot=n_boot)
    if spread is None:
        missing["seeds"] = "no study part was repeated with extra episode seed sets (`seeds`)"
    else:
        tables["robust_seeds"] = spread
    return tables, missing


def seed_spread(
    study: StudyFolder, *, rng_seed: int = 0, n_boot: int = 1000
) -> pd.DataFrame | None:
    """Reversal rates (all population pairs of the part) per seed set, for every part
    with extra ``seeds`` (null designs aside: the answer section tests them); None when
    no part has any. Columns: part, seed_set, metric, backend, mapping, reversals,
    comparisons, rate, ci_low, ci_high, then :data:`SET_COLUMNS`."""
    cfg = study.manifest.get("study_config") or {}
    frames = []
    for name, part in (cfg.get("parts") or {}).items():
        seeds = [s for s in part.get("seeds", []) if s != cfg.get("seed", 0)]
        if not seeds or part.get("null_design"):
            continue
        for seed in [cfg.get("seed", 0), *seeds]:
            got = part_cells(study, name, seed)
            if got is None:
                continue
            rates = rates_by_set(got[0], rng=np.random.default_rng(rng_seed), n_boot=n_boot)
            frames.append(with_sets(rates, got[1]).assign(part=name, seed_set=seed))
    if not frames:
        return None
    out = pd.concat(frames, ignore_index=True)
    return out[["part", "seed_set", *[c for c in out.columns if c not in ("part", "seed_set")]]]
