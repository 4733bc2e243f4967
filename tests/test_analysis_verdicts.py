"""Verdicts against null replicates and their calibration, on data where
the truth is known: synthetic rates (thousands of independent designs) and synthetic
studies run through the real analysis (:mod:`synth_study`)."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from popnavshift.analysis.calibrate import calibration_table, family_placebos, placebos, status
from popnavshift.analysis.verdicts import (
    ABOVE,
    BELOW,
    DESCRIPTIVE,
    NOT_SHOWN,
    SMALL,
    UNDECIDED,
    clopper_pearson,
    decide,
    min_nulls_permutation,
    permutation_p,
    permutation_test,
    prediction_test,
)

N_DESIGNS = 4000
MC = 3  # Monte-Carlo standard errors allowed above a nominal rate


def rates(rng: np.random.Generator, shape, *, comparisons: int = 600, base: float = 0.2,
          spread: float = 0.02) -> np.ndarray:
    """Raw-rule-like reversal rates: reversals / comparisons with a design-level rate that
    varies between replicates (overdispersed binomial), shape (…)."""
    p = np.clip(rng.normal(base, spread, shape), 0.01, 0.99)
    return rng.binomial(comparisons, p) / comparisons


def sig_rates(rng: np.random.Generator, shape, *, comparisons: int = 40) -> np.ndarray:
    """Significant-rule-like rates: a few reversals among few decided comparisons (mostly 0,
    skewed) — where a t on the replicates' spread is not calibrated."""
    lam = rng.gamma(0.5, 0.6, shape)
    return np.minimum(rng.poisson(lam), comparisons) / comparisons


def claim_rate(fn, observed: np.ndarray, nulls: np.ndarray, verdicts) -> float:
    return float(np.mean([fn(o, n)["verdict"] in verdicts
                          for o, n in zip(observed, nulls, strict=True)]))


def bound(nominal: float, n: int = N_DESIGNS) -> float:
    return nominal + MC * np.sqrt(nominal * (1 - nominal) / n)


# --- the rules on synthetic rates ------------------------------------------------------------


@pytest.mark.parametrize("n_null", [4, 9, 19])
def test_the_prediction_t_claims_an_effect_at_its_nominal_rate_under_the_null(n_null):
    rng = np.random.default_rng(n_null)
    draws = rates(rng, (N_DESIGNS, n_null + 1))
    observed, nulls = draws[:, 0], draws[:, 1:]
    assert claim_rate(prediction_test, observed, nulls, (ABOVE, BELOW)) <= bound(0.05)
    assert claim_rate(prediction_test, observed, nulls, (ABOVE,)) <= bound(0.025)
    # and it is not conservative to uselessness: close to nominal
    assert claim_rate(prediction_test, observed, nulls, (ABOVE, BELOW)) > 0.03


def test_the_prediction_t_rules_out_5_pp_wrongly_at_most_at_its_nominal_rate():
    rng = np.random.default_rng(7)
    draws = rates(rng, (N_DESIGNS, 10))
    observed = draws[:, 0] + 0.05  # the truth: an excess of exactly 5 pp
    assert claim_rate(prediction_test, observed, draws[:, 1:], (SMALL,)) <= bound(0.025)


def test_the_prediction_t_finds_an_injected_excess():
    rng = np.random.default_rng(8)
    draws = rates(rng, (1000, 10))
    sd = float(draws[:, 1:].std(ddof=1, axis=1).mean())
    found = claim_rate(prediction_test, draws[:, 0] + 5 * sd, draws[:, 1:], (ABOVE,))
    assert found > 0.8
    tight = rates(rng, (1000, 10), spread=0.005)  # replicate SD ≈ 1.7 pp
    small = claim_rate(prediction_test, tight[:, 0], tight[:, 1:], (SMALL,))
    assert small > 0.5  # no excess: the data usually rule out a 5-pp one


def test_on_skewed_small_counts_the_t_over_rejects_and_the_permutation_test_does_not():
    rng = np.random.default_rng(9)
    draws = sig_rates(rng, (N_DESIGNS, 20))
    observed, nulls = draws[:, 0], draws[:, 1:]
    t_rate = claim_rate(prediction_test, observed, nulls, (ABOVE, BELOW))
    perm = claim_rate(permutation_test, observed, nulls, (ABOVE,))
    assert perm <= bound(0.05)
    assert t_rate > perm  # why the significant rule rests on the exact test


def test_the_permutation_test_needs_19_replicates_to_decide():
    assert min_nulls_permutation(0.05) == 19
    assert permutation_test(0.9, np.zeros(9))["verdict"] == DESCRIPTIVE
    assert permutation_test(0.9, np.zeros(19))["verdict"] == ABOVE
    assert permutation_test(0.0, np.zeros(19))["verdict"] == NOT_SHOWN
    assert permutation_p(0.3, np.array([0.1, 0.3, 0.5, 0.2])) == pytest.approx(3 / 5)
    # a tie in exact arithmetic that summation order put a few ulps below still counts
    third = sum([1 / 3, 1 / 3, 1 / 3, 0.1]) / 4  # one order of the same four numbers …
    other = sum([0.1, 1 / 3, 1 / 3, 1 / 3]) / 4  # … and another
    assert permutation_p(max(third, other), np.array([min(third, other), 0.0])) == 2 / 3
    assert permutation_p(0.3, np.array([0.3 - 1e-9])) == 1 / 2  # a real difference is not


def test_prediction_interval_by_hand():
    null = np.array([0.20, 0.22, 0.18, 0.21, 0.19])
    d = prediction_test(0.30, null)
    s = null.std(ddof=1) * np.sqrt(1 + 1 / 5)
    half = stats.t.ppf(0.975, 4) * s
    assert d["excess"] == pytest.approx(0.10)
    assert d["ci_low"] == pytest.approx(0.10 - half) and d["ci_high"] == pytest.approx(0.10 + half)
    assert d["t"] == pytest.approx(0.10 / s) and d["df"] == 4
    assert d["verdict"] == ABOVE
    assert prediction_test(0.2, null[:2])["verdict"] == UNDECIDED  # 2 replicates: no verdict
    assert prediction_test(0.2, np.full(5, 0.2))["verdict"] == UNDECIDED  # no spread


def test_decide_takes_the_verdict_of_the_rules_test():
    null = np.linspace(0.1, 0.2, 9)
    assert decide(0.5, null, "raw")["test"] == "prediction t"
    assert decide(0.5, null, "raw")["verdict"] == ABOVE
    sig = decide(0.5, null, "sig")
    assert sig["test"] == "permutation" and sig["verdict"] == DESCRIPTIVE  # 9 < 19


def test_clopper_pearson_matches_scipy():
    low, high = clopper_pearson(3, 92)
    ref = stats.binomtest(3, 92).proportion_ci(method="exact")
    assert (low, high) == pytest.approx((ref.low, ref.high))
    assert clopper_pearson(0, 10)[0] == 0.0 and clopper_pearson(10, 10)[1] == 1.0


# --- calibration on placebos -----------------------------------------------------------------


def null_table(draws: np.ndarray, comparison: str = "matched", rule: str = "raw"
               ) -> pd.DataFrame:
    """A null-rates table from (designs, P) replicate rates, one metric per design."""
    return pd.DataFrame([{"comparison": comparison, "metric": f"m{i}", "rule": rule,
                          "replicate": k + 1, "rate": x}
                         for i, row in enumerate(draws) for k, x in enumerate(row)])


@pytest.mark.slow  # many simulated studies of pure noise (10–20 s)
def test_calibration_of_pure_noise_is_within_nominal_and_of_a_bad_rule_is_not():
    rng = np.random.default_rng(11)
    nulls = null_table(rates(rng, (300, 10)))
    cal = calibration_table(pd.concat([nulls, null_table(sig_rates(rng, (100, 20)), rule="sig")]))
    fp = cal[(cal["comparison"] == "all") & (cal["kind"] == "false positive")]
    assert set(fp["test"]) == {"prediction t", "exact permutation"}
    assert fp["within"].all(), fp
    t_any = fp[fp["claim"].str.startswith("an effect")].iloc[0]
    assert t_any["placebos"] == 3000
    # a rule that claimed on every placebo would be caught: its interval lies above 5%
    n = int(t_any["placebos"])
    assert status(*clopper_pearson(n, n), 0.05) == "above nominal"
    assert status(*clopper_pearson(int(0.08 * n), n), 0.05) == "above nominal"  # 8% of 3000
    power = cal[(cal["comparison"] == "all") & (cal["kind"] == "power")]
    assert (power["rate"].diff().dropna() >= 0).all()  # +10 pp is found more often than +5


def test_placebos_leave_one_replicate_out():
    nulls = null_table(np.array([[0.1, 0.2, 0.3, 0.9]]))
    p = placebos(nulls)
    above = p[(p["claim"] == "above the null")].set_index("replicate")["claim_made"]
    # replicate 4 (0.9) against the other three is far above them; the others are not
    assert above.to_dict() == {1: False, 2: False, 3: False, 4: True}


@pytest.mark.slow  # many simulated studies of pure noise (10–20 s)
def test_the_headline_table_as_a_whole_claims_at_most_its_nominal_rate():
    """The report decides its m rates together (each at 5%/m): on placebo tables of pure
    noise, any claim of the whole table is false, and happens at most 5% of the time."""
    rng = np.random.default_rng(12)
    tables = [null_table(rates(rng, (8, 10))).assign(comparison=f"c{i}") for i in range(150)]
    nulls = pd.concat(tables, ignore_index=True)
    claims = []
    for _, g in nulls.groupby("comparison"):
        fam = family_placebos(g.assign(comparison="one"), 8)
        claims += list(fam.loc[fam["claim"].str.startswith("any rate"), "claim_made"])
    assert len(claims) == 1500
    assert np.mean(claims) <= bound(0.05, len(claims))
    assert status(0.0, 0.08, 0.05) == "within" and status(0.06, 0.2, 0.05) == "above nominal"
    assert status(0.01, 0.2, 0.05) == "too few placebos to tell"


def test_the_binomial_floor_binds_only_where_rates_are_too_coarse_for_the_normal_model():
    from popnavshift.analysis.verdicts import NORMAL_COUNT, binomial_floor

    coarse = binomial_floor([2, 3, 2, 2], [12, 12, 12, 12])  # n̄·p(1−p) ≈ 2 < 5
    p = (9 + 0.5) / (48 + 1)
    assert coarse == pytest.approx(np.sqrt(p * (1 - p) / 12)) and 12 * p * (1 - p) < NORMAL_COUNT
    assert binomial_floor([40, 38, 41], [188, 190, 186]) == 0.0  # n̄·p(1−p) ≈ 31: no floor
    assert binomial_floor([], []) == 0.0 and binomial_floor([1], [0]) == 0.0
    # with the floor a coarse null that happens to agree cannot make a tiny spread decide
    tight = prediction_test(0.5, np.array([0.25, 0.25, 0.25, 0.26, 0.25]), floor=coarse)
    assert tight["verdict"] == "undecided"
