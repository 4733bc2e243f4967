"""The audit's power: each check's smallest detectable effect is what its test achieves
(simulated), the rule respondent is never called weak for lack of personas, and a
persona-blind respondent is caught wherever the audit has the power to."""

from __future__ import annotations

import numpy as np
import pytest

from popnavshift.analysis import audit_power as power
from popnavshift.analysis.audit import Target, persona_basis, sensitivity
from popnavshift.analysis.audit_retest import icc_oneway
from popnavshift.analysis.audit_verdict import (
    ALPHA,
    MIN_EXCESS_R2,
    MIN_ICC,
    NOT_SENSITIVE,
    UNDECIDED,
    USABLE,
    WEAK,
    audit_respondent,
)
from popnavshift.personas.synthetic import generate_personas
from popnavshift.personas.variants import matched_ids
from popnavshift.profiles.mappings import build_profiles
from popnavshift.read.respondent_tables import RespondentTables
from popnavshift.responses.collect import collect_responses
from popnavshift.responses.rule import RuleRespondent
from respondent_helpers import BlindRespondent

FAMILY = 16  # the answers' Bonferroni family


def audit(n: int, respondent, seed: int = 1) -> tuple[str, str]:
    personas = generate_personas(n, seed=seed)
    responses, _, _ = collect_responses(personas, respondent,
                                        matched_ids(personas, min(202, n // 3)))
    t = audit_respondent(personas, RespondentTables("first", responses, build_profiles(
        responses, personas, "A")), n_perm=399, n_boot=400)
    return t["verdict"]["verdict"].iloc[0], t["verdict"]["reasons"].iloc[0]


@pytest.mark.parametrize(("n", "rule_reads", "blind_reads"), [
    (20, UNDECIDED, UNDECIDED),
    (50, USABLE, UNDECIDED),
    (600, USABLE, NOT_SENSITIVE),
])
def test_the_rule_respondent_is_never_weak_for_lack_of_power_and_blindness_is_caught(
        n, rule_reads, blind_reads):
    word, reasons = audit(n, RuleRespondent())
    assert word == rule_reads and word != WEAK, reasons
    if word == UNDECIDED:
        assert reasons.startswith("needs ≈ ") and "personas" in reasons
    word, reasons = audit(n, BlindRespondent())
    assert word == blind_reads, reasons
    assert f"at {n} personas the test sees an R² of" in reasons


def detected(r2: float, basis: np.ndarray, reps: int, rng: np.random.Generator) -> float:
    """Share of ``reps`` targets of population R² ``r2`` on ``basis`` that the
    sensitivity test finds persona-sensitive (its criterion, the answers' family)."""
    hits = 0
    for _ in range(reps):
        signal = basis @ rng.normal(size=basis.shape[1])
        signal = signal / signal.std()
        y = np.sqrt(r2) * signal + np.sqrt(1 - r2) * rng.normal(size=len(signal))
        row = sensitivity([Target("y", "item", y[:, None])], basis, rng=rng,
                          n_perm=399).iloc[0]
        hits += row["p_value"] <= ALPHA / FAMILY and row["excess"] >= MIN_EXCESS_R2
    return hits / reps


def test_the_smallest_detectable_r2_is_what_the_permutation_test_detects():
    rng = np.random.default_rng(0)
    basis = persona_basis(generate_personas(120, seed=3))
    mde = power.sensitivity_mde(120, basis.shape[1], ALPHA / FAMILY, MIN_EXCESS_R2)
    assert 0.1 < mde < 0.5
    at = detected(mde, basis, 80, rng)
    assert 0.62 <= at <= 0.95, at  # 80 % in theory; ± 2.5 binomial sd of 80 draws
    assert detected(mde / 3, basis, 80, rng) < 0.4


def test_the_smallest_detectable_icc_is_what_test_retest_achieves():
    rng = np.random.default_rng(0)
    n, k = 40, 2
    mde = power.icc_mde(n, k, MIN_ICC)
    assert MIN_ICC < mde < 1

    def passes(icc: float) -> float:
        x = (np.sqrt(icc) * rng.normal(size=(400, n, 1))
             + np.sqrt(1 - icc) * rng.normal(size=(400, n, k)))
        return float(np.mean([icc_oneway(one)["icc"] >= MIN_ICC for one in x]))

    assert abs(passes(mde) - power.POWER) < 0.06
    assert passes(MIN_ICC) < 0.6


def test_the_direction_and_shift_thresholds_move_with_the_size():
    assert power.rho_mde(20) > power.USABLE["direction"] > power.rho_mde(200)
    assert power.rho_mde(power.rho_needs()) <= power.USABLE["direction"]
    assert power.rho_mde(power.rho_needs() - 1) > power.USABLE["direction"]
    assert power.shift_mde(0.0, 5, 0.125) == 0.125  # a deterministic shift needs no power
    needs = power.shift_needs(0.4, 0.125)
    assert power.shift_mde(0.4, needs, 0.125) <= power.USABLE["manipulation"]
    assert power.shift_mde(0.4, needs - 1, 0.125) > power.USABLE["manipulation"]
