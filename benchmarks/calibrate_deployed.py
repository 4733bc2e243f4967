"""The calibration of a study's verdict rules at a smaller deployed design, on a study that
already ran more null replicates: what ``popnavshift calibrate STUDY --replicates N``
computes in its side folder, for a folder that holds the N replicates already (e.g. the
seed-0 study of ``benchmarks/interaction_seed0.yaml``, 29 swap and 29 size-matched
replicates). Each of the N replicates is a placebo judged against the next P cyclically.

    .venv/bin/python benchmarks/calibrate_deployed.py FOLDER --null-size 9 [--csv out.csv]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import pandas as pd

from popnavshift.analysis.study_evidence import evidence_tables
from popnavshift.read.folder import open_study


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("folder", type=Path)
    ap.add_argument("--null-size", type=int, default=9)
    ap.add_argument("--csv", type=Path)
    a = ap.parse_args()
    started = time.perf_counter()
    tables, missing = evidence_tables(open_study(a.folder),
                                      null_sizes={"swap": a.null_size, "sized": a.null_size})
    cal = tables["evidence_calibration"]
    pd.set_option("display.width", 250)
    pd.set_option("display.max_columns", 20)
    cols = ["comparison", "test", "claim", "nominal", "placebos", "claims", "rate", "cp_low",
            "cp_high", "status"]
    print(cal[cols].to_string())
    if a.csv:
        cal.to_csv(a.csv, index=False)
    print(f"{time.perf_counter() - started:.0f} s; missing: {missing}")


if __name__ == "__main__":
    main()
