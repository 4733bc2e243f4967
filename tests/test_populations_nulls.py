"""Null populations: swap permutations of the matched pair and size-matched subsets of mixed."""

from __future__ import annotations

import numpy as np
import pytest

from popnavshift.design.study import study_from_dict
from popnavshift.errors import ConfigError
from popnavshift.personas.synthetic import generate_personas
from popnavshift.personas.variants import matched_ids
from popnavshift.populations.build import POPULATIONS, membership
from popnavshift.populations.identity import (
    PopulationSpec,
    Records,
    index_of,
    null_kind,
    null_populations,
)
from popnavshift.populations.nulls import sized_subset, swap_variants
from popnavshift.profiles.mappings import build_profiles
from popnavshift.responses.collect import collect_responses
from popnavshift.responses.rule import RuleRespondent


@pytest.fixture(scope="module")
def members():
    personas = generate_personas(300, seed=4)
    ids = matched_ids(personas, 80, seed=0)
    responses, _, _ = collect_responses(personas, RuleRespondent(), ids)
    prof = build_profiles(responses, personas, "A")
    nulls = (*null_populations("swap", 3, ()), *null_populations("sized", 2, POPULATIONS))
    return membership(personas, responses, prof, ids, populations=POPULATIONS + nulls, seed=0)


def test_swap_arms_hold_the_matched_personas_with_complementary_profiles(members):
    base = members[members["population"] == "matched_base"]
    for k in (1, 2, 3):
        a = members[members["population"] == swap_name(k, "a")].set_index("persona_id")
        b = members[members["population"] == swap_name(k, "b")].set_index("persona_id")
        # same ids in the same member order: the same persona in every slot
        assert list(a.index) == list(b.index) == list(base["persona_id"])
        assert (a["variant"] != b["variant"]).all()  # each persona's two profiles split
        share = (a["variant"] == "deadline").mean()
        assert 0.3 < share < 0.7  # a fair coin per persona
    arm1 = members[members["population"] == swap_name(1, "a")]["variant"].to_numpy()
    arm2 = members[members["population"] == swap_name(2, "a")]["variant"].to_numpy()
    assert (arm1 != arm2).any()  # permutations differ


def drawn(spec: PopulationSpec, members: dict[str, list[str]], seed: int) -> list:
    """The members of null population ``spec`` drawn by its kind's declaration from
    conditions holding ``members`` (persona ids, baseline)."""
    records = Records(lambda s: [(p, "baseline") for p in members[s.name]], seed)
    return null_kind(spec).members(spec, records)


def test_swap_coins_follow_the_seed():
    ids = [f"p{i:03d}" for i in range(50)]
    pair = {"matched_base": ids}
    arm = PopulationSpec.swap(1, "a")
    assert drawn(arm, pair, 0) == drawn(arm, pair, 0)
    assert drawn(arm, pair, 0) != drawn(arm, pair, 1)
    assert drawn(arm, pair, 0) != drawn(PopulationSpec.swap(2, "a"), pair, 0)
    other = dict(drawn(PopulationSpec.swap(1, "b"), pair, 0))
    assert all(other[p] != v for p, v in drawn(arm, pair, 0))  # complementary arms
    rng = np.random.default_rng(0)
    assert swap_variants(ids, "a", rng) != swap_variants(ids, "a", rng)  # the rng is the draw


def test_sized_subsets_match_sizes_and_come_from_mixed(members):
    size = members.groupby("population").size()
    mixed = set(members.loc[members["population"] == "mixed", "persona_id"])
    for pop in POPULATIONS:
        if pop == "mixed":
            assert sized_name(pop, 1) not in size  # mixed is its own size-matched subset
            continue
        for k in (1, 2):
            sub = members[members["population"] == sized_name(pop, k)]
            assert len(sub) == size[pop]
            assert set(sub["persona_id"]) <= mixed and (sub["variant"] == "baseline").all()
    a1 = members.loc[members["population"] == sized_name("high_caution", 1), "persona_id"]
    a2 = members.loc[members["population"] == sized_name("high_caution", 2), "persona_id"]
    assert set(a1) != set(a2)


def test_sized_subset_is_deterministic_and_sorted():
    src = {"mixed": [f"p{i}" for i in range(40)], "high_caution": [f"p{i}" for i in range(10)],
           "low_robot_trust": [f"p{i}" for i in range(10)]}
    one = [p for p, _ in drawn(PopulationSpec.sized("high_caution", 1), src, 0)]
    assert one == [p for p, _ in drawn(PopulationSpec.sized("high_caution", 1), src, 0)]
    assert one == sorted(one) and len(one) == 10 and set(one) <= set(src["mixed"])
    assert one != [p for p, _ in drawn(PopulationSpec.sized("low_robot_trust", 1), src, 0)]
    assert one != [p for p, _ in drawn(PopulationSpec.sized("high_caution", 2), src, 0)]
    assert one != [p for p, _ in drawn(PopulationSpec.sized("high_caution", 1), src, 1)]
    assert sized_subset(src["mixed"], 50, np.random.default_rng(0)) == sorted(src["mixed"])


def swap_name(k: int, arm: str) -> str:
    return PopulationSpec.swap(k, arm).name


def sized_name(of: str, k: int) -> str:
    return PopulationSpec.sized(of, k).name


def test_population_names_are_written_from_their_spec_and_looked_up_not_parsed():
    assert PopulationSpec.swap(12, "b").name == "matched_swap12_b"
    assert PopulationSpec.sized("high_caution", 3).name == "high_caution_sized3"
    assert PopulationSpec.half("mixed", "b").name == "mixed_half_b"
    study = study_from_dict({"name": "t", "parts": {
        "main": {"populations": ["mixed", "high_caution", "mixed_half_a"]},
        "null": {"populations": ["high_caution"], "null_design": {"kind": "sized",
                                                                  "replicates": 2}}}}, "t")
    assert study.population_specs() == {
        "mixed": PopulationSpec("mixed"), "high_caution": PopulationSpec("high_caution"),
        "mixed_half_a": PopulationSpec.half("mixed", "a"),
        **{sized_name("high_caution", k): PopulationSpec.sized("high_caution", k)
           for k in (1, 2)}}
    # a null replicate comes from a null design, never from a name a part lists
    for name in ("matched_swap1_a", "high_caution_sized2"):
        with pytest.raises(ConfigError, match="unknown population.*null_design"):
            study_from_dict({"name": "t", "parts": {"main": {"populations": [name]}}}, "t")
    with pytest.raises(ValueError, match="rename the condition"):
        index_of([PopulationSpec("x_sized1"), PopulationSpec.sized("x", 1)])


def test_a_swap_null_part_stands_for_the_matched_pair():
    base = {"name": "t", "parts": {"n": {"null_design": {"kind": "swap", "replicates": 4}}}}
    part = study_from_dict(base, "t").parts["n"]
    assert part.planned_populations == tuple(swap_name(k, a) for k in range(1, 5)
                                             for a in "ab")
    bad = {"name": "t", "parts": {"n": {"populations": ["mixed"],
                                        "null_design": {"kind": "swap"}}}}
    with pytest.raises(ConfigError, match="swap null stands in for matched_base and "
                                          "matched_deadline"):
        study_from_dict(bad, "t")


def test_population_columns_say_what_a_population_is():
    from popnavshift.populations.identity import with_population_columns

    assert PopulationSpec("mixed").columns() == {"population_role": "observed",
                                                 "null_replicate": 0}
    assert PopulationSpec.swap(7, "a").columns() == {"population_role": "swap_null",
                                                     "null_replicate": 7}
    assert PopulationSpec.sized("high_caution", 3).columns() == {
        "population_role": "sized_null", "null_replicate": 3}
    assert PopulationSpec.half("mixed", "b").columns()["population_role"] == "half"
    import pandas as pd

    old = pd.DataFrame({"population": ["mixed", "matched_swap2_b"]})  # stored before them
    filled = with_population_columns(old, index_of([PopulationSpec.swap(2, "b")]))
    assert list(filled["population_role"]) == ["observed", "swap_null"]
    assert list(filled["null_replicate"]) == [0, 2]


def test_headline_designs_pair_each_observed_pair_with_the_first_null_kind_the_study_ran():
    from popnavshift.analysis.nulls import headline_designs
    from popnavshift.populations.identity import MATCHED_PAIR

    obs = ["mixed", "high_caution", *MATCHED_PAIR]
    observed = [PopulationSpec(p) for p in obs]
    swaps = null_populations("swap", 3, MATCHED_PAIR)
    sized = null_populations("sized", 2, tuple(obs))
    none = headline_designs(observed, obs)
    assert (none["matched"].null, none["matched"].nulls) == ("swap", [])
    assert (none["all_pairs"].null, none["all_pairs"].nulls) == ("sized", [])
    both = headline_designs([*observed, *swaps, *sized], obs)
    assert both["matched"].nulls == [[(swap_name(k, "a"), swap_name(k, "b"))] for k in (1, 2, 3)]
    pairs = both["all_pairs"]
    assert pairs.null == "sized" and len(pairs.nulls) == 2  # replicates with every pair's null
    first = dict(zip(pairs.observed, pairs.nulls[0], strict=True))
    assert first[("mixed", "high_caution")] == ("mixed", sized_name("high_caution", 1))
    assert first[MATCHED_PAIR] == (swap_name(1, "a"), swap_name(1, "b"))  # same personas
    only_sized = headline_designs([*observed, *sized], obs)
    assert only_sized["matched"].nulls == []  # a sized null is no null of the matched pair
    assert dict(zip(pairs.observed, only_sized["all_pairs"].nulls[1], strict=True))[
        MATCHED_PAIR] == tuple(sized_name(p, 2) for p in MATCHED_PAIR)


def test_a_null_of_a_pair_holds_the_pair_not_a_name():
    arm = PopulationSpec.swap(3, "a")
    assert arm.base == arm.bases == ("matched_base", "matched_deadline")
    assert PopulationSpec.sized("mixed_x", 1).bases == ("mixed_x",)
    assert index_of([arm])["matched_swap3_a"] is arm
