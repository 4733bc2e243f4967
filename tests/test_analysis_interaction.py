"""The interaction test (analysis/interaction.py): by hand, on many draws of pure noise,
and through the real analysis on synthetic studies where the truth is known."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from popnavshift.analysis.calibrate import calibration_table
from popnavshift.analysis.evidence import test_comparisons as run_tests
from popnavshift.analysis.interaction import (
    CHANGES,
    NOT_SHOWN,
    PREDICTION,
    RECOMBINED,
    Recombined,
    interaction_placebos,
    interaction_test,
    interaction_verdicts,
    one_sided,
    rank_statistic,
    weighted_midranks,
)
from popnavshift.analysis.nulls import headline_designs
from popnavshift.analysis.significance import Orderings
from popnavshift.analysis.verdicts import DESCRIPTIVE, clopper_pearson
from popnavshift.populations.identity import MATCHED_PAIR, PopulationSpec
from synth_study import design_specs, swap_study


def test_the_rank_statistic_by_hand():
    # 3 designs × 2 terms; term 2 is missing in design 3 (ranked among the other two)
    z = np.array([[[3.0, -2.0]], [[1.0, 0.5]], [[-2.0, np.nan]]])
    # term 1 |z| = 3, 1, 2 → ranks 3, 1, 2 → (r − 1)/2 = 1, 0, 0.5
    # term 2 |z| = 2, 0.5 → ranks 2, 1 → (r − 1)/1 = 1, 0
    assert rank_statistic(z) == pytest.approx([1.0, 0.0, 0.5])
    # ties share their mid-rank; a term finite in one design only is left out
    tied = np.array([[[1.0, 7.0]], [[-1.0, np.nan]], [[0.0, np.nan]]])
    assert rank_statistic(tied) == pytest.approx([0.75, 0.75, 0.0])


def test_the_one_sided_prediction_t_by_hand():
    null = np.array([0.4, 0.5, 0.6, 0.5])
    d = one_sided(0.8, null)
    s = np.std(null, ddof=1) * np.sqrt(1 + 1 / 4)
    assert d["t"] == pytest.approx((0.8 - 0.5) / s) and d["df"] == 3
    assert d["p_value"] == pytest.approx(1 / 5)  # above every replicate
    assert one_sided(0.2, null)["p_t"] > 0.5  # less than the null: no claim
    assert np.isnan(one_sided(0.8, null[:2])["t"])  # too few replicates


def test_on_pure_noise_the_test_claims_at_its_nominal_rate():
    """2,000 designs of independent normal z (9 replicates, 300 terms): the one-sided
    prediction t of the rank statistic claims at 5 % within its Clopper–Pearson interval."""
    rng = np.random.default_rng(7)
    n, claims, strict = 2000, 0, 0
    for _ in range(n):
        T = rank_statistic(rng.standard_normal((10, 100, 1, 3)))
        p = one_sided(T[0], T[1:])["p_t"]
        claims += p <= 0.05
        strict += p <= 0.05 / 8
    assert clopper_pearson(claims, n)[0] <= 0.05 and claims / n > 0.03  # not conservative
    assert clopper_pearson(strict, n)[0] <= 0.05 / 8


def test_the_family_decides_each_row_at_alpha_over_m():
    t = pd.DataFrame({"comparison": ["matched"] * 3, "metric": ["a", "b", "c"],
                      "p_t": [0.004, 0.01, np.nan], "n_null": [9, 9, 2]})
    v = interaction_verdicts(t)
    assert list(v["family"]) == [2, 2, 2] and v["alpha_row"].iloc[0] == pytest.approx(0.025)
    assert list(v["verdict"]) == [CHANGES, CHANGES, DESCRIPTIVE]
    assert v["p_adj"].iloc[:2].tolist() == pytest.approx([0.008, 0.02])
    assert interaction_verdicts(t.assign(p_t=[0.03, 0.2, np.nan]))["verdict"].iloc[0] == NOT_SHOWN


def matched(inject: float, seed: int, n_null: int = 9):
    runs, peds = swap_study(n_null, inject=inject, seed=seed, n_cells=12, variants=4, n_peds=5)
    designs = headline_designs(design_specs(runs, "swap"), list(MATCHED_PAIR))
    t = run_tests(runs, peds, designs, list(MATCHED_PAIR), rng=np.random.default_rng(seed),
                  n_boot=80, metrics=("mean_delay",))
    return t


def test_a_planted_interaction_is_claimed_and_pure_noise_is_not():
    planted = matched(1.0, seed=3)
    row = interaction_verdicts(planted.interaction).iloc[0]
    assert row["n_null"] == 9 and row["terms"] > 0
    assert row["verdict"] == CHANGES and row["p_value"] == pytest.approx(0.1)
    noise = matched(0.0, seed=4)
    assert interaction_verdicts(noise.interaction)["verdict"].iloc[0] == NOT_SHOWN
    # every replicate is a placebo against the other 8, ranks recomputed among them
    reps = noise.interaction_nulls
    assert list(reps["replicate"]) == list(range(1, 10)) and reps["placebo_t"].notna().all()
    assert (reps["placebo_p_t"] > 0.05 / 8).all()


def test_the_calibration_counts_the_interaction_placebos_at_both_levels():
    nulls = pd.DataFrame({"comparison": "matched", "metric": "mean_delay",
                          "replicate": range(1, 11), "T": 0.5,
                          "placebo_t": 0.0, "placebo_p_t": [0.001, 0.03] + [0.5] * 8})
    p = interaction_placebos(nulls, family=8)
    assert set(p["nominal"]) == {0.05 / 8, 0.05}
    rates = nulls.assign(rule="raw", rate=0.1, reversals=1, comparable=10)
    cal = calibration_table(rates[["comparison", "metric", "rule", "replicate", "rate",
                                   "reversals", "comparable"]], interaction=p)
    got = cal[(cal["comparison"] == "all") & cal["test"].str.startswith("interaction")]
    assert list(got["claims"]) == [1, 2] and list(got["placebos"]) == [10, 10]
    assert got["nominal"].tolist() == pytest.approx([0.05 / 8, 0.05])


def test_the_plain_sentence_follows_the_interaction_verdicts():
    """Change the verdicts and the words change; the paragraph never says orderings cross."""
    from popnavshift.report.plain import answer_sentences

    rows = pd.DataFrame({"comparison": ["matched", "matched", "all_pairs"],
                         "metric": ["robot_time", "mean_delay", "mean_delay"],
                         "t": [2.0, 6.4, 4.4], "p_t": [0.04, 1e-5, 2e-4], "n_null": 19})
    head = pd.DataFrame({"comparison": ["matched"], "metric": ["cvar90"], "rule": ["raw"],
                         "verdict": ["undecided"], "excess": [0.02], "ci_low": [-0.03],
                         "ci_high": [0.07], "n_null": [19], "null": ["swap"], "seed_sets": [4],
                         "variants_per_cell": [12]})

    def text(inter: pd.DataFrame) -> str:
        answer, _ = answer_sentences({"evidence_headline": head,
                                      "evidence_interaction": interaction_verdicts(inter)})
        return " ".join(a["lead"] + " " + a["text"] for a in answer)

    said = text(rows)
    assert "mean delay differences change more than under the null (t = 6.4" in said
    assert "robot time differences are not shown to change more" in said
    assert "not whether orderings cross" in said and "each of its 3 rows" in said
    assert "Robot time: under the matched shift, controller differences are not shown" in said
    none = text(rows.assign(p_t=0.5))
    assert "differences change more than under the null" not in none and "not shown" in none
    few = text(rows.assign(n_null=2))
    assert "cannot be tested for a change (2 null replicates; the test needs 3)" in few


def test_rows_without_a_term_say_why_not_that_replicates_are_missing():
    """A study whose cells hold one episode ran its null replicates, but no controller
    difference has a bootstrap spread (terms 0): the paragraph and the card say that, once,
    not '0 null replicates; the test needs 3' (false: it ran 3)."""
    from popnavshift.analysis.interaction import NO_TERMS
    from popnavshift.evaluate.robustness import interaction_sentence
    from popnavshift.report.plain import answer_sentences

    inter = interaction_verdicts(pd.DataFrame({
        "comparison": "matched", "metric": ["robot_time", "mean_delay"], "t": np.nan,
        "p_t": np.nan, "n_null": 0, "terms": 0, "design": "matched"}))
    head = pd.DataFrame({"comparison": ["matched"] * 2, "metric": ["robot_time", "mean_delay"],
                         "rule": "raw", "verdict": "undecided", "excess": 0.02,
                         "ci_low": -0.03, "ci_high": 0.07, "n_null": 3, "null": "swap",
                         "seed_sets": 1, "variants_per_cell": 3})
    answer, _ = answer_sentences({"evidence_headline": head, "evidence_interaction": inter})
    said = " ".join(a["lead"] + " " + a["text"] for a in answer)
    assert said.count(NO_TERMS) == 2 and "null replicates" not in said.split("decide them.")[1]
    assert "0 null replicates" not in said and "needs more episodes per cell" in said
    assert NO_TERMS in interaction_sentence(inter, "HRVO")
    few = interaction_sentence(inter.assign(terms=4), "HRVO")
    assert "too few null replicates" in few and NO_TERMS not in few


def unit_orderings(rng: np.random.Generator, *, n_null: int, effect: Sequence[float] = (),
                   n_cells: int = 8, n_boot: int = 40) -> tuple[Orderings, list, list]:
    """Orderings of 4 populations, each with ``n_null`` independent stand-ins (one unit per
    population, as size-matched subsets are): every population instance moves all its
    cells' controller difference by a heavy-tailed draw of its own (t₂: what makes the null
    T far from normal), plus episode noise; observed population i by ``effect[i]`` more."""
    pops = ["a", "b", "c", "d"]
    names = [f"{p}{k}" for k in range(n_null + 1) for p in pops]
    shift = rng.standard_t(2, size=(len(names), 1, 1))
    shift[:len(effect), 0, 0] += effect
    diff = shift + 0.3 * rng.standard_normal((len(names), n_cells, 1))
    boot = (diff[None] + 0.5 * rng.standard_normal((n_boot, *diff.shape))).astype(np.float32)
    nan = np.full(diff.shape, np.nan)
    o = Orderings("mean_delay", names, pd.DataFrame({"cell": range(n_cells)}), [("x", "y")],
                  diff, nan, nan, nan, nan, boot, 0.9, 0.0, np.full(n_cells, 5))
    pairs = [(p, q) for i, p in enumerate(pops) for q in pops[i + 1:]]
    observed = [(f"{p}0", f"{q}0") for p, q in pairs]
    nulls = [[(f"{p}{k}", f"{q}{k}") for p, q in pairs] for k in range(1, n_null + 1)]
    return o, observed, nulls


UNITS = tuple(ord(x) - ord("a") for pair in ("ab", "ac", "ad", "bc", "bd", "cd") for x in pair)


def test_recombined_designs_make_an_exact_test():
    """400 null designs whose populations carry heavy-tailed shifts: the randomization test
    over designs recombined population by population claims at its nominal 10 %, neither
    more nor (beyond chance) less."""
    rng = np.random.default_rng(11)
    n, claims = 400, 0
    for _ in range(n):
        o, observed, nulls = unit_orderings(rng, n_null=5)
        claims += interaction_test(o, observed, nulls, units=UNITS, draws=99)[0]["p_t"] <= 0.1
    low, high = clopper_pearson(claims, n)
    assert low <= 0.1 <= high


def test_recombined_designs_find_a_planted_interaction_and_are_reproducible():
    rng = np.random.default_rng(5)
    o, observed, nulls = unit_orderings(rng, n_null=9, effect=(-30.0, -10.0, 10.0, 30.0))
    row, reps = interaction_test(o, observed, nulls, units=UNITS, draws=199)
    assert row["reference"] == RECOMBINED and row["n_null"] == 9
    assert row["p_t"] == pytest.approx(1 / 200) and row["t"] > 2  # above every draw
    # carried by one population alone, the observed is matched by the recombinations that
    # draw that population's unit from the observed (1 in 10): p cannot fall far below it
    one, _ = interaction_test(*unit_orderings(rng, n_null=9, effect=(0, 0, 0, 30.0)),
                              units=UNITS, draws=199)
    assert 0.03 <= one["p_t"] <= 0.3
    again = interaction_test(o, observed, nulls, units=UNITS, draws=199)
    assert again[0] == row and again[1].equals(reps)
    # placebos against the next 3 replicates, each by its own recombinations
    _, cyc = interaction_test(o, observed, nulls, units=UNITS, draws=99, null_size=3)
    assert cyc["placebo_p_t"].between(0.01, 1).all() and len(cyc) == 9
    assert interaction_test(o, observed, nulls)[0]["reference"] == PREDICTION


def test_a_pairs_design_has_one_unit_per_population_and_one_for_the_swap():
    specs = [PopulationSpec(p) for p in ("mixed", "high_caution", *MATCHED_PAIR)]
    specs += [PopulationSpec.sized(p, k) for k in (1, 2) for p in
              ("mixed", "high_caution", *MATCHED_PAIR)]
    specs += [PopulationSpec.swap(k, arm) for k in (1, 2) for arm in "ab"]
    d = headline_designs(specs, ["mixed", "high_caution", *MATCHED_PAIR])["all_pairs"]
    by_pair = dict(zip(d.observed, zip(d.units[0::2], d.units[1::2], strict=True),
                       strict=True))
    swap = by_pair[MATCHED_PAIR]
    assert swap[0] == swap[1]  # both arms of a swap permutation move together
    assert by_pair[("mixed", "high_caution")][0] == by_pair[("mixed", MATCHED_PAIR[0])][0]
    assert len(set(d.units)) == 5  # 4 populations' subsets and the swap


def test_recombined_ranks_counted_per_population_pair_are_the_rank_statistic():
    """The recombined test's T (mid-ranks counted once per distinct population pair) is
    bit for bit :func:`rank_statistic` of the designs' z, with missing values and ties."""
    rng = np.random.default_rng(3)
    for _ in range(3):
        o, observed, nulls = unit_orderings(rng, n_null=9)
        o.boot[rng.random(o.boot.shape) < 0.01] = np.nan
        o.diff[3], o.boot[:, 3] = o.diff[7], o.boot[:, 7]  # two populations alike: ties
        rec = Recombined(o, [observed, *nulls], UNITS)
        designs = rng.integers(10, size=(300, 4))
        assert np.array_equal(rec.statistic(designs), rank_statistic(rec.z(designs)),
                              equal_nan=True)
    # a pool of 31 designs: up to 961 distinct population pairs per pair of the design
    o, observed, nulls = unit_orderings(rng, n_null=30)
    rec = Recombined(o, [observed, *nulls], UNITS)
    designs = rng.integers(31, size=(3000, 4))
    assert np.array_equal(rec.statistic(designs), rank_statistic(rec.z(designs)),
                          equal_nan=True)


def test_weighted_midranks_are_the_midranks_of_the_repeated_values():
    """Each value's mid-rank among its column's values repeated w times is scipy's
    mid-rank of the repeated column, with ties, zero weights and missing values."""
    rng = np.random.default_rng(8)
    v = rng.integers(0, 6, size=(40, 7)).astype(float)  # many ties
    v[rng.random(v.shape) < 0.1] = np.nan
    w = rng.integers(0, 4, size=v.shape) * np.isfinite(v)
    got = weighted_midranks(v, w)
    for t in range(v.shape[1]):
        ok = w[:, t] > 0
        rep = np.repeat(v[ok, t], w[ok, t])
        want = stats.rankdata(rep)
        for i in np.flatnonzero(ok):  # every repeat of value i has the same mid-rank
            assert got[i, t] == want[np.flatnonzero(rep == v[i, t])[0]]
    assert np.isnan(got[~np.isfinite(v)]).all()
