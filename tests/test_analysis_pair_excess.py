"""Which pairs carry the all-pairs excess (analysis/pair_excess.py) and how closely the
size-matched null matches the cohorts (analysis/cohorts.py): in-memory tables only."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest

from popnavshift.analysis.cohorts import (
    cohort_dispersion,
    cohort_overlaps,
    dispersion_summary,
)
from popnavshift.analysis.nulls import Design
from popnavshift.analysis.pair_excess import (
    COUNT_COLUMNS,
    GROUP_DIFF,
    GROUP_WITH,
    NOT_SHOWN,
    as_placebo,
    group_verdicts,
    maxt_p,
    pair_counts,
    pair_verdicts,
    placebos,
    self_null_direction,
)
from popnavshift.analysis.significance import Orderings
from popnavshift.analysis.verdicts import ABOVE
from popnavshift.report.pairs_section import PAIRS, carriers_sentence, null_words
from popnavshift.tables import PARAMS

POPS = ["homogeneous", "mixed", "high_time_pressure", "high_caution"]
PAIRS_OF = [(a, b) for i, a in enumerate(POPS) for b in POPS[i + 1:]]


def orderings_of(diff: dict[str, list[float]], tolerance: float = 0.0) -> Orderings:
    """Orderings of one metric on one unit with len(values) controller pairs, from each
    population's differences."""
    pops = list(diff)
    d = np.array([[diff[p]] for p in pops], float)  # (P, 1, C)
    nan = np.full(d.shape, np.nan)
    return Orderings("mean_delay", pops, pd.DataFrame({"backend": ["orca"], "mapping": ["A"],
                                                       "cell": ["c"]}),
                     [(f"c{i}", f"d{i}") for i in range(d.shape[2])], d, nan, nan, nan, nan,
                     np.zeros((2, *d.shape), np.float32), 0.9, tolerance, np.array([3]))


def test_pair_counts_count_each_pair_its_nulls_and_homogeneous_itself():
    o = orderings_of({"homogeneous": [1, 1, -1, 0], "mixed": [1, -1, -1, 1],
                      "high_caution": [-1, -1, 1, 1], "homogeneous_sized1": [-1, 1, 1, 1],
                      "high_caution_sized1": [1, 1, 1, 1]})
    design = Design([("homogeneous", "mixed"), ("homogeneous", "high_caution")],
                    [[("homogeneous_sized1", "mixed"),
                      ("homogeneous_sized1", "high_caution_sized1")]], "sized")
    c = pair_counts(o, design).set_index(["pair", "kind", "replicate"])
    # homogeneous vs mixed: signs (1,1), (1,-1), (-1,-1), tie → 1 reversal of 3 comparable
    assert tuple(c.loc[("homogeneous vs mixed", "observed", 0), ["reversals", "comparable"]]) \
        == (1, 3)
    assert tuple(c.loc[("homogeneous vs high_caution", "null", 1),
                       ["reversals", "comparable"]]) == (1, 4)
    # homogeneous itself against high_caution's null: (1,1), (1,1), (-1,1), tie
    assert tuple(c.loc[("homogeneous vs high_caution", "null_self", 1),
                       ["reversals", "comparable"]]) == (1, 3)
    # with mixed (which stands for itself) the self null would be the observed pair: none
    assert ("homogeneous vs mixed", "null_self", 1) not in c.index


def synthetic_counts(rng: np.random.Generator, *, n_rep: int,
                     excess: dict[str, float] | None = None, comparable: int = 400,
                     heavy: bool = False) -> pd.DataFrame:
    """A counts table of every pair of POPS (one metric): the observed and ``n_rep`` null
    replicates exchangeable (each pair's base rate, a shared per-arrangement shift and the
    pair's own noise), plus ``excess`` added to the observed rate of the named pairs."""
    excess = excess or {}
    base = rng.uniform(0.15, 0.35, len(PAIRS_OF))
    rows = []
    for k in range(n_rep + 1):
        shared = rng.normal(0, 0.01)
        noise = rng.standard_t(3, len(PAIRS_OF)) if heavy else rng.normal(size=len(PAIRS_OF))
        for i, (a, b) in enumerate(PAIRS_OF):
            label = f"{a} vs {b}"
            p = np.clip(base[i] + shared + 0.02 * noise[i]
                        + (excess.get(label, 0.0) if k == 0 else 0.0), 0.01, 0.99)
            rows.append(("mean_delay", label, a, b, "observed" if k == 0 else "null", k,
                         int(rng.binomial(comparable, p)), comparable))
    return pd.DataFrame(rows, columns=COUNT_COLUMNS)


def test_the_exact_max_t_holds_its_family_wise_level_on_heavy_tailed_replicates():
    """1,000 synthetic families of 28 correlated rows, 20 exchangeable arrangements each,
    t-distributed on 2 df (heavy tails, where a t at a Holm level rejects too often)."""
    rng = np.random.default_rng(1)
    n, rows, arr = 1000, 28, 20
    hits_exact = 0
    for _ in range(n):
        x = 0.3 + 0.02 * (rng.standard_t(2, (rows, arr)) + rng.normal(size=(1, arr)))
        hits_exact += bool((maxt_p(x, np.zeros(rows)) <= 0.05).any())
    rate = hits_exact / n
    assert rate <= 0.05 + 3 * np.sqrt(0.05 * 0.95 / n)  # nominal within 3 Monte-Carlo SEs
    assert rate >= 0.05 - 3 * np.sqrt(0.05 * 0.95 / n)  # and not far under it: exact


def test_the_pair_that_carries_an_excess_is_named_and_no_other():
    rng = np.random.default_rng(2)
    found, others = 0, 0
    for _ in range(40):
        v = pair_verdicts(synthetic_counts(rng, n_rep=19,
                                           excess={"mixed vs high_time_pressure": 0.25}))
        v = v.set_index("pair")
        found += v.at["mixed vs high_time_pressure", "claim"] == ABOVE
        others += int((v.drop(index="mixed vs high_time_pressure")["claim"] != NOT_SHOWN).sum())
    assert found >= 36 and others <= 2


def test_with_too_few_replicates_the_exact_test_claims_nothing():
    c = synthetic_counts(np.random.default_rng(3), n_rep=9,
                         excess={"mixed vs high_time_pressure": 0.4})
    v = pair_verdicts(c)
    assert v["p_maxt"].min() == pytest.approx(0.1)  # 1/(P + 1): cannot reach 0.05
    assert (v["claim"] == NOT_SHOWN).all()
    assert v.set_index("pair").at["mixed vs high_time_pressure", "t"] > 5  # the t sees it


def test_maxt_p_is_monotone_in_the_step_down_order_and_nan_without_a_statistic():
    x = np.array([[5.0, 0, 1, 0, 1, 0], [2.0, 0, 1, 0, 1, 0], [np.nan] * 6])
    p = maxt_p(x, np.zeros(3))
    assert p[0] <= p[1] and np.isnan(p[2]) and p[0] == pytest.approx(1 / 6)


def test_groups_split_pairs_by_the_time_pressure_attribute_and_keep_their_level():
    rng = np.random.default_rng(4)
    c = synthetic_counts(rng, n_rep=19, excess={"mixed vs high_time_pressure": 0.2,
                                                "homogeneous vs high_time_pressure": 0.2,
                                                "high_time_pressure vs high_caution": 0.2})
    g = group_verdicts(c).set_index("group")
    assert g.at[GROUP_WITH, "pairs"] == 3 and g.at["others", "pairs"] == 3
    assert g.at[GROUP_WITH, "claim"] == ABOVE and g.at[GROUP_DIFF, "claim"] == ABOVE
    assert g.at["others", "claim"] == NOT_SHOWN
    hits = [(group_verdicts(synthetic_counts(rng, n_rep=9))["claim"] != NOT_SHOWN).any()
            for _ in range(120)]
    assert float(np.mean(hits)) <= 0.05 + 3 * np.sqrt(0.05 * 0.95 / 120)


def test_placebos_take_each_replicate_as_the_observed_without_the_real_one():
    c = synthetic_counts(np.random.default_rng(5), n_rep=5,
                         excess={"mixed vs high_time_pressure": 0.5})
    p = as_placebo(c, 3)
    assert sorted(p["replicate"].unique()) == [0, 1, 2, 3, 4]
    orig = c[(c["replicate"] == 3)].set_index("pair")["reversals"]
    got = p[p["kind"] == "observed"].set_index("pair")["reversals"]
    assert got.sort_index().equals(orig.sort_index())
    table = placebos(c).set_index("rule")
    assert table.at["pairs", "placebos"] == 5 and table.at["pairs", "null_replicates"] == 4
    assert table.at["pairs", "tables_with_claim"] == 0  # 4 replicates: 1/5 is the least p
    assert 0 <= table.at["groups", "ci_low"] <= table.at["groups", "ci_high"] <= 1


def test_the_self_null_direction_compares_homogeneous_random_member_and_itself():
    pairs = pd.DataFrame({"metric": ["m"] * 3, "pair": ["a", "b", "c"],
                          "null_mean": [0.2, 0.3, 0.5], "null_mean_self": [0.25, 0.35, np.nan]})
    d = self_null_direction(pairs).iloc[0]
    assert d["pairs"] == 2 and d["pairs_lower"] == 2
    assert d["difference"] == pytest.approx(-0.05)


def populations_table(rng: np.random.Generator) -> pd.DataFrame:
    """mixed (200 members), a central cohort (the 40 nearest the centre), a random cohort
    (40 members) and homogeneous (the median profile, not a member)."""
    x = rng.normal(size=(200, len(PARAMS)))
    ids = [f"p{i:03d}" for i in range(200)]
    mixed = pd.DataFrame(x, columns=list(PARAMS)).assign(persona_id=ids)
    central = mixed.iloc[np.argsort((x ** 2).sum(axis=1))[:40]]
    rand = mixed.iloc[rng.choice(200, 40, replace=False)]
    med = pd.DataFrame([np.median(x, axis=0)], columns=list(PARAMS)).assign(persona_id="median")
    parts = [(mixed, "mixed"), (central, "high_caution"), (rand, "high_time_pressure"),
             (med, "homogeneous")]
    return pd.concat([f.assign(population=n, mapping="A") for f, n in parts],
                     ignore_index=True)


def test_a_central_cohort_is_less_dispersed_than_random_subsets_and_a_random_one_is_not():
    pops = populations_table(np.random.default_rng(6))
    d = cohort_dispersion(pops, ["homogeneous", "mixed", "high_caution", "high_time_pressure"],
                          draws=500, seed=0)
    assert set(d["cohort"]) == {"homogeneous", "high_caution", "high_time_pressure"}
    s = dispersion_summary(d).set_index("cohort")
    assert s.at["high_caution", "sd_ratio_mean"] < 0.8
    assert s.at["high_caution", "params_below"] >= 5
    assert 0.85 < s.at["high_time_pressure", "sd_ratio_mean"] < 1.15
    homo = d[d["cohort"] == "homogeneous"]
    assert homo["sd_ratio"].isna().all() and (homo["in_source"] == 0).all()
    assert (d.loc[d["cohort"] == "high_caution", "in_source"] == 1).all()
    again = cohort_dispersion(pops, ["high_caution"], draws=500, seed=0)
    other = cohort_dispersion(pops, ["high_caution"], draws=500, seed=1)
    assert again["random_sd"].equals(d.loc[d["cohort"] == "high_caution", "random_sd"]
                                     .reset_index(drop=True))
    assert not again["random_sd"].equals(other["random_sd"])


def test_overlaps_are_set_beside_two_independent_random_subsets():
    pops = populations_table(np.random.default_rng(7))
    o = cohort_overlaps(pops, [("high_caution", "high_time_pressure")]).iloc[0]
    assert o["expected"] == pytest.approx(40 * 40 / 200)
    ids = pops.groupby("population")["persona_id"].apply(set)
    assert o["shared"] == len(ids["high_caution"] & ids["high_time_pressure"])
    assert 0 <= o["p_low"] <= 1 and 0 <= o["p_high"] <= 1


def test_the_section_says_what_the_null_is_and_which_pairs_carry_the_excess():
    rng = np.random.default_rng(8)
    c = synthetic_counts(rng, n_rep=19, excess={"mixed vs high_time_pressure": 0.25})
    pops = populations_table(rng)
    tables = {"evidence_pairs": pair_verdicts(c), "evidence_pair_groups": group_verdicts(c),
              "evidence_pair_placebos": placebos(c),
              "evidence_cohorts": cohort_dispersion(pops, POPS, draws=200),
              "evidence_cohort_overlaps": cohort_overlaps(pops, [("high_caution",
                                                                  "high_time_pressure")])}
    page = SimpleNamespace(a=SimpleNamespace(tables=tables, missing={}))
    section = PAIRS.render(page)  # type: ignore[arg-type]
    text = " ".join(b.get("text", "") for b in section.blocks)
    assert "random subsets of mixed of the same sizes" in text
    assert "not in the dispersion" in null_words(tables["evidence_cohorts"])
    sentence = carriers_sentence(tables["evidence_pairs"], tables["evidence_pair_groups"])
    assert "mixed vs high time pressure" in sentence and "above the null" in sentence
    assert {b.get("table") for b in section.blocks} >= {
        "evidence_pairs", "evidence_pair_groups", "evidence_pair_placebos",
        "evidence_cohorts", "evidence_cohort_overlaps"}
    empty = PAIRS.render(SimpleNamespace(a=SimpleNamespace(  # type: ignore[arg-type]
        tables={}, missing={"evidence_pairs": "the study ran no null of the all_pairs "
                                              "comparison"})))
    assert "ran no null" in empty.missing


def test_with_nine_replicates_the_section_says_no_pair_can_be_named_and_why():
    c = synthetic_counts(np.random.default_rng(9), n_rep=9,
                         excess={"mixed vs high_time_pressure": 0.3})
    sentence = carriers_sentence(pair_verdicts(c), group_verdicts(c))
    assert "no pair can be named on its own with 9 null replicates" in sentence
    assert "1/10 (it needs 19)" in sentence
    assert "Largest excesses (descriptive): mixed vs high time pressure" in sentence
