"""Paired significance, nulls and power on synthetic tables where the answer is known."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from popnavshift.analysis import cell_key, cell_metrics, paired_delays
from popnavshift.analysis.calibrate import calibration_table
from popnavshift.analysis.delay import cvar, worst_decile
from popnavshift.analysis.evidence import test_comparisons as run_tests
from popnavshift.analysis.nulls import headline_designs
from popnavshift.analysis.resample import build_design, episode_weights, resampled_metrics
from popnavshift.analysis.significance import (
    bh,
    crossover_p,
    detectable_crossover,
    holm,
    orderings,
)
from popnavshift.analysis.verdicts import ABOVE, BELOW, clopper_pearson
from popnavshift.populations.identity import MATCHED_PAIR
from synth_study import (
    CROSS_CELLS,
    crossover,
    design_specs,
    no_effect,
    swap_study,
    synthetic_cells,
    synthetic_study,
)


def analyse_matched(runs, peds, *, n_boot=200, seed=0, metrics=("mean_delay", "robot_time")):
    designs = headline_designs(design_specs(runs, "swap"), list(MATCHED_PAIR))
    return run_tests(runs, peds, designs, list(MATCHED_PAIR), rng=np.random.default_rng(seed),
                     n_boot=n_boot, metrics=metrics)


def head(t, metric, rule="sig"):
    h = t.headline
    return h[(h["comparison"] == "matched") & (h["metric"] == metric)
             & (h["rule"] == rule)].iloc[0]


# --- the episode bootstrap ---------------------------------------------------------------


def test_unit_weights_reproduce_the_cell_metrics():
    runs, peds = synthetic_study({"P": no_effect, "Q": no_effect}, n_cells=4, variants=3)
    paired = paired_delays(peds)
    cells = cell_metrics(runs, paired)
    design = build_design(runs, paired)
    ones = np.ones((1, design.n_columns), dtype=np.int32)
    got = resampled_metrics(design, ones)
    for m in ("robot_time", "mean_delay", "worst_decile", "cvar90"):
        np.testing.assert_allclose(got[m][0], cells[m].to_numpy(float), rtol=1e-5, err_msg=m)


def test_cell_tails_equal_the_reference_definitions_on_pooled_records():
    runs, peds = synthetic_study({"P": no_effect}, n_cells=3, variants=4, n_peds=7)
    paired = paired_delays(peds)
    cells = cell_metrics(runs, paired).set_index(["cell", "controller"])
    per = paired.assign(cell=paired["episode"].str.rsplit("-v", n=1).str[0])
    for (cell, ctrl), g in per.groupby(["cell", "controller"]):
        d = g["delay"].to_numpy()  # 4 variants × 7 pedestrians = 28 records: tails differ
        assert cells.loc[(cell, ctrl), "cvar90"] == pytest.approx(cvar(d))
        assert cells.loc[(cell, ctrl), "worst_decile"] == pytest.approx(worst_decile(d))
        assert cvar(d) != pytest.approx(worst_decile(d))


def test_episode_weights_resample_within_cells_and_follow_the_seed():
    runs, peds = synthetic_study({"P": no_effect}, n_cells=5, variants=4)
    design = build_design(runs, paired_delays(peds))
    a = episode_weights(design, 30, np.random.default_rng(1))
    b = episode_weights(design, 30, np.random.default_rng(1))
    c = episode_weights(design, 30, np.random.default_rng(2))
    np.testing.assert_array_equal(a, b)
    assert (a != c).any()
    for _, cols in design.episodes.groupby("cell")["column"]:
        assert (a[:, cols.to_numpy()].sum(axis=1) == len(cols)).all()  # n episodes per cell


# --- orderings, significant reversals and the swap null ---------------------------------


def test_an_injected_crossover_is_found_and_beats_the_swap_null():
    runs, peds = swap_study(19, inject=1.5, seed=3)
    t = analyse_matched(runs, peds)
    row = head(t, "mean_delay")
    assert row["n_null"] == 19
    assert row["observed"] > 0.2  # the injected cells reverse significantly
    assert row["p_value"] == pytest.approx(1 / 20)  # beats every one of the 19 permutations
    assert row["test"] == "permutation" and row["verdict"] == ABOVE
    raw = head(t, "mean_delay", rule="raw")
    assert raw["verdict"] == ABOVE and raw["ci_low"] > 0  # the prediction interval above 0
    assert head(t, "robot_time", rule="raw")["verdict"] == ABOVE  # a shifts robot time too
    cross = t.crossovers[(t.crossovers["metric"] == "mean_delay")
                         & (t.crossovers["comparison"] == "matched")]
    found = cross[cross["crossover"]]
    # every crossover found is of controller a, in an injected cell
    assert len(found) >= 3
    assert found[["ctrl_1", "ctrl_2"]].apply(lambda r: "a" in set(r), axis=1).all()
    injected = {cell_key(*c) for i, c in enumerate(synthetic_cells(12)) if i in CROSS_CELLS}
    assert set(found["cell"]) <= injected


@pytest.mark.slow  # many simulated studies of pure noise (10–20 s)
def test_pure_noise_keeps_every_verdict_rule_at_its_nominal_rate():
    """30 synthetic matched studies without any population effect, each with 9 swap
    permutations, through the real analysis: the observed pair's verdicts, and every
    placebo of every study (each permutation as the observed against the others)."""
    p_values, claims, crossovers, nulls = [], 0, [], []
    n = 30
    for seed in range(n):
        runs, peds = swap_study(9, inject=0.0, seed=100 + seed, n_cells=6, variants=3, n_peds=5)
        t = analyse_matched(runs, peds, n_boot=60, seed=seed, metrics=("mean_delay",))
        row = head(t, "mean_delay", rule="raw")
        p_values.append(row["p_value"])
        claims += row["verdict"] in (ABOVE, BELOW)
        crossovers += [bool(t.crossovers["crossover"].any()),
                       *t.placebo_crossovers["any"].astype(bool)]
        nulls.append(t.null_rates.assign(metric=f"mean_delay-{seed}"))
    p = np.array(p_values)
    # the permutation p of 9 exchangeable nulls is uniform on {0.1, 0.2, …, 1} (ties
    # make it conservative): mean ≈ 0.55, P(p ≤ 0.1) ≤ 0.1
    assert 0.4 < p.mean() < 0.75
    assert (p <= 0.1).mean() <= 0.2
    assert stats.kstest(p, "uniform").pvalue > 0.01
    # the prediction t claims an effect for at most 5 % of pure-noise pairs (CP lower end)
    assert clopper_pearson(claims, n)[0] <= 0.05
    # no crossover table of pure noise shows a crossover more often than 5 %
    assert clopper_pearson(sum(crossovers), len(crossovers))[0] <= 0.05
    # the calibration of 270 placebos: every false-positive rule within its nominal level
    cal = calibration_table(pd.concat(nulls, ignore_index=True))
    fp = cal[(cal["comparison"] == "all") & (cal["kind"] == "false positive")]
    assert len(fp) >= 4 and fp["within"].all()


def test_orderings_are_significant_only_for_real_differences():
    big = {"P": crossover(range(12), 3.0, +1.0)}
    runs, peds = synthetic_study(big, variants=6)
    paired = paired_delays(peds)
    cells = cell_metrics(runs, paired)
    design = build_design(runs, paired)
    boot = resampled_metrics(design, episode_weights(design, 200, np.random.default_rng(0)))
    o = orderings(cells, design, boot, "mean_delay")
    t = o.table()
    with_a = t[(t["ctrl_1"] == "a")]
    assert (with_a["sig"] == 1).mean() > 0.9  # a is 3 s slower: (a − b), (a − c) > 0
    assert (with_a["low"] > 0).mean() > 0.9


# --- the crossover test and multiplicity control -------------------------------------------


def test_crossover_p_by_hand():
    # two populations, t = ±3 on 9 df (n = 10, SE scaled by √(10/9)): p = 2 · P(t₉ > 3)
    se = 1 / np.sqrt(10 / 9)
    p = crossover_p(np.array([[3.0, -3.0], [3.0, 3.0], [3.0, np.nan]]),
                    np.full((3, 2), se), np.full(3, 10.0))
    assert p[0] == pytest.approx(2 * stats.t.sf(3.0, 9))
    assert p[1] == pytest.approx(1.0)  # both positive: no evidence of a negative side
    assert np.isnan(p[2])  # one population cannot cross
    # three populations: Bonferroni over them on each side, the weaker side decides
    p3 = crossover_p(np.array([[4.0, -2.0, 1.0]]), np.full((1, 3), se), np.array([10.0]))
    assert p3[0] == pytest.approx(3 * stats.t.cdf(-2.0, 9))


def test_detectable_crossover_grows_with_the_table_and_shrinks_with_episodes():
    y = detectable_crossover(np.array([0.2, 0.2, 0.2]), np.array([3.0, 12.0, 12.0]),
                             np.array([2, 2, 2]), m=100)
    assert y[0] > 10 * y[1]  # 3 episodes (2 df) can see almost nothing
    assert detectable_crossover(np.array([0.2]), np.array([12.0]), np.array([2]), m=1000)[0] \
        > y[1]
    # at the detectable size a crossover is found with 80 % power (Monte Carlo: normal
    # differences, their SE estimated on n − 1 degrees of freedom)
    rng = np.random.default_rng(0)
    n, se, m, k = 12, 0.2, 100, 4000
    sigma = se * np.sqrt(n / (n - 1))  # the true SD of a difference
    d = np.column_stack([y[1] + sigma * rng.standard_normal(k),
                         -y[1] + sigma * rng.standard_normal(k)])
    se_hat = se * np.sqrt(rng.chisquare(n - 1, (k, 2)) / (n - 1))
    p = crossover_p(d, se_hat, np.full(k, float(n)))
    assert 0.76 < (p <= 0.05 / m).mean() < 0.84


def test_holm_and_bh_by_hand():
    p = np.array([0.01, 0.04, 0.03, 0.2, np.nan])
    np.testing.assert_allclose(holm(p)[:4], [0.04, 0.09, 0.09, 0.2])
    np.testing.assert_allclose(bh(p)[:4], [0.04, 0.16 / 3, 0.16 / 3, 0.2])
    assert np.isnan(holm(p)[4]) and np.isnan(bh(p)[4])


# --- tail statistic and power --------------------------------------------------------------


def test_cvar_by_hand_and_equal_to_the_worst_decile_at_multiples_of_ten():
    x = np.arange(1.0, 21.0)  # 20 records: the tail is the 2 largest
    assert cvar(x) == pytest.approx(19.5) == worst_decile(x)
    y = np.arange(1.0, 16.0)  # 15 records: 1.5 records, the 15 and half of the 14
    assert cvar(y) == pytest.approx((15 + 0.5 * 14) / 1.5)
    assert worst_decile(y) == pytest.approx(14.5)  # ⌈1.5⌉ = 2 records
    assert cvar(np.array([3.0])) == 3.0 and np.isnan(cvar(np.array([])))


def sized_study(n_null: int, *, inject: float, seed: int, **kw):
    """Three cohorts (P and Q cross over on controller a by ±inject in CROSS_CELLS, mixed
    does not) and ``n_null`` size-matched replicates of P and Q with no effect."""
    pops = {"mixed": no_effect, "high_caution": crossover(CROSS_CELLS, inject, -1.0),
            "low_robot_trust": crossover(CROSS_CELLS, inject, +1.0)}
    for k in range(1, n_null + 1):
        pops[f"high_caution_sized{k}"] = no_effect
        pops[f"low_robot_trust_sized{k}"] = no_effect
    return synthetic_study(pops, seed=seed, **kw)


def sized_headline(runs, peds, *, n_boot=150, seed=0, rule="sig"):
    obs = ["mixed", "high_caution", "low_robot_trust"]
    specs = design_specs(runs, "sized", obs)
    designs = {"all_pairs": headline_designs(specs, obs)["all_pairs"]}
    t = run_tests(runs, peds, designs, obs, rng=np.random.default_rng(seed), n_boot=n_boot,
                  metrics=("mean_delay",))
    h = t.headline
    return h[h["rule"] == rule].iloc[0]


def test_cohort_pairs_with_a_true_crossover_beat_the_size_matched_null():
    runs, peds = sized_study(19, inject=1.5, seed=5)
    row = sized_headline(runs, peds)
    assert row["n_null"] == 19
    assert row["p_value"] == pytest.approx(1 / 20) and row["ci_low"] > 0


@pytest.mark.slow  # many simulated studies of pure noise (10–20 s)
def test_cohort_pairs_without_an_effect_do_not_beat_the_size_matched_null():
    p_values = []
    for seed in range(20):
        runs, peds = sized_study(9, inject=0.0, seed=300 + seed, n_cells=6, variants=3, n_peds=5)
        p_values.append(sized_headline(runs, peds, n_boot=60, seed=seed, rule="raw")["p_value"])
    p = np.array(p_values)
    assert 0.35 < p.mean() < 0.8 and (p <= 0.1).mean() <= 0.25
