"""The power advice, from a model of the whole replicate curve, on curves where the truth
is known: the excess and the null SD are exact functions of the seed sets."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from popnavshift.analysis.power import (
    HOLDOUT_BIAS,
    POWER,
    Costs,
    Spread,
    advise_prediction,
    chance,
    design_advice,
    fit_curve,
    holdout,
    sd_exponent,
)
from popnavshift.analysis.verdicts import ABOVE, DESCRIPTIVE, UNDECIDED
from popnavshift.cli.plan import advice_text, holdout_lines

ROOT = ("root", "constant")  # the form of the synthetic truth (the package's may differ)
COSTS = Costs(per_population=1000.0, observed=2, per_replicate=2, runs_per_second=500.0)
S = np.array([1, 2, 3, 4])


def test_the_sd_exponent_is_measured_not_assumed():
    half = pd.DataFrame({"seed_sets": S, "null_sd": 0.03 / np.sqrt(S)})
    flat = pd.DataFrame({"seed_sets": S, "null_sd": np.full(4, 0.03)})
    assert sd_exponent(half) == pytest.approx(0.5)
    assert sd_exponent(flat) == pytest.approx(0.0)
    assert np.isnan(sd_exponent(half.iloc[:1]))


def test_each_form_recovers_its_own_curve():
    for form, g in (("root", np.sqrt), ("log", np.log), ("saturating", lambda s: -1 / np.sqrt(s))):
        fit = fit_curve(S, 0.01 + 0.02 * g(S), 0.02 / S ** 0.3, (form, "power"))
        assert fit.excess(9) == pytest.approx(0.01 + 0.02 * g(9.0))
        assert fit.sd(9) == pytest.approx(0.02 / 9 ** 0.3)
        assert fit.growing
    flat = fit_curve(S, np.full(4, 0.03), np.full(4, 0.02), ("root", "constant"))
    assert flat.excess(16) == pytest.approx(0.03) and not flat.growing
    one = fit_curve(S[:1], [0.03], [0.02])  # one seed set: no curve, constant
    assert one.excess_form == "constant" and one.points == 1
    none = fit_curve(S, np.full(4, np.nan), np.full(4, 0.02))  # no usable point
    assert none.points == 0 and not none.growing
    assert advise_prediction(none, 4, 9, COSTS)["limit"].startswith("cannot estimate")


def test_an_excess_rising_as_root_s_is_decided_where_the_truth_says():
    """The truth: δ(S) = 0.03·√S, s = 0.02 at every S. The advice must name the cheapest
    design whose true chance reaches 80 %, with the true t there."""
    fit = fit_curve(S, 0.03 * np.sqrt(S), np.full(4, 0.02), ROOT)
    spread = Spread(0.0, 1.0)
    alpha = 0.05 / 8
    adv = advise_prediction(fit, 4, 9, COSTS, spread=spread, alpha=alpha)
    s1, p1 = int(adv["seed_sets_needed"]), int(adv["nulls_needed"])
    assert s1 > 4 and "seed sets" in adv["limit"]
    true_t = 0.03 * np.sqrt(s1) / (0.02 * np.sqrt(1 + 1 / p1))
    assert adv["t_predicted"] == pytest.approx(true_t)
    assert adv["chance"] >= POWER
    assert adv["t_low"] < true_t < adv["t_high"]
    # nothing cheaper reaches the chance: every design at fewer seed sets and at most
    # as many replicates falls short
    for s in range(4, s1):
        assert chance(fit, s, p1, 4, spread, alpha=alpha) < POWER
    assert adv["runs_needed"] == COSTS.runs(4, 9, s1, p1)


def test_a_flat_excess_gets_the_advice_of_a_fixed_excess():
    """δ and s flat over the curve: the advice is §8's (excess fixed, 80 % power as
    s·√(1+1/P′)·(t_crit + z₀.₈) ≤ δ) — only more replicates, the fewest that reach it.
    (§8 counted one way to decide; the model adds the chance of the other, *no excess ≥
    5 pp*, negligible here: δ is 3 null SDs above 5 pp.)"""
    fit = fit_curve(S, np.full(4, 0.10), np.full(4, 0.03))
    adv = advise_prediction(fit, 4, 5, COSTS, spread=Spread(0.0, 1.0))
    need = next(p for p in range(5, 100) if 0.03 * np.sqrt(1 + 1 / p) * (
        stats.t.ppf(0.975, p - 1) + stats.norm.ppf(POWER)) <= 0.10)
    assert adv["limit"] == "null replicates" and adv["seed_sets_needed"] == 4
    assert adv["nulls_needed"] == need
    assert adv["minutes_needed"] == pytest.approx(adv["runs_needed"] / 500 / 60)


def test_nothing_reachable_is_never_said_while_the_fitted_excess_rises():
    rising = fit_curve(S, 0.004 * np.sqrt(S), np.full(4, 0.4), ROOT)
    adv = advise_prediction(rising, 4, 9, COSTS)
    assert "nothing reachable" not in adv["limit"] and "still growing" in adv["limit"]
    assert adv["seed_sets_needed"] == 20 and adv["chance"] < POWER  # the most it promises
    flat = fit_curve(S, np.full(4, 0.02), np.full(4, 0.2))
    assert advise_prediction(flat, 4, 9, COSTS)["limit"].startswith("nothing reachable")
    one = advise_prediction(fit_curve(S[:1], [0.02], [0.2]), 1, 9, COSTS)
    assert "one seed set" in one["limit"] and "seed_sets_needed" not in one


def test_the_hold_out_predicts_the_last_point_from_the_first_two():
    truth = pd.DataFrame({"seed_sets": S, "excess": 0.02 * np.sqrt(S), "null_sd": 0.02})
    h = holdout(truth, 9, ROOT)
    assert h["holdout_at"] == 4 and h["holdout_error"] == pytest.approx(0.0, abs=1e-9)
    bumped = truth.assign(excess=truth["excess"] + np.where(S == 4, 0.01, 0.0))
    expected = 0.01 / (0.02 * np.sqrt(10 / 9))
    assert holdout(bumped, 9, ROOT)["holdout_error"] == pytest.approx(expected)
    assert np.isnan(holdout(truth.iloc[:2], 9, ROOT)["holdout_error"])  # S₀ = 2: nothing held out


def _head():
    return pd.DataFrame([
        {"comparison": "matched", "metric": "mean_delay", "rule": "raw", "verdict": ABOVE,
         "test": "prediction t", "excess": 0.08, "null_sd": 0.02, "n_null": 9,
         "seed_sets": 4, "n_null_above": 0},
        {"comparison": "matched", "metric": "cvar90", "rule": "raw", "verdict": UNDECIDED,
         "test": "prediction t", "excess": 0.04 * np.sqrt(4), "null_sd": 0.03, "n_null": 9,
         "seed_sets": 4, "n_null_above": 0},
        {"comparison": "matched", "metric": "cvar90", "rule": "sig", "verdict": DESCRIPTIVE,
         "test": "permutation", "excess": 0.04, "null_sd": 0.02, "n_null": 9,
         "seed_sets": 4, "n_null_above": 2}])


def _curve():
    return pd.DataFrame({"metric": "cvar90", "rule": "raw", "seed_sets": S,
                         "excess": 0.04 * np.sqrt(S), "null_sd": 0.03})


def test_design_advice_fits_each_rows_curve_and_reports_its_hold_out():
    out = design_advice(_head(), _curve(), COSTS, alpha=0.05 / 8, model=ROOT)
    assert out.loc[0, "limit"] == "decided" and np.isnan(out.loc[0, "runs_needed"])
    row = out.loc[1]
    assert row["excess_form"] == "root" and row["excess_slope"] == pytest.approx(0.04)
    assert row["runs_needed"] > 0 and row["chance"] >= POWER
    assert row["holdout_error"] == pytest.approx(0.0, abs=1e-9)
    assert out.loc[2, "limit"].startswith("nothing reachable")  # a null is above it
    assert np.isnan(out.loc[2, "holdout_error"])  # the permutation rule has no t to predict


def test_plan_words_give_the_interval_and_the_hold_out():
    out = design_advice(_head(), _curve(), COSTS, alpha=0.05 / 8, model=ROOT)
    text = advice_text(next(out.iloc[[1]].itertuples(index=False)))
    assert "seed sets" in text and "; t " in text and "decided with chance" in text
    lines = holdout_lines(out)
    assert len(lines) == 1 and "predicted from seed sets 1–2 was off by" in lines[0]
    assert "cvar90 +0.0" in lines[0]


def test_the_chosen_model_still_says_the_excess_grows():
    """The package's model holds the excess constant (chosen by hold-out); a rising curve
    is still reported as rising, never as nothing reachable, and a flat one is not."""
    rising = fit_curve(S, 0.004 * np.sqrt(S), np.full(4, 0.4))
    assert rising.excess_form == "constant" and rising.growing
    adv = advise_prediction(rising, 4, 9, COSTS)
    assert "still growing" in adv["limit"] and "nothing reachable" not in adv["limit"]
    out = design_advice(_head(), _curve(), COSTS, alpha=0.05 / 8)
    s1, p1 = out.loc[1, "seed_sets_needed"], out.loc[1, "nulls_needed"]
    # the constant form's t, shifted by the growth per doubling it was measured to miss
    assert out.loc[1, "t_predicted"] == pytest.approx(
        0.08 / (0.03 * np.sqrt(1 + 1 / p1)) + HOLDOUT_BIAS * np.log2(s1 / 4))
    assert out.loc[1, "t_low"] < out.loc[1, "t_predicted"] < out.loc[1, "t_high"]


def test_a_wider_interval_does_not_buy_a_decision():
    """The model's uncertainty widens the interval; it never raises the chance of a
    decision (else the advice would pick a design for a lucky draw)."""
    fit = fit_curve(S, np.full(4, 0.04), np.full(4, 0.03))
    narrow, wide = Spread(0.0, 0.5), Spread(0.0, 5.0)
    assert chance(fit, 16, 20, 4, narrow) == chance(fit, 16, 20, 4, wide)
    assert advise_prediction(fit, 4, 9, COSTS, spread=wide)["limit"].startswith("nothing")


def test_a_null_too_spread_to_rule_out_the_margin_is_said_with_the_sd_it_would_need():
    """Flat excess +1 pp, null SD 3 pp: even unlimited replicates need SD < (5 − 1)/z to
    rule out 5 pp, so the advice names that SD; a tight null (0.5 pp) is not told so."""
    from popnavshift.analysis.verdicts import ALPHA, MIN_EFFECT

    wide = advise_prediction(fit_curve(S, np.full(4, 0.01), np.full(4, 0.03)), 4, 9, COSTS)
    need = (MIN_EFFECT - 0.01) / stats.norm.ppf(1 - ALPHA / 2)
    assert wide["limit"].startswith("nothing reachable")
    assert f"needs a null SD under {100 * need:.1f} pp" in wide["limit"]
    tight = fit_curve(S, np.full(4, 0.01), np.full(4, 0.005))
    assert "needs a null SD" not in advise_prediction(tight, 4, 9, COSTS).get("limit", "")
