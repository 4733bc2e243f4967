"""Time the interaction test across the population pairs at several numbers of recombined
designs, on a finished study: the observed test and its P placebos per metric, as the
report runs them (docs/analysis.md §12: more draws cost almost nothing, because each term's
mid-ranks are computed once per distinct population pair, not once per draw).

Prints, per metric and number of draws, the wall time of the whole test and the observed
p (the report's: the same episode resamples, drawn once per metric and not timed). Not a
test: run it by hand on a quiet machine.

    .venv/bin/python benchmarks/bench_interaction_draws.py study [--draws 999 19999]
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import numpy as np

from popnavshift.analysis.delay import cell_metrics, paired_delays
from popnavshift.analysis.evidence import complete_design
from popnavshift.analysis.interaction import interaction_test
from popnavshift.analysis.nulls import design_populations, headline_designs
from popnavshift.analysis.ranked import RANKED_NAMES
from popnavshift.analysis.resample import build_design, episode_weights, resampled_metrics
from popnavshift.analysis.significance import LEVEL, orderings
from popnavshift.populations.identity import spec_of
from popnavshift.read.folder import open_study


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("folder", type=Path, help="a finished study folder (e.g. make run's study)")
    ap.add_argument("--draws", type=int, nargs="+", default=[999, 19_999])
    ap.add_argument("--metrics", nargs="+", default=list(RANKED_NAMES))
    a = ap.parse_args()
    study = open_study(a.folder)
    main_part = study.main_part()
    assert main_part is not None, f"{a.folder}: the study has no main part"
    part = main_part[1]
    keep = study.runs["backend"].isin(part.backends) & study.runs["mapping"].isin(part.mappings)
    peds = study.pedestrians
    peds = peds[peds["backend"].isin(part.backends) & peds["mapping"].isin(part.mappings)]
    present = [spec_of(study.population_specs, p)
               for p in study.runs.loc[keep, "population"].unique()]
    observed = [p for p in part.populations
                if p in {s.name for s in present if s.role == "observed"}]
    designs = headline_designs(present, observed)
    design, index = designs["all_pairs"], list(designs).index("all_pairs")
    runs, peds = complete_design(study.runs[keep], peds, design_populations(design))
    paired = paired_delays(peds)
    cells, built = cell_metrics(runs, paired), build_design(runs, paired)
    # the report's episode resamples (analysis/study_evidence.py), so p is the report's
    weights = episode_weights(built, 1000, np.random.default_rng([0, index]))
    print(f"{a.folder}: {len(design.nulls)} null replicates, load average "
          f"{os.getloadavg()[0]:.2f}")
    for metric in a.metrics:
        o = orderings(cells, built, resampled_metrics(built, weights, (metric,)), metric,
                      level=LEVEL)
        for draws in a.draws:
            started = time.perf_counter()
            row, reps = interaction_test(o, design.observed, design.nulls, units=design.units,
                                         draws=draws)
            wall = time.perf_counter() - started
            print(f"{metric:>13}  {draws:>6} draws  {wall:6.1f} s  (observed and "
                  f"{len(reps)} placebos)  p {row['p_t']:.5f}", flush=True)
    print(f"load average after {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
