"""The all-pairs comparison pair by pair, on finished studies (docs/analysis.md §7): which
pairs and which attribute carry the excess, each rule's false-claim rate on the study's
placebos, the random member of homogeneous against homogeneous itself, and how the cohorts
match random subsets of mixed.

Not part of the package and not a test: it reads each study folder (never writes it) and
computes, with the package's functions, the raw reversal counts of every pair of the main
part's populations in the observed design and in every null replicate (point estimates
only: the episode bootstrap is not needed), then the tables ``popnavshift report`` writes as
``evidence_pairs``, ``evidence_pair_groups``, ``evidence_pair_placebos`` and
``evidence_cohorts``. The figures of docs/analysis.md §7 come from

    .venv/bin/python benchmarks/pair_placebos.py study DIR0 DIR1

with ``study`` from ``make run`` and DIR0, DIR1 run from benchmarks/interaction_seed0.yaml
(29 size-matched replicates) and interaction_seed1.yaml (seed 1, 19).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pandas as pd

from popnavshift.analysis.cohorts import cohort_dispersion, dispersion_summary
from popnavshift.analysis.delay import cell_metrics, paired_delays
from popnavshift.analysis.evidence import complete_design
from popnavshift.analysis.nulls import design_populations, headline_designs
from popnavshift.analysis.pair_excess import (
    group_verdicts,
    pair_counts,
    pair_verdicts,
    placebos,
    self_null_direction,
)
from popnavshift.analysis.ranked import RANKED_NAMES
from popnavshift.analysis.resample import build_design, episode_weights, resampled_metrics
from popnavshift.analysis.significance import orderings
from popnavshift.populations.identity import spec_of
from popnavshift.read.folder import open_study


def counts_of(folder: Path) -> tuple[pd.DataFrame, pd.DataFrame | None, list[str]]:
    """The pair counts of a study's all-pairs design, its populations table and its
    observed populations."""
    study = open_study(folder)
    main = study.main_part()
    assert main is not None, f"{folder}: no main part"
    part = main[1]
    runs = study.runs[study.runs["backend"].isin(part.backends)
                      & study.runs["mapping"].isin(part.mappings)]
    peds = study.pedestrians[study.pedestrians["backend"].isin(part.backends)
                             & study.pedestrians["mapping"].isin(part.mappings)]
    present = [spec_of(study.population_specs, p) for p in runs["population"].unique()]
    conds = {s.name for s in present if s.role == "observed"}
    observed = [p for p in part.populations if p in conds]
    design = headline_designs(present, observed)["all_pairs"]
    r, p = complete_design(runs, peds, design_populations(design))
    paired = paired_delays(p)
    cells, d = cell_metrics(r, paired), build_design(r, paired)
    w = episode_weights(d, 2, np.random.default_rng(0))  # point rates need no resamples
    frames = [pair_counts(orderings(cells, d, resampled_metrics(d, w, (m,)), m), design)
              for m in RANKED_NAMES]
    pops = study.populations
    if pops is not None:
        pops = pops[pops["mapping"].isin(part.mappings)]
    return pd.concat(frames, ignore_index=True), pops, observed


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("studies", nargs="+", type=Path)
    args = ap.parse_args()
    pd.set_option("display.width", 200)
    for folder in args.studies:
        counts, pops, observed = counts_of(folder)
        n_rep = int(counts["replicate"].max())
        print(f"=== {folder}: {n_rep} null replicates")
        v = pair_verdicts(counts)
        cols = ["metric", "pair", "observed", "null_mean", "excess", "t", "p_holm", "p_maxt",
                "claim"]
        print(v.sort_values("p_maxt").head(8)[cols].round(4).to_string(index=False))
        g = group_verdicts(counts)
        print(g[["metric", "group", "pairs", "observed", "null_mean", "excess", "t", "p_holm",
                 "p_maxt", "claim"]].round(4).to_string(index=False))
        print(placebos(counts).round(4).to_string(index=False))
        print(self_null_direction(v).round(4).to_string(index=False))
        if pops is not None:
            s = dispersion_summary(cohort_dispersion(pops, observed))
            print(s.round(3).to_string(index=False))


if __name__ == "__main__":
    main()
