"""Robustness profile sets: reassignment, column shuffles, single response blocks."""

import numpy as np
import pandas as pd
import pytest

from popnavshift.personas.variants import matched_ids
from popnavshift.populations.perturb import (
    BLOCKS,
    reassign_profiles,
    shuffle_columns,
    single_block_responses,
)
from popnavshift.profiles.mappings import build_profiles
from popnavshift.responses.collect import collect_responses
from popnavshift.responses.rule import RuleRespondent
from popnavshift.tables import PARAMS
from population_tables import build_populations


@pytest.fixture(scope="module")
def stage(request):
    rng = np.random.default_rng(0)
    from popnavshift.personas.fields import PERSONA_FIELDS, vocabulary

    n = 300
    personas = pd.DataFrame(
        {
            f: [vocabulary(f)[i] for i in rng.integers(0, len(vocabulary(f)), n)]
            for f in PERSONA_FIELDS
        }
    )
    personas.insert(0, "persona_id", [f"p-{i:04d}" for i in range(n)])
    personas.insert(1, "source", "t")
    ids = matched_ids(personas, 60, 0)
    responses, _, _ = collect_responses(personas, RuleRespondent(), ids)
    return personas, responses, build_profiles(responses, personas, "A"), ids


def rows(df):
    return sorted(map(tuple, df[list(PARAMS)].round(12).to_numpy().tolist()))


def test_reassignment_keeps_the_multiset_of_profiles_but_moves_them(stage):
    _, _, prof, _ = stage
    out = reassign_profiles(prof, seed=0)
    base, moved = prof[prof.variant == "baseline"], out[out.variant == "baseline"]
    assert rows(base) == rows(moved)  # same vectors …
    assert (base[list(PARAMS)].to_numpy() != moved[list(PARAMS)].to_numpy()).any(
        axis=1
    ).mean() > 0.9
    assert (out.mapping == "A~reassign").all()
    pd.testing.assert_frame_equal(
        out[out.variant == "deadline"].drop(columns="mapping"),
        prof[prof.variant == "deadline"].drop(columns="mapping"),
    )
    assert rows(reassign_profiles(prof, seed=1)) == rows(out)
    assert not out.equals(reassign_profiles(prof, seed=1))


def test_column_shuffles_keep_each_marginal_and_break_associations(stage):
    personas, responses, prof, ids = stage
    pops = build_populations(personas, responses, prof, ids)
    out = shuffle_columns(pops, seed=0)
    for name, group in pops.groupby("population"):
        shuffled = out[out.population == name]
        for p in PARAMS:  # each marginal exactly
            assert sorted(group[p]) == sorted(shuffled[p])
    mixed, mixed_s = pops[pops.population == "mixed"], out[out.population == "mixed"]

    def mean_abs_corr(df):
        c = np.corrcoef(df[list(PARAMS)].to_numpy().T)
        return np.abs(c[np.triu_indices(len(PARAMS), 1)]).mean()

    before, after = mean_abs_corr(mixed), mean_abs_corr(mixed_s)
    assert before > 0.15 and after < before / 2  # associations broken
    assert (mixed.persona_id.to_numpy() == mixed_s.persona_id.to_numpy()).all()


@pytest.mark.parametrize("block", sorted(BLOCKS))
def test_single_block_varies_only_its_items(stage, block):
    _, responses, _, _ = stage
    out = single_block_responses(responses, block)
    items, actions_vary = BLOCKS[block]
    for q in (
        "q_clearance",
        "q_waiting",
        "q_yielding",
        "q_gap",
        "q_detour",
        "q_trust",
        "q_urgency",
    ):
        if q in items:
            pd.testing.assert_series_equal(out[q], responses[q])
        else:
            assert out[q].nunique() == 1 and out[q].iloc[0] in (0, 0.25, 0.5, 0.75, 1.0)
    acts = [f"action_{i}" for i in range(1, 9)]
    assert (out[acts].nunique() > 1).any() == actions_vary
