"""Test–retest in the respondent audit, from k independent samples per persona: a noisy
respondent comes out at its injected level, the deterministic rule respondent at perfect
agreement, a temperature-0 server whose samples differ is named not reproducible, and
one sample says test–retest is not measured and how to measure it."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pandas as pd
import pytest

from popnavshift.analysis.audit_retest import fleiss_kappa, icc_oneway, retest
from popnavshift.analysis.audit_verdict import MIN_ICC, USABLE, WEAK, audit_respondent
from popnavshift.hashing import unit_hash
from popnavshift.personas.synthetic import generate_personas
from popnavshift.personas.variants import matched_ids
from popnavshift.profiles.mappings import build_profiles
from popnavshift.read.respondent_tables import RespondentTables
from popnavshift.responses.collect import collect_responses
from popnavshift.responses.probes import PROBE_IDS
from popnavshift.responses.respondent import Answer, ProbeRequest, Progress, Respondent
from popnavshift.responses.rule import RuleRespondent
from popnavshift.responses.samples import aggregate_samples
from popnavshift.responses.schema import LEVELS
from popnavshift.tables import ACTIONS, BLOCK_ITEMS, Q_COLUMNS
from respondent_helpers import render_audit

N_PERM, N_BOOT = 399, 400
U_MEAN, U_SQUARE = 0.5, float(np.mean(np.linspace(0, 1, 5) ** 2))  # a uniform level


class NoisyRespondent(Respondent):
    """The rule respondent's answer, each item and action replaced, with probability
    ``p`` and independently per sample, by a uniform level or action."""

    name = "noisy"

    def __init__(self, p: float) -> None:
        self.p = p
        self.rule = RuleRespondent()

    def answer_all(self, requests: Sequence[ProbeRequest],
                   progress: Progress | None = None) -> list[Answer]:
        out = []
        for r in requests:
            a = self.rule.answer_one(r.persona_id, r.persona)
            key = (r.persona_id, r.variant, r.sample)
            for k in BLOCK_ITEMS:
                if unit_hash("hit", *key, k) < self.p:
                    a["block"][k] = LEVELS[int(5 * unit_hash("level", *key, k))]
            for pid in PROBE_IDS:
                if unit_hash("hit", *key, pid) < self.p:
                    a["actions"][pid] = ACTIONS[int(6 * unit_hash("act", *key, pid))]
            out.append(Answer(r.persona_id, r.variant, answer=a))
        return out


@pytest.fixture(scope="module")
def personas() -> pd.DataFrame:
    return generate_personas(600, seed=1)


def asked(personas: pd.DataFrame, respondent: Respondent, samples: int) -> pd.DataFrame:
    responses, invalid, _ = collect_responses(personas, respondent, matched_ids(personas, 202),
                                              samples=samples)
    assert invalid.empty
    return responses


def audit(personas: pd.DataFrame, responses: pd.DataFrame, meta: dict | None = None
          ) -> dict[str, pd.DataFrame]:
    profiles = build_profiles(aggregate_samples(responses), personas, "A")
    r = RespondentTables("first", responses, profiles, meta or {})
    return audit_respondent(personas, r, n_perm=N_PERM, n_boot=N_BOOT)


def expected_icc(truth: np.ndarray, p: float) -> float:
    """ICC of answers that keep the true level T with probability 1 − p and are uniform
    otherwise: between = (1 − p)² Var(T); within = E[Var(X | T)]."""
    mean = (1 - p) * truth + p * U_MEAN
    within = ((1 - p) * truth**2 + p * U_SQUARE - mean**2).mean()
    between = (1 - p) ** 2 * truth.var()
    return between / (between + within)


@pytest.mark.parametrize("p", [0.2, 0.5])
def test_a_noisy_respondent_comes_out_at_its_injected_level(personas, p):
    truth = asked(personas, RuleRespondent(), 1).set_index(["persona_id", "variant"])
    noisy = asked(personas, NoisyRespondent(p), 2)
    t = retest(noisy).set_index("target")
    n = int(t["records"].iloc[0])
    assert n == 802 and (t["samples"] == 2).all()
    agree = (1 - p) ** 2 + (1 - (1 - p) ** 2) / 5  # both kept, or equal by chance
    sd = np.sqrt(agree * (1 - agree) / n)
    assert np.abs(t.loc[list(Q_COLUMNS), "agree"] - agree).max() < 4 * sd
    for col in Q_COLUMNS:
        want = expected_icc(truth[col].to_numpy(float), p)
        assert abs(t.loc[col, "icc"] - want) < 0.08, (col, t.loc[col, "icc"], want)
    actions = t[t["kind"] == "action"]
    agree = (1 - p) ** 2 + (1 - (1 - p) ** 2) / len(ACTIONS)
    assert np.abs(actions["agree"] - agree).max() < 4 * np.sqrt(agree * (1 - agree) / n)
    assert actions["kappa"].between(0, agree).all()  # chance agreement taken out


def test_noise_fails_the_verdict_and_names_the_items(personas):
    t = audit(personas, asked(personas, NoisyRespondent(0.6), 2))
    v = t["verdict"].iloc[0]
    assert v["verdict"] == WEAK and f"test–retest ICC below {MIN_ICC:g}" in v["reasons"]
    assert "q_trust" in v["reasons"].split("test–retest")[1]
    assert "2 samples of 802 records" in v["retest"]


def test_the_rule_respondent_gives_identical_samples_and_perfect_agreement(personas):
    responses = asked(personas, RuleRespondent(), 3)
    assert (responses["sample"].value_counts() == 802).all()
    t = retest(responses, lambda one: build_profiles(one, personas, "A")).set_index("target")
    assert (t["agree"] == 1).all() and (t["kappa"].dropna() == 1).all()
    assert np.allclose(t["icc"].dropna(), 1)
    assert np.allclose(t["within_var"].dropna(), 0, rtol=0, atol=1e-12)
    v = audit(personas, responses, {"temperature": 0})["verdict"].iloc[0]
    assert v["verdict"] == USABLE and "100% identical" in v["retest"]
    # the aggregate of identical samples is the one-sample table
    one = asked(personas, RuleRespondent(), 1)
    pd.testing.assert_frame_equal(aggregate_samples(responses), one)


def test_differing_samples_at_temperature_zero_read_not_reproducible(personas):
    noisy = asked(personas, NoisyRespondent(0.05), 2)
    at = {temp: audit(personas, noisy, {"temperature": temp})["verdict"].iloc[0]
          for temp in (0, 0.7)}
    assert "server not reproducible" in at[0]["reasons"]
    assert "not reproducible" not in at[0.7]["reasons"]


def test_one_sample_says_test_retest_is_not_measured_and_how(personas):
    v = audit(personas, asked(personas, RuleRespondent(), 1))["verdict"].iloc[0]
    assert v["retest"].startswith("not measured") and "--samples 2" in v["retest"]
    assert v["verdict"] == USABLE


def test_fleiss_kappa_and_icc_on_known_tables():
    rng = np.random.default_rng(0)
    same = np.repeat(rng.integers(0, 4, (300, 1)), 3, axis=1)
    assert fleiss_kappa(same) == 1 and icc_oneway(same.astype(float))["icc"] == 1
    independent = rng.integers(0, 4, (4000, 3))
    assert abs(fleiss_kappa(independent)) < 0.03
    assert abs(icc_oneway(independent.astype(float))["icc"]) < 0.03
    # Fleiss (1971) by hand: 2 subjects × 2 raters, one agrees (a, a), one does not (a, b)
    assert fleiss_kappa(np.array([["a", "a"], ["a", "b"]])) == pytest.approx(
        (0.5 - (0.75**2 + 0.25**2)) / (1 - (0.75**2 + 0.25**2)))
    assert np.isnan(icc_oneway(np.ones((5, 2)))["icc"])


def test_aggregate_takes_the_median_item_and_the_modal_action():
    rows, _, _ = collect_responses(generate_personas(5, seed=3), NoisyRespondent(0.9),
                                   samples=4)
    agg = aggregate_samples(rows)
    assert len(agg) == 5 and (agg["sample"] == 0).all()
    for pid, g in rows.groupby("persona_id"):
        a = agg.set_index("persona_id").loc[pid]
        assert all(a[c] == g[c].median() for c in Q_COLUMNS)
        counts = g["action_1"].value_counts()
        tied = counts[counts == counts.max()].index
        first = next(x for x in g.sort_values("sample")["action_1"] if x in tied)
        assert a["action_1"] == first
    assert list(agg["persona_id"]) == list(rows.loc[rows["sample"] == 0, "persona_id"])


def test_the_report_shows_test_retest_or_says_it_was_not_measured(tmp_path):
    few = generate_personas(120, seed=4)
    for k, folder in ((2, tmp_path / "two"), (1, tmp_path / "one")):
        responses, _, _ = collect_responses(few, NoisyRespondent(0.3), matched_ids(few, 30),
                                            samples=k)
        folder.mkdir()
        few.to_parquet(folder / "personas.parquet")
        responses.to_parquet(folder / "responses.parquet")
        build_profiles(aggregate_samples(responses), few, "A").to_parquet(
            folder / "profiles.parquet")
    two, one = render_audit(tmp_path / "two"), render_audit(tmp_path / "one")
    assert "Within-persona variance" in two and "2 samples of 150 records" in two
    assert "test–retest not measured" in one and "--samples 2" in one


def test_a_second_respondent_with_samples_is_retested_with_its_base_mapping(personas):
    from popnavshift.analysis.audit_verdict import audit_tables

    first = asked(personas, RuleRespondent(), 1)
    pair = personas[personas["persona_id"].isin(matched_ids(personas, 202))]
    second, _, _ = collect_responses(pair, NoisyRespondent(0.2), matched_ids(personas, 202),
                                     samples=2)
    profiles = build_profiles(aggregate_samples(second), personas, "A")
    rs = [RespondentTables("first", first, build_profiles(first, personas, "A")),
          RespondentTables("second", second, profiles.assign(mapping="A~noisy-2"))]
    t = audit_tables(personas, rs, n_perm=N_PERM, n_boot=N_BOOT)
    v = t["audit_verdict"].set_index("respondent")
    assert v.loc["first", "retest"].startswith("not measured")
    assert v.loc["second", "retest"].startswith("2 samples of 404 records")
    g = t["audit_retest"]
    assert set(g["respondent"]) == {"second"} and (g["kind"] == "parameter").sum() == 7
    assert (t["audit_agreement"]["n"] == 404).all()  # the aggregate, one row per record
