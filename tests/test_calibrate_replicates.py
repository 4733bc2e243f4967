"""``popnavshift calibrate --replicates N``: more placebos, run beside the study, each judged
against the study's own count of replicates; the study itself never changes."""

from __future__ import annotations

import re

import numpy as np
import pandas as pd
import pytest

from cli_helpers import assert_one_line_error, cli, table_hashes
from popnavshift.analysis.calibrate import placebo_nulls, placebos

STUDY = """\
name: side
seed: 0
personas: {source: synthetic, n: 60}
matched_n: 12
parts:
  main:
    populations: [matched_base, matched_deadline]
    controllers: [reactive, early_yield]
    episodes: {ids: [head_on-w1.8-d0.06-s0.6-v1, sidewalk-w2.4-d0.12-s0.6-v1]}
  swap_null:
    populations: [matched_base, matched_deadline]
    controllers: [reactive, early_yield]
    episodes: {ids: [head_on-w1.8-d0.06-s0.6-v1, sidewalk-w2.4-d0.12-s0.6-v1]}
    null_design: {kind: swap, replicates: 3}
"""


def test_a_placebo_is_judged_against_the_next_replicates_cyclically_or_all_others():
    assert list(placebo_nulls(6, 1)) == [0, 2, 3, 4, 5]
    assert list(placebo_nulls(6, 4, 3)) == [5, 0, 1]
    assert list(placebo_nulls(4, 2, 3)) == [0, 1, 3]  # as many as there are: all others
    for j in range(7):  # never itself, each as often as the others over all placebos
        assert j not in placebo_nulls(7, j, 3)
    counts = np.bincount(np.concatenate([placebo_nulls(7, j, 3) for j in range(7)]))
    assert set(counts) == {3}


def test_placebos_at_the_studys_design_use_that_many_replicates():
    rng = np.random.default_rng(0)
    rates = pd.DataFrame({"comparison": "matched", "metric": "mean_delay", "rule": "raw",
                          "replicate": range(1, 13), "rate": rng.uniform(0.2, 0.3, 12)})
    loo, deployed = placebos(rates), placebos(rates, {"matched": 4})
    assert len(loo) == len(deployed) > 0  # one placebo per replicate and check either way
    # replicate 1 far above the rest: leave-one-out puts it in every other placebo's null
    # (a wide null), the study's design only in the 4 placebos before it (cyclically), so
    # the two sets of claims differ
    shifted = rates.assign(rate=np.where(rates["replicate"] == 1, 0.9, rates["rate"]))
    a = placebos(shifted)
    b = placebos(shifted, {"matched": 4})
    assert not a["claim_made"].equals(b["claim_made"])


@pytest.fixture(scope="module")
def side_study(tmp_path_factory):
    root = tmp_path_factory.mktemp("side")
    (root / "side.yaml").write_text(STUDY)
    proc = cli("run", str(root / "side.yaml"), "--out", str(root / "s"), "--no-report",
               "-w", "1")
    assert proc.returncode == 0, proc.stderr
    return root / "s"


def test_calibrate_replicates_runs_only_the_new_replicates_beside_the_study(side_study):
    before = table_hashes(side_study)
    proc = cli("calibrate", str(side_study), "--replicates", "5", "-w", "1")
    assert proc.returncode == 0, proc.stderr
    assert table_hashes(side_study) == before  # the study is not touched
    assert not (side_study / "report").exists()
    side = side_study / "calibration"
    runs = pd.read_parquet(side / "runs.parquet")
    nulls = runs[runs["population"].str.contains("swap", na=False)]
    assert nulls["population"].nunique() == 2 * 5  # both arms of 5 swap permutations
    assert "judged against 3 swap replicates" in " ".join(proc.stderr.split())
    # the headline table as a whole: one placebo per replicate, 5 of them
    assert re.search(r"│ \d+/5 ", proc.stdout), proc.stdout
    again = cli("calibrate", str(side_study), "--replicates", "5", "-w", "1")
    assert again.returncode == 0, again.stderr
    assert "0 runs simulated now" in " ".join(again.stderr.split())


def test_calibrate_replicates_refuses_fewer_than_the_study_has(side_study):
    assert_one_line_error(cli("calibrate", str(side_study), "--replicates", "3"),
                          "--replicates 3", "already has 3")


def test_plans_advice_counts_the_runs_run_would_simulate_for_it(side_study):
    from popnavshift.cli.plan import advice_text, exact_runs
    from popnavshift.design.study import Study
    from popnavshift.engine.pending import pending_runs
    from popnavshift.read.folder import open_study

    study = open_study(side_study).study
    assert isinstance(study, Study)
    advice = pd.DataFrame({"comparison": ["matched", "matched"], "metric": ["mean_delay"] * 2,
                           "rule": ["raw"] * 2, "null": ["swap"] * 2, "seed_sets": [1, 1],
                           "n_null": [3, 3], "limit": ["null replicates", "seed sets"],
                           "seed_sets_needed": [1.0, 4.0], "nulls_needed": [6.0, 3.0],
                           "runs_needed": [999.0, 999.0], "minutes_needed": [1.0, 1.0]})
    from popnavshift.cli.plan import power_advice
    from popnavshift.io import write_csv

    write_csv(advice.assign(excess=0.1, verdict="undecided"), side_study.parent / "power.csv")
    read = power_advice(side_study.parent / "power.csv")  # as plan reads a report's table
    assert read is not None and {"seed_sets", "n_null", "null"} <= set(read.columns)
    out = exact_runs(read, study, side_study)
    want = pending_runs(study.extended(replicates=6), side_study).execute
    assert want and out["runs_exact"].iloc[0] == want  # more replicates: counted as run plans
    assert np.isnan(out["runs_exact"].iloc[1])  # more seed sets on a part without seeds
    assert f"`run` would simulate {want:,} new runs here" in advice_text(out.iloc[0])
    assert "about +999 runs" in advice_text(out.iloc[1])


def test_plan_counts_exact_runs_from_the_power_table_a_report_writes(side_study, tmp_path):
    """power_advice keeps what exact_runs reads (seed_sets, null): `plan STUDY` on a study
    with its report and tables crashed on a missing column; a rule without an excess
    (sig with no null replicate) says so instead of '+nan pp'."""
    from popnavshift.cli.plan import _pp, exact_runs, power_advice
    from popnavshift.engine.pending import pending_runs
    from popnavshift.read.folder import open_study

    csv = tmp_path / "evidence_power.csv"
    pd.DataFrame({"comparison": ["matched"], "metric": ["mean_delay"], "rule": ["raw"],
                  "excess": [np.nan], "verdict": ["undecided"], "limit": ["null replicates"],
                  "seed_sets_needed": [1.0], "nulls_needed": [6.0], "runs_needed": [999.0],
                  "minutes_needed": [1.0], "seed_sets": [1], "null": ["swap"],
                  "t_predicted": [np.nan]}).to_csv(csv, index=False)
    study = open_study(side_study).study
    out = exact_runs(power_advice(csv), study, side_study)
    assert out["runs_exact"].iloc[0] == pending_runs(study.extended(replicates=6),
                                                     side_study).execute
    assert _pp(out["excess"].iloc[0]) == "no estimate" and _pp(0.031) == "+3.1 pp"


def test_a_file_named_calibration_is_one_line_and_nothing_is_linked(side_study, tmp_path):
    import shutil

    study = tmp_path / "s"
    shutil.copytree(side_study, study, ignore=shutil.ignore_patterns("calibration"))
    (study / "calibration").write_text("my notes")
    assert_one_line_error(cli("calibrate", str(study), "--replicates", "5"),
                          "calibration", "move it away")
    assert (study / "calibration").read_text() == "my notes"
    assert not (study / ".calibration.tmp").exists()


def test_the_side_folder_copies_the_response_cache_and_links_the_rest(tmp_path):
    from popnavshift.engine.side import link_tree

    src = tmp_path / "s"
    (src / "cache").mkdir(parents=True)
    (src / "runs.parquet").write_bytes(b"runs")
    (src / "cache" / "llm.sqlite").write_bytes(b"db")
    link_tree(src, tmp_path / "side")
    inode = (src / "runs.parquet").stat().st_ino
    assert (tmp_path / "side" / "runs.parquet").stat().st_ino == inode
    cache = tmp_path / "side" / "cache" / "llm.sqlite"
    assert cache.read_bytes() == b"db"  # SQLite writes in place: never the study's inode
    assert cache.stat().st_ino != (src / "cache" / "llm.sqlite").stat().st_ino


def test_variants_per_cell_are_the_studys_own_not_the_papers_three(side_study):
    """The report said '3 variants per cell' for every study (the paper's grid): a study
    naming one episode per cell has 1; two variants on two seed sets have 4."""
    from popnavshift.analysis.replicates import variants_per_cell

    assert variants_per_cell(pd.read_parquet(side_study / "runs.parquet")) == 1
    runs = pd.DataFrame({"episode": [f"e-v{v}@s{k}" for k in (1, 2) for v in (1, 2)],
                         "scene": "sidewalk", "width": 1.8, "density": 0.06,
                         "robot_speed": 0.6, "variant": [1, 2, 1, 2]})
    assert variants_per_cell(runs) == 4 and variants_per_cell(runs.iloc[:0]) == 0


def test_the_placebos_are_read_under_both_locks(side_study, monkeypatch):
    """A second calibrate (or run) used to prune or remake the side folder while the first
    was still reading its placebos: the locks are now held until they are read."""
    from popnavshift.analysis import study_evidence
    from popnavshift.cli.calibrate import _side_calibration
    from popnavshift.engine import lock

    held = []

    def spy(folder, **kw):
        held.append({p.name for p in lock._HELD})
        return {}, None

    monkeypatch.setattr(study_evidence, "evidence_tables", spy)
    assert _side_calibration(side_study, 5, 1) is None
    assert held == [{side_study.name, "calibration"}]


def test_a_rule_above_nominal_in_one_comparison_is_said_though_within_pooled():
    """The 75-replicate calibration of the default study: the interaction test at 5 % was
    within pooled (39/750) and above nominal across the population pairs (28/375); the
    summary under the tables must not hide the second behind the first."""
    import pandas as pd
    from scipy import stats

    from popnavshift.cli.calibrate import summary_lines

    def row(comparison: str, claims: int, placebos: int, status: str) -> dict:
        lo, hi = (stats.beta.ppf(0.025, claims, placebos - claims + 1),
                  stats.beta.ppf(0.975, claims + 1, placebos - claims))
        return {"comparison": comparison, "kind": "false positive", "test": "interaction",
                "claim": "changes more than under the null, at 0.05", "rule": "—",
                "claims": claims, "placebos": placebos, "rate": claims / placebos,
                "cp_low": lo, "cp_high": hi, "nominal": 0.05, "status": status}

    cal = pd.DataFrame([row("all", 39, 750, "within"), row("matched", 11, 375, "within"),
                        row("all_pairs", 28, 375, "above nominal")])
    lines = summary_lines(cal)
    assert lines[0].startswith("[red]above its nominal level[/]") and (
        "all_pairs: 28/375, 7.5% [5.0, 10.6]" in lines[0]), lines
    fine = summary_lines(cal.assign(status="within"))
    assert fine[0].startswith("[green]no verdict rule claims more") and (
        "pooled or in any one comparison" in fine[0])
