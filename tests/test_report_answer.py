"""The report leads with the answer: excess over the null, CI and p, computed from the tables."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml

from popnavshift.analysis.evidence import test_comparisons as run_tests
from popnavshift.analysis.nulls import headline_designs
from popnavshift.engine.runner import run_study
from popnavshift.engine.study import study_from_dict
from popnavshift.report import build_report

EPISODES = {"scenes": ["sidewalk", "bottleneck"], "widths": [1.8, 4.2], "densities": [0.06],
            "robot_speeds": [1.0], "variants": [1, 2]}
STUDY = {
    "name": "answer-test", "seed": 0, "personas": {"source": "synthetic", "n": 300},
    "matched_n": 60,
    "parts": {
        "main": {"populations": ["homogeneous", "mixed", "matched_base", "matched_deadline"],
                 "episodes": EPISODES},
        "sized_null": {"populations": ["homogeneous", "mixed", "matched_base",
                                       "matched_deadline"],
                       "null_design": {"kind": "sized", "replicates": 2}, "episodes": EPISODES},
        "matched": {"populations": ["matched_base", "matched_deadline"], "seeds": [1],
                    "episodes": EPISODES},
        "swap_null": {"null_design": {"kind": "swap", "replicates": 3}, "seeds": [1],
                      "episodes": EPISODES},
    },
}
N_BOOT = 100


@pytest.fixture(scope="module")
def study(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("answer")
    run_study(study_from_dict(STUDY), folder, workers=1, show_progress=False)
    build_report(folder, rng_seed=0, n_boot=N_BOOT, replays=0)
    return folder


def test_the_report_opens_with_the_headline_box(study):
    page = (study / "report" / "index.html").read_text("utf-8")
    box = page.index('id="headline"')
    assert box < page.index('id="table1"')  # before every reproduction table
    head = page[box: page.index("</div>", box)]
    assert "swap permutations" in head and "size-matched subsets of mixed" in head
    assert "excess" in head and "p = " in head and "Paper's rule: raw rate" in head
    # each raw-rule line carries its own verdict, beside the significant rule's
    assert head.count("Paper's rule: raw rate") == head.count('→ <span class="verdict') / 2 > 0
    for name in ("evidence_headline", "evidence_null_rates", "evidence_ranks",
                 "evidence_power", "evidence_curve", "evidence_crossovers"):
        assert (study / "report" / "tables" / f"{name}.csv").exists(), name
    assert (study / "report" / "figures" / "evidence_nulls.png").exists()
    # with 3 and 2 null replicates no p can reach 0.05: Table I is labelled descriptive
    table1 = page[page.index('id="table1"'):]
    assert "Descriptive: for the matched intervention and the population pairs" in table1


def test_the_headline_is_recomputed_from_the_parquet_tables(study):
    runs = pd.read_parquet(study / "runs.parquet")
    peds = pd.read_parquet(study / "pedestrians.parquet")
    obs = ["matched_base", "matched_deadline"]
    pops = ["matched_base", "matched_deadline"] + [f"matched_swap{k}_{a}" for k in (1, 2, 3)
                                                   for a in "ab"]
    r, p = runs[runs["population"].isin(pops)], peds[peds["population"].isin(pops)]
    designs = {"matched": headline_designs(pops, obs)["matched"]}
    got = run_tests(r, p, designs, obs, rng=np.random.default_rng([0, 0]), n_boot=N_BOOT)
    table = pd.read_csv(study / "report" / "tables" / "evidence_headline.csv")
    table = table[table["comparison"] == "matched"].set_index(["metric", "rule"])
    for row in got.headline.itertuples():
        mine = table.loc[(row.metric, row.rule)]
        assert mine["n_null"] == row.n_null
        assert row.rule == "sig" or row.n_null == 3
        for col in ("observed", "null_mean", "excess", "ci_low", "ci_high", "p_value"):
            a, b = float(mine[col]), float(getattr(row, col))
            assert (np.isnan(a) and np.isnan(b)) or a == pytest.approx(b, abs=1e-9), col


def test_plan_prints_the_power_advice_of_a_pilot(study, tmp_path):
    cfg = tmp_path / "s.yaml"
    cfg.write_text(yaml.safe_dump(STUDY))
    out = subprocess.run([sys.executable, "-m", "popnavshift", "plan", str(cfg), "--from",
                          str(study)], capture_output=True, text=True, timeout=120,
                         env={**os.environ, "COLUMNS": "200"})
    assert out.returncode == 0, out.stderr
    text = " ".join((out.stdout + out.stderr).split())  # the console writes to stderr
    assert "power (from" in text and "matched" in text and "80% power" in text
    bare = subprocess.run([sys.executable, "-m", "popnavshift", "plan", str(cfg), "--from",
                           str(tmp_path)], capture_output=True, text=True, timeout=120)
    assert bare.returncode == 0 and "no estimate yet" in bare.stdout + bare.stderr


def test_every_html_id_of_the_report_is_unique(study):
    """The table of contents links to each section by its id: no other element may
    carry it (the respondent banner once took the respondent section's)."""
    import re

    page = (study / "report" / "index.html").read_text("utf-8")
    ids = re.findall(r'\bid="([^"]+)"', page)
    assert ids and len(ids) == len(set(ids)), sorted(i for i in ids if ids.count(i) > 1)
