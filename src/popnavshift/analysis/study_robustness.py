"""The robustness parts of a study (paper §IV-C, §V-D, §V-E) as tables.

Each part named in the study's manifest (``mapping``, ``structure``, ``backend``,
``respondent``) is selected from the runs table by its own episodes, populations,
backends and profile sets (:func:`popnavshift.engine.folder.part_runs`) and analysed with
:mod:`popnavshift.analysis.robustness`; parts repeated on extra seed sets give the
spread of their rates. The paper's figures are declared here, beside the analysis.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from ..engine.folder import StudyFolder, part_runs
from .delay import cell_metrics, paired_delays
from .robustness import agreement_with, backend_rates, matched_rates, rates_by_set

#: The paper's robustness figures (rates as fractions), for the tables beside ours.
PAPER_ROBUSTNESS: dict[str, dict[str, dict[str, float]]] = {
    "mapping": {
        "A": {"mean_delay": 0.245, "worst_decile": 0.260},
        "B": {"mean_delay": 0.242, "worst_decile": 0.286},
        "C": {"mean_delay": 0.246, "worst_decile": 0.257},
        "D": {"mean_delay": 0.375, "worst_decile": 0.358},
    },
    "agreement": {
        "B": {"mean_delay": 0.923, "worst_decile": 0.926},
        "C": {"mean_delay": 0.922, "worst_decile": 0.918},
        "D": {"mean_delay": 0.768, "worst_decile": 0.710},
    },
    "structure": {
        "A": {"mean_delay": 0.284, "worst_decile": 0.269},
        "A~reassign": {"mean_delay": 0.198, "worst_decile": 0.188},
        "A~shuffle": {"mean_delay": 0.268, "worst_decile": 0.297},
    },
    "backend": {
        "orca": {"robot_time": 0.032, "mean_delay": 0.105, "worst_decile": 0.098},
        "hl": {"robot_time": 0.024, "mean_delay": 0.352, "worst_decile": 0.346},
    },
    "respondent": {
        "A": {"robot_time": 0.086, "mean_delay": 0.224, "worst_decile": 0.239},
        "second": {"robot_time": 0.091, "mean_delay": 0.256, "worst_decile": 0.265},
    },
}


PARTS = ("mapping", "structure", "backend", "respondent")


def part_cells(study: StudyFolder, name: str, seed: int | None = None) -> pd.DataFrame | None:
    """Cell metrics of the study part ``name`` (None when the study has no such part or
    runs); ``seed`` selects one of the part's extra seed sets (default: the study's own)."""
    got = part_runs(study, name, seed)
    return None if got is None else cell_metrics(got[0], paired_delays(got[1]))


def robustness_tables(
    study: StudyFolder, *, rng_seed: int = 0, n_boot: int = 1000
) -> tuple[dict[str, pd.DataFrame], dict[str, str]]:
    """Tables ``robust_<part>`` (and ``robust_agreement``) and why parts are missing."""
    tables: dict[str, pd.DataFrame] = {}
    missing: dict[str, str] = {}
    for name in PARTS:
        cells = part_cells(study, name)
        if cells is None:
            missing[name] = f"the study has no {name!r} part (or it has no runs)"
            continue
        rng = np.random.default_rng(rng_seed)
        if name == "mapping":
            tables["robust_mapping"] = rates_by_set(cells, rng=rng, n_boot=n_boot)
            tables["robust_agreement"] = agreement_with(cells, "A")
        elif name == "structure":
            tables["robust_structure"] = rates_by_set(cells, rng=rng, n_boot=n_boot)
        elif name == "backend":
            tables["robust_backend"] = backend_rates(cells, rng=rng, n_boot=n_boot)
        else:
            tables["robust_respondent"] = matched_rates(cells, rng=rng, n_boot=n_boot)
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
    comparisons, rate, ci_low, ci_high."""
    cfg = study.manifest.get("study_config") or {}
    frames = []
    for name, part in (cfg.get("parts") or {}).items():
        seeds = [s for s in part.get("seeds", []) if s != cfg.get("seed", 0)]
        if not seeds or part.get("null_design"):
            continue
        for seed in [cfg.get("seed", 0), *seeds]:
            cells = part_cells(study, name, seed)
            if cells is None:
                continue
            rates = rates_by_set(cells, rng=np.random.default_rng(rng_seed), n_boot=n_boot)
            frames.append(rates.assign(part=name, seed_set=seed))
    if not frames:
        return None
    out = pd.concat(frames, ignore_index=True)
    return out[["part", "seed_set", *[c for c in out.columns if c not in ("part", "seed_set")]]]
