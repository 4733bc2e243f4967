"""The rejected burden rule, measured (docs/method.md §8): build a study's report with every
blocked pedestrian counted in the delays at the 45 s limit, ΔT = 45 s − T(no robot), instead
of the SPEC's delays of pedestrians that arrived in both runs plus ``blocked_pct``.

Not part of the package and not a test: it swaps :func:`popnavshift.analysis.delay.
paired_delays` for a censored one in every module that imported it, then runs the ordinary
report. A blocked record is then an ordinary paired delay (``blocked`` False), so the delay
metrics include it and ``blocked_pct`` is 0 everywhere (it drops out of the headline family,
whose rates need an untied ordering). Run it on a COPY of a study folder: it overwrites that
folder's report.

    cp -r study /tmp/censored && \
    .venv/bin/python benchmarks/burden_censored.py /tmp/censored

then compare ``/tmp/censored/report/tables/evidence_headline.csv`` and
``controller_outcomes.csv`` with the same tables of ``popnavshift report`` on another copy.
"""

from __future__ import annotations

import argparse
import importlib
from pathlib import Path

import pandas as pd

from popnavshift.analysis import delay
from popnavshift.tables import NO_ROBOT, TIME_LIMIT

#: the modules that import ``paired_delays`` by name (grep "import.*paired_delays" src/)
USERS = ("popnavshift.analysis", "popnavshift.analysis.study", "popnavshift.analysis.summary",
         "popnavshift.analysis.evidence", "popnavshift.analysis.replicates",
         "popnavshift.analysis.study_robustness", "popnavshift.analysis.surviving",
         "popnavshift.evaluate.compare", "popnavshift.evaluate.verdict")
SPEC_RULE = delay.paired_delays


def censored_delays(pedestrians: pd.DataFrame) -> pd.DataFrame:
    """:func:`popnavshift.analysis.delay.paired_delays` with each blocked pedestrian's delay
    counted at the limit (a lower bound), and no record marked blocked."""
    out = SPEC_RULE(pedestrians)
    key = [*delay.PAIR_KEY, "slot"]
    base = pedestrians[(pedestrians["controller"] == NO_ROBOT) & pedestrians["arrived"]]
    t0 = out[key].merge(base[[*key, "travel_time"]], on=key, how="left")["travel_time"]
    blocked = out["blocked"].to_numpy(bool)
    out.loc[blocked, "delay"] = TIME_LIMIT - t0.to_numpy(float)[blocked]
    return out.assign(blocked=False)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("study_dir", type=Path, help="a COPY of a study folder")
    parser.add_argument("--n-boot", type=int, default=1000)
    args = parser.parse_args()
    modules = [importlib.import_module(name) for name in USERS]  # all, before any swap
    for module in modules:
        assert module.paired_delays is SPEC_RULE, module.__name__
        module.paired_delays = censored_delays
    from popnavshift.report import build_report

    build_report(args.study_dir, n_boot=args.n_boot)
    print(f"censored report → {args.study_dir / 'report' / 'index.html'}")


if __name__ == "__main__":
    main()
