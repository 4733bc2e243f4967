import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from popnavshift.profiles.mappings import (
    ACTION_SCORE,
    MOBILITY_SPEED_CAPS,
    build_profiles,
    speed_cap,
)
from popnavshift.responses.probes import PROBE_SET_HASH
from popnavshift.responses.samples import with_samples
from popnavshift.tables import ACTIONS, BLOCK_ITEMS, PARAM_RANGES, PARAMS, Z_COLUMNS, check_table

LEVELS = [0.0, 0.25, 0.5, 0.75, 1.0]


def response_rows(draw_levels, draw_actions, n):
    rows = []
    for i in range(n):
        row = {
            "persona_id": f"p{i}",
            "variant": "baseline",
            "respondent": "t",
            "model": "t",
            "served_model": "t",
            "probe_set": PROBE_SET_HASH,
        }
        row.update({f"action_{j + 1}": draw_actions[i][j] for j in range(8)})
        row.update({f"q_{k}": draw_levels[i][j] for j, k in enumerate(BLOCK_ITEMS)})
        rows.append(row)
    return with_samples(pd.DataFrame(rows))  # one sample each, no served-model identity


def personas_for(ids, mobility="Full", access="None"):
    return pd.DataFrame(
        {"persona_id": ids, "health_mobility": mobility, "accessibility_needs": access}
    )


@settings(max_examples=60, deadline=None)
@given(
    levels=st.lists(
        st.lists(st.sampled_from(LEVELS), min_size=7, max_size=7), min_size=1, max_size=12
    ),
    actions=st.lists(
        st.lists(st.sampled_from(ACTIONS), min_size=8, max_size=8), min_size=12, max_size=12
    ),
    mapping=st.sampled_from("ABCD"),
    mobility=st.sampled_from(
        ["Full", "Mild limitation", "Moderate limitation", "Uses mobility aid"]
    ),
)
def test_every_parameter_lies_in_its_physical_range(levels, actions, mapping, mobility):
    n = len(levels)
    responses = response_rows(levels, actions, n)
    prof = build_profiles(responses, personas_for(responses["persona_id"], mobility), mapping)
    check_table(prof, "profiles")
    for p in PARAMS:
        lo, hi = PARAM_RANGES[p]
        assert prof[p].between(lo, hi).all(), p
        np.testing.assert_allclose(prof[p], lo + prof[Z_COLUMNS[p]] * (hi - lo), atol=1e-12)
    cap = speed_cap(mobility, "None")
    assert (prof["speed_mps"] <= cap + 1e-12).all()


def test_mobility_caps_are_ordered_and_motor_needs_cap():
    caps = [speed_cap(m, "None") for m in ("Full", *MOBILITY_SPEED_CAPS)]
    assert caps[0] == np.inf and caps[1] > caps[2] > caps[3]
    assert speed_cap("Full", "Motor") < np.inf


def test_mapping_a_by_hand():
    # all levels 1.0 except gap 0 and trust 0; all actions 'stop' → q_a = 1
    lv = {k: 1.0 for k in BLOCK_ITEMS} | {"gap": 0.0, "trust": 0.0}
    responses = response_rows([[lv[k] for k in BLOCK_ITEMS]], [["stop"] * 8], 1)
    prof = build_profiles(responses, personas_for(["p0"]), "A").iloc[0]
    c = 0.34 * 1 + 0.22 * (1 - 0) + 0.22 * 1 + 0.22 * ACTION_SCORE["stop"]
    assert prof["caution"] == pytest.approx(c)
    assert prof["z_speed"] == pytest.approx(min(1, 0.32 + 0.6 * 1 + 0.15 * (1 - c)))
    assert prof["clearance_m"] == pytest.approx(1.20)
    assert prof["z_avoidance_gain"] == pytest.approx(min(1, 0.6 * c + 0.4))
    assert prof["z_yield_fraction"] == pytest.approx(0.75)
    assert prof["z_reaction_delay"] == pytest.approx(0.5)
    assert prof["gap_acceptance"] == pytest.approx(0.0)


def test_mappings_differ_but_d_is_direct():
    rng = np.random.default_rng(0)
    levels = rng.choice(LEVELS, size=(50, 7)).tolist()
    actions = rng.choice(ACTIONS, size=(50, 8)).tolist()
    responses = response_rows(levels, actions, 50)
    pers = personas_for(responses["persona_id"])
    a, d = (build_profiles(responses, pers, m) for m in "AD")
    assert not np.allclose(a["speed_mps"], d["speed_mps"])
    np.testing.assert_allclose(d["z_gap_acceptance"], responses["q_gap"])
    np.testing.assert_allclose(d["z_avoidance_gain"], 1 - responses["q_trust"])


def test_urgency_raises_speed_and_lowers_yielding_under_mapping_a():
    lo = {k: 0.5 for k in BLOCK_ITEMS} | {"urgency": 0.0}
    hi = {k: 0.5 for k in BLOCK_ITEMS} | {"urgency": 1.0}
    responses = response_rows(
        [[lo[k] for k in BLOCK_ITEMS], [hi[k] for k in BLOCK_ITEMS]], [["slow"] * 8] * 2, 2
    )
    prof = build_profiles(responses, personas_for(responses["persona_id"]), "A")
    assert prof["speed_mps"].iloc[1] > prof["speed_mps"].iloc[0]
    assert prof["yield_fraction"].iloc[1] < prof["yield_fraction"].iloc[0]


def test_unknown_mapping_and_unknown_persona_are_clear_errors():
    from popnavshift.errors import InputError, UnknownNameError

    responses = response_rows([[0.5] * 7], [["slow"] * 8], 1)
    with pytest.raises(UnknownNameError, match="mapping 'E'"):
        build_profiles(responses, personas_for(["p0"]), "E")
    with pytest.raises(InputError, match="not in the persona table"):
        build_profiles(responses, personas_for(["other"]), "A")
