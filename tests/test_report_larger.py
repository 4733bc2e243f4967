"""The larger built-in study the report names beside rows it decided (issue #32, item 3)."""

from __future__ import annotations

import pandas as pd

from popnavshift.design.study import builtin_studies, load_study
from popnavshift.report.larger import (
    QUESTIONS,
    larger_clause,
    larger_studies,
    split_undecided,
    unresolved,
)


def test_the_recorded_larger_studies_are_built_in_and_their_runs_are_what_plan_counts():
    studies = larger_studies("paper")
    assert studies and studies == sorted(studies, key=lambda s: s.runs)  # smallest first
    from popnavshift.design.plan import plan_study
    from popnavshift.episodes.specs import all_episodes

    def distinct(name: str) -> int:
        study = load_study(name)
        return len(plan_study(study, all_episodes(seed=study.seed)))

    for larger in studies:
        assert larger.name in builtin_studies()
        assert distinct(larger.name) == larger.runs
        assert set(larger.decided) == set(QUESTIONS)


def test_a_row_recorded_as_unresolved_is_decided_by_no_recorded_larger_study():
    measured = unresolved("paper")
    assert measured and all(u.question in QUESTIONS and u.rows and u.why for u in measured)
    for u in measured:
        for larger in larger_studies("paper"):
            assert not u.rows & larger.decided[u.question], (u, larger.name)
    assert unresolved("quick") == [] and larger_studies("quick") == []
    # the larger studies run the same grid: the same rows stay unresolved in their reports
    for larger in larger_studies("paper"):
        assert unresolved(larger.name) == measured


def test_undecided_rows_split_into_those_the_larger_study_decided_and_the_rest():
    larger = larger_studies("paper")[0]
    rows = pd.DataFrame({"comparison": ["matched", "matched", "all_pairs"],
                         "metric": ["worst_decile", "blocked_pct", "cvar90"]})
    hit, rest = split_undecided(rows, "reversals", larger)
    assert list(hit["metric"]) == ["worst_decile", "cvar90"] and list(rest["metric"]) == [
        "blocked_pct"]
    hit, rest = split_undecided(rows, "interaction", larger)
    assert hit.empty and len(rest) == 3
    none, all_ = split_undecided(rows, "reversals", None)  # none recorded
    assert none.empty and len(all_) == 3


def test_the_clause_names_the_study_its_cost_and_whose_seed_it_was_measured_on():
    larger = larger_studies("paper")[0]
    same = larger_clause(larger, larger.seed, 1)
    assert larger.name in same and f"{larger.runs:,} runs" in same and "decided it" in same
    assert "this study's seed" in same
    other = larger_clause(larger, larger.seed + 1, 2)
    assert "decided them" in other and "not this study's" in other


def test_a_recorded_calibration_is_a_count_with_its_clopper_pearson_interval():
    from scipy import stats

    from popnavshift.report.larger import measured_calibration, measured_claims

    measured = measured_calibration("paper")
    assert measured
    for m in measured:
        for at in (m.at_05, m.at_level):
            k, n = at["claims"], at["placebos"]
            assert n == m.replicates * 5 and abs(at["rate"] - k / n) < 5e-4
            assert abs(at["cp_low"] - stats.beta.ppf(0.025, k, n - k + 1)) < 5e-4
            assert abs(at["cp_high"] - stats.beta.ppf(0.975, k + 1, n - k)) < 5e-4
    claims = measured_claims("paper")
    assert claims
    for c in claims:
        k, n = c.measured["claims"], c.measured["placebos"]
        assert n == c.replicates * 5 and abs(c.measured["rate"] - k / n) < 5e-4
        assert abs(c.measured["cp_low"] - stats.beta.ppf(0.025, k, n - k + 1)) < 5e-4
        assert abs(c.measured["cp_high"] - stats.beta.ppf(0.975, k + 1, n - k)) < 5e-4
