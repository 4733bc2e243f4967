"""The report leads with the answer in plain words, then the headline box: verdicts against
the null, their intervals and p, calibration — computed from the tables."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml

from forked_cli import run_cli
from popnavshift.analysis.evidence import test_comparisons as run_tests
from popnavshift.analysis.nulls import headline_designs
from popnavshift.analysis.verdicts import binomial_floor, decide
from popnavshift.design.study import study_from_dict
from popnavshift.engine.runner import run_study
from popnavshift.read.folder import open_study
from popnavshift.report import build_report

pytestmark = pytest.mark.slow  # each test reads a study run and reported once (~1 min)

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


def test_the_report_opens_with_the_answer_in_plain_words(study):
    page = (study / "report" / "index.html").read_text("utf-8")
    answer = page.index('id="plain-answer"')
    box = page.index('id="headline"')
    assert answer < box < page.index('id="table1"')  # before every reproduction table
    plain = page[answer:box]
    assert "Do controller rankings change with the pedestrian population beyond noise?" in plain
    assert "Pedestrian burden:" in plain and "Robot time:" in plain
    assert "placebos" in plain  # the deciding test's false-positive rate on this study
    assert "Two questions per metric and design." in plain  # the interaction test, and rates
    assert "not whether orderings cross" in plain
    head = page[box: page.index("</div>", box)]
    assert "swap permutations" in head and "size-matched random subsets of mixed" in head
    assert "prediction t" in head and "Exact permutation" in head and "episode-only" in head
    # one verdict per (comparison, metric) line, the raw rule's, for every rate with a null
    table = pd.read_csv(study / "report" / "tables" / "evidence_headline.csv")
    tested = table[(table["rule"] == "raw") & (table["n_null"] > 0)]
    assert head.count('→ <span class="verdict') == len(tested)
    # blocked pedestrians are judged like the delays wherever their rate exists
    assert {"mean_delay", "worst_decile", "cvar90", "robot_time"} <= set(tested["metric"])
    assert "blocked pedestrians" in head or "blocked_pct" not in set(tested["metric"])
    for name in ("evidence_headline", "evidence_null_rates", "evidence_ranks",
                 "evidence_power", "evidence_curve", "evidence_crossovers",
                 "evidence_calibration", "evidence_interaction", "evidence_interaction_nulls"):
        assert (study / "report" / "tables" / f"{name}.csv").exists(), name
    assert (study / "report" / "figures" / "evidence_nulls.png").exists()
    assert 'id="calibration"' in page


def test_the_plain_answer_follows_the_verdicts():
    """Change the verdicts and the words change: nothing in the paragraph is fixed text."""
    from popnavshift.analysis.verdicts import ABOVE, SMALL, UNDECIDED
    from popnavshift.report.plain import answer_sentences

    def row(comp, metric, verdict, excess):
        return {"comparison": comp, "metric": metric, "rule": "raw", "verdict": verdict,
                "excess": excess, "ci_low": excess - 0.03, "ci_high": excess + 0.03,
                "n_null": 9, "null": "swap" if comp == "matched" else "sized",
                "seed_sets": 4, "variants_per_cell": 12, "reversals": 5, "comparable": 50,
                "observed": 0.3}

    head = pd.DataFrame([row("matched", "mean_delay", ABOVE, 0.09),
                         row("matched", "cvar90", UNDECIDED, 0.02),
                         row("matched", "robot_time", SMALL, 0.0)])
    answer, _ = answer_sentences({"evidence_headline": head})
    text = " ".join(a["lead"] + " " + a["text"] for a in answer)
    assert ("Pedestrian burden: under the matched shift, orderings reverse beyond the null for "
            "mean delay (undecided for CVaR-90 delay)." in text)
    assert "Robot time: under the matched shift, orderings show no excess of reversals" in text
    assert "mean delay orderings reverse more often than under the null (+9.0 pp [+6.0, +12.0])" \
        in text and "CVaR-90 delay orderings are undecided" in text
    head.loc[0, "verdict"] = UNDECIDED
    answer, _ = answer_sentences({"evidence_headline": head})
    assert answer[1]["lead"] == ("Pedestrian burden: under the matched shift, orderings are "
                                 "undecided.")
    head["verdict"] = SMALL
    assert answer_sentences({"evidence_headline": head})[0][1]["lead"] == (
        "Pedestrian burden: under the matched shift, orderings show no excess of reversals of "
        "5 pp or more.")


def test_calibrate_prints_every_rules_false_positive_rate(study):
    out = subprocess.run([sys.executable, "-m", "popnavshift", "calibrate", str(study)],
                         capture_output=True, text=True, timeout=300,
                         env={**os.environ, "COLUMNS": "200"})
    text = " ".join((out.stdout + out.stderr).split())
    assert out.returncode == 0, text
    for rule in ("prediction t", "exact permutation", "crossover test", "episode-only"):
        assert rule in text, rule
    assert "no verdict rule claims more than its nominal level" in text
    assert "prediction t" in out.stdout  # the tables are the output: `calibrate S > f` keeps them
    empty = run_cli("calibrate", str(study / "nowhere"))
    assert empty.returncode == 2 and "Traceback" not in empty.stderr


def test_the_headline_is_recomputed_from_the_parquet_tables(study):
    runs = pd.read_parquet(study / "runs.parquet")
    peds = pd.read_parquet(study / "pedestrians.parquet")
    obs = ["matched_base", "matched_deadline"]
    pops = ["matched_base", "matched_deadline"] + [f"matched_swap{k}_{a}" for k in (1, 2, 3)
                                                   for a in "ab"]
    r, p = runs[runs["population"].isin(pops)], peds[peds["population"].isin(pops)]
    index = open_study(study).population_specs
    designs = {"matched": headline_designs([index[p] for p in pops], obs)["matched"]}
    got = run_tests(r, p, designs, obs, rng=np.random.default_rng([0, 0]), n_boot=N_BOOT)
    table = pd.read_csv(study / "report" / "tables" / "evidence_headline.csv")
    table_all = table
    table = table[table["comparison"] == "matched"].set_index(["metric", "rule"])
    nulls = got.null_rates
    for row in got.headline.itertuples():
        mine = table.loc[(row.metric, row.rule)]
        assert mine["n_null"] == row.n_null
        # every raw rate has its 3 null replicates, unless no ordering is untied (no rate)
        assert row.rule == "sig" or row.n_null == 3 or row.comparable == 0
        for col in ("observed", "null_mean", "excess", "p_value", "p_t", "episode_ci_low",
                    "episode_ci_high"):
            a, b = float(mine[col]), float(getattr(row, col))
            assert (np.isnan(a) and np.isnan(b)) or a == pytest.approx(b, abs=1e-9), col
        # the report decides the whole table together: each rate at 5% / (its m rates)
        null = nulls[(nulls["metric"] == row.metric) & (nulls["rule"] == row.rule)]["rate"]
        mine_nulls = nulls[(nulls["metric"] == row.metric) & (nulls["rule"] == row.rule)]
        floor = binomial_floor(mine_nulls["reversals"], mine_nulls["comparable"])
        d = decide(row.observed, null.to_numpy(float), row.rule, alpha=0.05 / mine["family"],
                   floor=floor)
        # the family: every rate of the rule with a null, over both comparisons
        rule_rows = table_all[table_all["rule"] == row.rule]
        assert mine["family"] == int((rule_rows["n_null"] > 0).sum())
        assert mine["verdict"] == d["verdict"]
        for col in ("ci_low", "ci_high"):
            a, b = float(mine[col]), float(d[col])
            assert (np.isnan(a) and np.isnan(b)) or a == pytest.approx(b, abs=1e-9), col


def test_plan_prints_the_power_advice_of_a_pilot(study, tmp_path):
    cfg = tmp_path / "s.yaml"
    cfg.write_text(yaml.safe_dump(STUDY))
    out = subprocess.run([sys.executable, "-m", "popnavshift", "plan", str(cfg), "--from",
                          str(study)], capture_output=True, text=True, timeout=120,
                         env={**os.environ, "COLUMNS": "200"})
    assert out.returncode == 0, out.stderr
    text = " ".join(out.stdout.split())  # the tables are the output: stdout
    assert "power (from" in text and "matched" in text and "80% power" in text
    assert "what would decide it" in text
    pilot = tmp_path / "pilot"  # a study folder without a report yet
    pilot.mkdir()
    (pilot / "stages.json").write_text("{}")
    bare = run_cli("plan", str(cfg), "--from", str(pilot))
    assert bare.returncode == 0 and "no estimate yet" in bare.stdout + bare.stderr


def test_every_html_id_of_the_report_is_unique(study):
    """The table of contents links to each section by its id: no other element may
    carry it (the respondent banner once took the respondent section's)."""
    import re

    page = (study / "report" / "index.html").read_text("utf-8")
    ids = re.findall(r'\bid="([^"]+)"', page)
    assert ids and len(ids) == len(set(ids)), sorted(i for i in ids if ids.count(i) > 1)


def test_the_decided_orderings_sentence_follows_the_permutation_verdicts():
    from popnavshift.analysis.verdicts import DESCRIPTIVE, NOT_SHOWN
    from popnavshift.report.plain_support import decided_sentence

    head = pd.DataFrame([{"comparison": "matched", "metric": m, "rule": "sig", "n_null": 19,
                          "verdict": DESCRIPTIVE, "level": 1 - 0.05 / 8, "reversals": 1,
                          "comparable": 40, "observed": 0.025}
                         for m in ("mean_delay", "robot_time")])
    text = decided_sentence(head)["text"]
    assert "cannot decide (19 null replicates" in text and "it needs 159" in text
    head["verdict"] = NOT_SHOWN
    assert "shows none above the null" in decided_sentence(head)["text"]


def test_a_p_near_the_level_reads_to_two_significant_digits():
    """A randomization p of 19,999 draws either side of 0.005 must not print as 0.005 both."""
    from popnavshift.report.answer import _p

    assert [_p(x) for x in (0.0049, 0.005, 0.0051, 0.02, 1.0)] == [
        "0.0049", "0.0050", "0.0051", "0.020", "1.000"]
    assert _p(1 / 20000) == "0.000050" and _p(0.0) == "0.000"
    assert _p(np.nan) == _p(None) == _p(pd.NA) == "–"
