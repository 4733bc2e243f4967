import numpy as np
import pandas as pd
import pytest

from popnavshift.personas.variants import matched_ids
from popnavshift.populations.build import (
    HOMOGENEOUS_ID,
    POPULATIONS,
    population_sizes,
)
from popnavshift.profiles.mappings import build_profiles
from popnavshift.responses.collect import collect_responses
from popnavshift.responses.rule import RuleRespondent
from popnavshift.tables import PARAMS, check_table
from population_tables import build_populations


@pytest.fixture
def pipeline(random_personas):
    personas = random_personas(400, seed=5)
    ids = matched_ids(personas, 100, seed=0)
    responses, _, _ = collect_responses(personas, RuleRespondent(), ids)
    prof_a = build_profiles(responses, personas, "A")
    return personas, responses, prof_a, ids


def test_eight_populations_with_the_spec_definitions(pipeline):
    personas, responses, prof_a, ids = pipeline
    pops = check_table(build_populations(personas, responses, prof_a, ids), "populations")
    sizes = population_sizes(pops)
    assert list(sizes) == [*POPULATIONS, "mixed_half_a", "mixed_half_b"]
    a = set(pops[pops.population == "mixed_half_a"].persona_id)
    b = set(pops[pops.population == "mixed_half_b"].persona_id)
    assert not a & b and len(a | b) == 400 and abs(len(a) - len(b)) <= 1  # the noise-floor split
    assert sizes["homogeneous"] == 1 and sizes["mixed"] == 400
    assert sizes["matched_base"] == sizes["matched_deadline"] == 100
    per = personas.set_index("persona_id")
    htp = pops[pops.population == "high_time_pressure"].persona_id
    assert per.loc[htp, "time_pressure"].isin(["Deadline", "Emergency"]).all()
    assert (
        sizes["high_time_pressure"] == personas.time_pressure.isin(["Deadline", "Emergency"]).sum()
    )
    mob = pops[pops.population == "mobility_support"].persona_id
    m = per.loc[mob]
    assert (
        m.health_mobility.isin(["Moderate limitation", "Uses mobility aid"])
        | (m.accessibility_needs == "Motor")
    ).all()
    base_resp = responses[responses.variant == "baseline"].set_index("persona_id")
    low = pops[pops.population == "low_robot_trust"].persona_id
    assert (base_resp.loc[low, "q_trust"] <= 0.25).all()
    assert sizes["low_robot_trust"] == (base_resp.q_trust <= 0.25).sum()


def test_high_caution_is_the_upper_quartile_with_ties_kept(pipeline):
    personas, responses, prof_a, ids = pipeline
    pops = build_populations(personas, responses, prof_a, ids)
    base = prof_a[prof_a.variant == "baseline"]
    q75 = base.caution.quantile(0.75)
    hc = pops[pops.population == "high_caution"]
    assert len(hc) == (base.caution >= q75).sum() >= len(base) // 4


def test_matched_pair_has_the_same_ids_in_the_same_member_order(pipeline):
    personas, responses, prof_a, ids = pipeline
    pops = build_populations(personas, responses, prof_a, ids)
    b = pops[pops.population == "matched_base"]
    d = pops[pops.population == "matched_deadline"]
    assert b.persona_id.tolist() == d.persona_id.tolist() == sorted(ids)
    assert (b.variant == "baseline").all() and (d.variant == "deadline").all()
    assert b.member.tolist() == list(range(100))
    assert not np.allclose(b[list(PARAMS)].to_numpy(), d[list(PARAMS)].to_numpy())


def test_homogeneous_is_the_per_parameter_median(pipeline):
    personas, responses, prof_a, ids = pipeline
    pops = build_populations(personas, responses, prof_a, ids)
    h = pops[pops.population == "homogeneous"].iloc[0]
    assert h.persona_id == HOMOGENEOUS_ID
    base = prof_a[prof_a.variant == "baseline"]
    for p in PARAMS:
        assert h[p] == pytest.approx(np.median(base[p]))


def test_other_mappings_share_membership(pipeline):
    personas, responses, prof_a, ids = pipeline
    prof_d = build_profiles(responses, personas, "D")
    a = build_populations(personas, responses, prof_a, ids)
    d = build_populations(personas, responses, prof_a, ids, profiles=prof_d)
    pd.testing.assert_frame_equal(
        a[["population", "member", "persona_id"]], d[["population", "member", "persona_id"]]
    )
    assert (d.mapping == "D").all() and not np.allclose(a.speed_mps, d.speed_mps)
