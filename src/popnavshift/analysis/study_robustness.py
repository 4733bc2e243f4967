"""The robustness parts of a study (paper §IV-C, §V-D, §V-E) as tables.

Each part whose role (:meth:`popnavshift.design.study.Study.role`) is one of
:data:`ROLE_TABLES` (``mapping``, ``structure``, ``backend``, ``respondent``), whatever
its name, is selected from the runs table by its own episodes, populations,
backends and profile sets (:func:`popnavshift.read.folder.part_runs`) and analysed with
:mod:`popnavshift.analysis.robustness`; parts repeated on extra seed sets give the
spread of their rates. Every table of profile sets carries the sets' columns of the
runs table (``profile_base``, ``perturbation``, ``perturbation_arg``) beside their
``mapping`` label, so readers never parse the label.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pandas as pd

from ..populations.perturb import with_profile_set_columns
from ..read.folder import StudyFolder, part_runs
from ..tables import PROFILE_SET_COLUMNS
from .delay import cell_metrics, paired_delays
from .robustness import agreement_with, backend_rates, matched_rates, rates_by_set

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


Tables = dict[str, pd.DataFrame]


def _mapping(cells: pd.DataFrame, sets: pd.DataFrame, rng: np.random.Generator,
             n_boot: int) -> Tables:
    return {"robust_mapping": with_sets(rates_by_set(cells, rng=rng, n_boot=n_boot), sets),
            "robust_agreement": with_sets(agreement_with(cells, "A"), sets)}


def _structure(cells: pd.DataFrame, sets: pd.DataFrame, rng: np.random.Generator,
               n_boot: int) -> Tables:
    return {"robust_structure": with_sets(rates_by_set(cells, rng=rng, n_boot=n_boot), sets)}


def _backend(cells: pd.DataFrame, sets: pd.DataFrame, rng: np.random.Generator,
             n_boot: int) -> Tables:
    return {"robust_backend": backend_rates(cells, rng=rng, n_boot=n_boot)}


def _respondent(cells: pd.DataFrame, sets: pd.DataFrame, rng: np.random.Generator,
                n_boot: int) -> Tables:
    return {"robust_respondent": with_sets(matched_rates(cells, rng=rng, n_boot=n_boot), sets)}


#: the tables of each robustness role, from the part's cells and profile sets; the
#: report's section of a role is missing (keyed by its table ``robust_<role>``) when no
#: part has it
ROLE_TABLES: dict[str, Callable[[pd.DataFrame, pd.DataFrame, np.random.Generator, int],
                                Tables]] = {
    "mapping": _mapping, "structure": _structure, "backend": _backend,
    "respondent": _respondent}


def robustness_tables(
    study: StudyFolder, *, rng_seed: int = 0, n_boot: int = 1000
) -> tuple[dict[str, pd.DataFrame], dict[str, str]]:
    """Tables ``robust_<role>`` (and ``robust_agreement``) and why any is missing (by the
    table's name)."""
    tables: dict[str, pd.DataFrame] = {}
    missing: dict[str, str] = {}
    for role, compute in ROLE_TABLES.items():
        found = None if study.study is None else study.study.part_with(role)
        got = None if found is None else part_cells(study, found[0])
        if got is None:
            missing[f"robust_{role}"] = (f"the study has no part with role {role!r} (or it "
                                         "has no runs)")
            continue
        tables.update(compute(*got, np.random.default_rng(rng_seed), n_boot))
    spread = seed_spread(study, rng_seed=rng_seed, n_boot=n_boot)
    if spread is None:
        missing["robust_seeds"] = ("no study part was repeated with extra episode seed sets "
                                   "(`seeds`)")
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
    spec = study.study
    if spec is None:
        return None
    frames = []
    for name, part in spec.parts.items():
        seeds = [s for s in part.seeds if s != spec.seed]
        if not seeds or part.null_design is not None:
            continue
        for seed in [spec.seed, *seeds]:
            got = part_cells(study, name, seed)
            if got is None:
                continue
            rates = rates_by_set(got[0], rng=np.random.default_rng(rng_seed), n_boot=n_boot)
            frames.append(with_sets(rates, got[1]).assign(part=name, seed_set=seed))
    if not frames:
        return None
    out = pd.concat(frames, ignore_index=True)
    return out[["part", "seed_set", *[c for c in out.columns if c not in ("part", "seed_set")]]]
