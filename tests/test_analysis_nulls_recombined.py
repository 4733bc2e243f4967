"""The raw reversal rule against designs recombined unit by unit (analysis/recombine.py,
nulls.null_test): exact where the prediction t is not, on synthetic designs whose truth is
known; its verdict, interval and table-level decision agree; its placebos reach the
calibration table under their own name."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from popnavshift.analysis.calibrate import calibration_table, family_placebos
from popnavshift.analysis.nulls import family_verdicts, null_test
from popnavshift.analysis.recombine import (
    PLACEBO_PS,
    RECOMBINED,
    RecombinedRates,
    order_level,
    recombined_decide,
    tail_ps,
)
from popnavshift.analysis.significance import Orderings, pair_counts
from popnavshift.analysis.verdicts import (
    ABOVE,
    BELOW,
    SMALL,
    UNDECIDED,
    clopper_pearson,
    prediction_test,
)

POPS = ("a", "b", "c", "d")
PAIRS = [(p, q) for i, p in enumerate(POPS) for q in POPS[i + 1:]]
#: one unit per population, as size-matched subsets are: two per pair, in pair order
UNITS = tuple(POPS.index(x) for pair in PAIRS for x in pair)


def skewed(rng: np.random.Generator, *, n_null: int = 9, n_cells: int = 40,
           effect: float = 0.0) -> tuple[Orderings, list, list]:
    """Orderings of 4 populations, each with ``n_null`` independent stand-ins. Every
    population instance flips the sign of each cell's controller difference with its own
    probability, drawn from Beta(0.15, 3): most instances flip almost nothing, a few flip
    many cells, so a design's reversal rate has a right-skewed null — the shape a t on
    P − 1 df does not model. The observed instances flip ``effect`` more."""
    names = [f"{p}{k}" for k in range(n_null + 1) for p in POPS]
    pi = rng.beta(0.15, 3.0, size=(len(names), 1, 1))
    pi[:len(POPS)] = np.minimum(pi[:len(POPS)] + effect, 1.0)
    diff = np.where(rng.random((len(names), n_cells, 1)) < pi, -1.0, 1.0)
    nan = np.full(diff.shape, np.nan)
    o = Orderings("mean_delay", names, pd.DataFrame({"cell": range(n_cells)}), [("x", "y")],
                  diff, nan, nan, nan, np.sign(diff), np.repeat(diff[None], 2, 0)
                  .astype(np.float32), 0.9, 0.0, np.full(n_cells, 5))
    observed = [(f"{p}0", f"{q}0") for p, q in PAIRS]
    nulls = [[(f"{p}{k}", f"{q}{k}") for p, q in PAIRS] for k in range(1, n_null + 1)]
    return o, observed, nulls


def test_on_a_skewed_null_the_recombined_rule_holds_its_level_and_the_prediction_t_does_not():
    """2,000 null designs of a right-skewed reversal rate, 9 replicates each: the prediction
    t claims *above the null* well above its nominal 2.5 % (measured 6.4 %), the
    randomization test over recombined designs does not exceed it."""
    rng = np.random.default_rng(0)
    n, rec, pred = 2000, 0, 0
    for _ in range(n):
        o, observed, nulls = skewed(rng)
        r = RecombinedRates(o, [observed, *nulls], UNITS)
        rate, ref = r.reference(0, range(1, 10), draws=199, seed=[0])
        null = r.rates(r.rec.own(np.arange(1, 10)))
        rec += recombined_decide(rate, ref, null_mean=null.mean(), alpha=0.05)["verdict"] \
            == ABOVE
        pred += prediction_test(rate, null)["verdict"] == ABOVE
    assert clopper_pearson(pred, n)[0] > 0.025  # the failure the remedy is for
    assert clopper_pearson(rec, n)[0] <= 0.025  # exact: never above nominal


def test_a_planted_excess_is_found_and_the_rates_are_the_pair_counts():
    rng = np.random.default_rng(4)
    o, observed, nulls = skewed(rng, effect=0.4)
    rows, reps = null_test(o, observed, nulls, units=UNITS, draws=999)
    raw = next(r for r in rows if r["rule"] == "raw")
    assert raw["test"] == RECOMBINED and raw["verdict"] == ABOVE
    # an excess carried by the tested units also enters the recombinations that draw them
    # (1 in 10 per unit): conservative, p well above 1/1000
    assert 1 / 1000 < raw["p_above"] <= 0.025 and raw["ci_low"] > 0
    assert raw["observed"] == pytest.approx(pair_counts(o, observed).rate("raw"))
    r = RecombinedRates(o, [observed, *nulls], UNITS)
    own = r.rates(r.rec.own(np.arange(10)))
    assert own == pytest.approx([pair_counts(o, g).rate("raw") for g in [observed, *nulls]])
    # the significant rule keeps its exact permutation test; without units the prediction t
    assert next(r for r in rows if r["rule"] == "sig")["test"] == "permutation"
    assert next(r for r in null_test(o, observed, nulls)[0]
                if r["rule"] == "raw")["test"] == "prediction t"
    # reproducible, and every replicate's raw row carries its placebo's p-values
    again = null_test(o, observed, nulls, units=UNITS, draws=999)
    assert again[1].equals(reps) and np.array_equal(
        next(x for x in again[0] if x["rule"] == "raw")["reference"], raw["reference"])
    raw_reps = reps[reps["rule"] == "raw"]
    assert raw_reps[list(PLACEBO_PS)].notna().all().all()
    assert reps.loc[reps["rule"] == "sig", list(PLACEBO_PS)].isna().all().all()


def test_the_verdict_is_its_interval_and_its_p_values_at_every_level():
    rng = np.random.default_rng(2)
    ref = np.round(rng.gamma(0.7, 0.04, size=1999), 3)  # skewed, with ties
    for rate in (*np.quantile(ref, [0.001, 0.02, 0.5, 0.97, 0.999]), 0.2, 0.0):
        for alpha in (0.05, 0.005):
            d = recombined_decide(rate, ref, null_mean=float(ref.mean()), alpha=alpha)
            up, down = tail_ps(rate, ref)
            assert (d["verdict"] == ABOVE) == (up <= alpha / 2) == (d["ci_low"] > 0)
            if d["verdict"] != ABOVE:
                assert (d["verdict"] == BELOW) == (down <= alpha / 2) == (d["ci_high"] < 0)
            if d["verdict"] not in (ABOVE, BELOW):
                assert (d["verdict"] == SMALL) == (d["ci_high"] < 0.05)
            assert d["p_t"] == pytest.approx(min(1, 2 * min(up, down)))
    assert order_level(ref[:9], 0.01) == (pytest.approx(np.nan, nan_ok=True),) * 2
    assert recombined_decide(np.nan, ref, null_mean=0.0, alpha=0.05)["verdict"] == UNDECIDED


def _headline(rows: list[dict], comparison: str) -> pd.DataFrame:
    return pd.DataFrame([{k: v for k, v in r.items() if k not in ("boot_excess", "reference")}
                         for r in rows]).assign(comparison=comparison)


def test_the_table_decides_a_recombined_row_at_its_share_of_the_level():
    """At α/m the row needs a smaller p: the planted excess stays *above* in a family of 2
    and, with 199 draws (p ≥ 1/200), cannot reach α/(2m) in a family of 10."""
    rng = np.random.default_rng(4)
    o, observed, nulls = skewed(rng, effect=0.4)
    rows, reps = null_test(o, observed, nulls, units=UNITS, draws=199)
    refs = {("pairs", "mean_delay", r["rule"]): r["reference"] for r in rows
            if "reference" in r}
    head = _headline(rows, "pairs")
    nulls_t = reps.assign(comparison="pairs")
    two = family_verdicts(pd.concat([head, head.assign(comparison="other")]),
                          pd.concat([nulls_t, nulls_t.assign(comparison="other")]),
                          references={**refs, **{("other", *k[1:]): v for k, v in refs.items()}})
    raw = two[(two["rule"] == "raw") & (two["comparison"] == "pairs")].iloc[0]
    assert raw["verdict"] == ABOVE and raw["ci_low"] > 0 and raw["family"] == 2
    ten = pd.concat([head.assign(comparison=f"c{i}") for i in range(10)])
    ten_nulls = pd.concat([nulls_t.assign(comparison=f"c{i}") for i in range(10)])
    wide = family_verdicts(ten, ten_nulls, references={(f"c{i}", *k[1:]): v for i in range(10)
                                                      for k, v in refs.items()})
    raw10 = wide[wide["rule"] == "raw"].iloc[0]
    assert raw10["verdict"] == UNDECIDED and not raw10["ci_low"] > 0
    # without its recombined rates the row is still decided, from its p-values
    bare = family_verdicts(ten, ten_nulls)
    assert (bare.loc[bare["rule"] == "raw", "verdict"] == UNDECIDED).all()


def test_its_placebos_are_counted_under_their_own_name_and_in_the_whole_table():
    rng = np.random.default_rng(6)
    o, observed, nulls = skewed(rng, n_null=19)
    rows, reps = null_test(o, observed, nulls, units=UNITS, draws=199)
    table = calibration_table(reps.assign(comparison="all_pairs"))
    mine = table[(table["test"] == RECOMBINED) & (table["comparison"] == "all_pairs")]
    assert set(mine["claim"]) == {"an effect (above or below)", "above the null",
                                  "no excess ≥ 5 pp, at +5 pp", "above the null, at +5 pp",
                                  "above the null, at +10 pp"}
    assert (mine["placebos"] == 19).all()
    assert mine.set_index("claim").loc["above the null, at +5 pp", "kind"] == "power"
    assert not ((table["test"] == "prediction t") & (table["comparison"] == "all_pairs")).any()
    # a placebo claims what its p-values say, at α/2 alone and at α/(2m) in the table
    raw = reps[reps["rule"] == "raw"]
    above = mine.set_index("claim").loc["above the null", "claims"]
    assert above == int((raw["placebo_p_above"] <= 0.025).sum())
    fam = family_placebos(reps.assign(comparison="all_pairs"), 10)
    effect = fam[fam["claim"].str.startswith("any rate")]["claim_made"].to_numpy()
    expect = (np.minimum(raw["placebo_p_above"], raw["placebo_p_below"]) <= 0.0025).to_numpy()
    assert np.array_equal(effect, expect)


def test_a_card_decides_its_pairs_rates_against_recombined_designs_as_the_headline_does():
    """A card's rates across the population pairs (pooled over its baselines and against
    each alone) rest on the same recombined test as the headline's, decided at the card's
    share of the level, with its placebos in the card's calibration."""
    from popnavshift.evaluate.robustness import robustness_tables
    from popnavshift.populations.identity import PopulationSpec
    from synth_study import design_specs, no_effect, synthetic_study

    observed = ["mixed", "high_caution", "low_robot_trust"]
    pops = {p: no_effect for p in observed}
    pops |= {PopulationSpec.sized(p, k).name: no_effect for p in observed for k in range(1, 6)}
    runs, peds = synthetic_study(pops, n_cells=6, variants=3, n_peds=4, seed=1)
    specs = {s.name: s for s in design_specs(runs, "sized", observed)}
    rob = robustness_tables(runs, peds, "a", ["b", "c"], specs, observed, rng_seed=0,
                            n_boot=40, interaction=False)
    raw = rob.headline[rob.headline["rule"] == "raw"]
    assert (raw["test"] == RECOMBINED).all() and len(raw) >= 4
    rated = raw[raw["observed"].notna()]  # blocked pedestrians: none here, no rate
    assert len(rated) >= 4 and rated["ci_low"].notna().all()  # from its recombined rates
    by = rob.by_baseline[rob.by_baseline["rule"] == "raw"]
    assert (by["test"] == RECOMBINED).all() and set(by["baseline"]) == {"b", "c"}
    assert by.loc[by["observed"].notna(), "ci_low"].notna().all()
    cal = rob.calibration
    assert ((cal["test"] == RECOMBINED) & (cal["claim"] == "above the null")).any()
