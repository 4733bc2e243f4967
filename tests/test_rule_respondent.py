import json

import numpy as np
import pandas as pd

from popnavshift.personas.variants import apply_variant, matched_ids
from popnavshift.responses.collect import collect_responses
from popnavshift.responses.respondent import RESPONDENTS, ProbeRequest
from popnavshift.responses.rule import RuleRespondent, traits
from popnavshift.responses.schema import parse_answer
from popnavshift.tables import check_table

ACTS = [f"action_{i}" for i in range(1, 9)]


def test_answers_are_valid_under_the_strict_schema(random_personas):
    personas = random_personas(30)
    rule = RuleRespondent()
    for rec in personas.to_dict("records"):
        ans = rule.answer_one(rec["persona_id"], rec)
        assert parse_answer(json.dumps(ans)) == ans


def test_same_seed_same_answers_other_seed_other_answers(random_personas):
    personas = random_personas(100)
    a, _, _ = collect_responses(personas, RuleRespondent(seed=0))
    b, _, _ = collect_responses(personas, RuleRespondent(seed=0))
    c, _, _ = collect_responses(personas, RuleRespondent(seed=1))
    pd.testing.assert_frame_equal(a.drop(columns="model"), b.drop(columns="model"))
    assert (a[ACTS].to_numpy() != c[ACTS].to_numpy()).any()


def test_answers_follow_the_persona():
    base = {
        "persona_id": "p",
        "time_pressure": "No rush",
        "decision_style": "Analytical",
        "trust_level": "Trusting",
        "tech_savviness": "Digital native",
        "att_automation": "Enthusiast",
        "cog_patience": "High",
        "accessibility_needs": "None",
        "health_mobility": "Full",
        "risk_tolerance": "Balanced",
    }
    cautious = {**base, "risk_tolerance": "Risk-averse", "big5_cautiousness": "Very high"}
    bold = {**base, "risk_tolerance": "Risk-seeking", "big5_cautiousness": "Very low"}
    assert traits(cautious)["caution"] > traits(bold)["caution"]
    rule = RuleRespondent()
    levels = ["very_low", "low", "medium", "high", "very_high"]
    c = rule.answer_one("p", cautious)["block"]
    b = rule.answer_one("p", bold)["block"]
    assert levels.index(c["clearance"]) > levels.index(b["clearance"])
    assert levels.index(c["gap"]) < levels.index(b["gap"])
    distrust = {
        **base,
        "trust_level": "Hostile",
        "tech_savviness": "Avoidant",
        "att_automation": "Opposed",
    }
    assert levels.index(rule.answer_one("p", distrust)["block"]["trust"]) < levels.index(
        rule.answer_one("p", base)["block"]["trust"]
    )


def test_deadline_moves_answers_in_the_documented_directions(random_personas):
    personas = random_personas(600, seed=3)
    ids = matched_ids(personas, 202, seed=0)
    responses, invalid, _ = collect_responses(personas, RuleRespondent(), ids)
    assert invalid.empty
    check_table(responses, "responses")
    base = responses[responses.variant == "baseline"].set_index("persona_id").loc[ids]
    dead = responses[responses.variant == "deadline"].set_index("persona_id").loc[ids]
    d = {
        k: dead[f"q_{k}"].to_numpy() - base[f"q_{k}"].to_numpy()
        for k in ("urgency", "waiting", "yielding", "gap")
    }
    assert (d["urgency"] >= 0).all() and d["urgency"].mean() > 0.2
    assert (d["waiting"] <= 0).all() and d["waiting"].mean() < -0.05
    assert (d["yielding"] <= 0).all() and d["yielding"].mean() < -0.05
    assert (d["gap"] >= 0).all() and d["gap"].mean() > 0.05
    changed = (base[ACTS].to_numpy() != dead[ACTS].to_numpy()).any(axis=1)
    assert changed.mean() > 0.5  # "most matched personas change at least one categorical answer"


def test_variant_changes_only_time_pressure(random_personas):
    rec = random_personas(1).iloc[0].to_dict()
    dead = apply_variant(rec, "deadline")
    assert dead["time_pressure"] == "Deadline"
    assert {k: v for k, v in dead.items() if k != "time_pressure"} == {
        k: v for k, v in rec.items() if k != "time_pressure"
    }


def test_matched_ids_are_low_pressure_seeded_and_sorted(random_personas):
    personas = random_personas(600)
    ids = matched_ids(personas, 202, seed=0)
    assert ids == sorted(ids) and len(set(ids)) == 202
    assert (
        personas.set_index("persona_id")
        .loc[ids, "time_pressure"]
        .isin(["No rush", "Moderate"])
        .all()
    )
    assert ids == matched_ids(personas, 202, seed=0)
    assert ids != matched_ids(personas, 202, seed=1)


def test_registry_builds_rule_and_suggests_names():
    import pytest

    from popnavshift.errors import UnknownNameError

    assert isinstance(RESPONDENTS.make("rule", seed=2), RuleRespondent)
    with pytest.raises(UnknownNameError, match="did you mean 'rule'"):
        RESPONDENTS.make("rul")


def test_answer_all_reports_progress(random_personas):
    personas = random_personas(5)
    seen = []
    reqs = [ProbeRequest(r["persona_id"], "baseline", r) for r in personas.to_dict("records")]
    RuleRespondent().answer_all(reqs, progress=seen.append)
    assert sum(seen) == 5 and np.all(np.array(seen) == 1)


def test_a_misspelt_respondent_option_is_a_clear_error():
    import pytest

    from popnavshift.errors import ConfigError

    with pytest.raises(ConfigError, match="takes no parameter 'sed'.*did you mean 'seed'"):
        RESPONDENTS.make("rule", sed=1)
    with pytest.raises(ConfigError, match="'modle'.*did you mean 'model'"):
        RESPONDENTS.make("openai", modle="x")
