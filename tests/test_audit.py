"""The respondent audit on answer tables of known persona sensitivity: the real rule
respondent on synthetic personas reads usable; a persona-blind and a constant respondent
read not persona-sensitive; injected noise shows at its level; each failure of a weak
respondent is named."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pandas as pd
import pytest

from popnavshift.analysis.audit import agreement, direction_outcome
from popnavshift.analysis.audit_verdict import (
    MIN_PERMUTATIONS,
    NOT_SENSITIVE,
    USABLE,
    WEAK,
    audit_respondent,
    audit_tables,
)
from popnavshift.errors import ConfigError
from popnavshift.personas.synthetic import generate_personas
from popnavshift.profiles.mappings import build_profiles
from popnavshift.read.respondent_tables import RespondentTables
from popnavshift.responses.probes import PROBE_IDS
from popnavshift.responses.respondent import Answer, ProbeRequest, Progress, Respondent
from popnavshift.responses.rule import RuleRespondent
from popnavshift.tables import BLOCK_ITEMS, Q_COLUMNS
from respondent_helpers import BlindRespondent, answers

N_PERM, N_BOOT = 399, 400


class ConstantRespondent(Respondent):
    """The same answer for every persona and variant."""

    name = "constant"

    def answer_all(self, requests: Sequence[ProbeRequest],
                   progress: Progress | None = None) -> list[Answer]:
        answer = {"actions": dict.fromkeys(PROBE_IDS, "slow"),
                  "block": dict.fromkeys(BLOCK_ITEMS, "medium")}
        return [Answer(r.persona_id, r.variant, answer=answer) for r in requests]


@pytest.fixture(scope="module")
def personas() -> pd.DataFrame:
    return generate_personas(600, seed=1)


@pytest.fixture(scope="module")
def rule(personas) -> pd.DataFrame:
    return answers(personas, RuleRespondent())


def audit(personas: pd.DataFrame, responses: pd.DataFrame, seed: int = 0
          ) -> dict[str, pd.DataFrame]:
    r = RespondentTables("first", responses, build_profiles(responses, personas, "A"))
    return audit_respondent(personas, r, rng_seed=seed, n_perm=N_PERM, n_boot=N_BOOT)


def verdict(t: dict[str, pd.DataFrame]) -> tuple[str, str]:
    v = t["verdict"].iloc[0]
    return v["verdict"], v["reasons"]


def test_the_rule_respondent_reads_usable(personas, rule):
    t = audit(personas, rule)
    assert verdict(t) == (USABLE, "")
    sens = t["sensitivity"].set_index("target")
    assert sens.loc[list(Q_COLUMNS), "sensitive"].all()
    assert sens.loc[list(Q_COLUMNS), "r2"].min() > sens.loc[list(Q_COLUMNS), "null_q95"].max()
    assert set(t["directions"]["outcome"]) == {"as expected"}
    urgency = t["manipulation"].set_index("target").loc["q_urgency"]
    assert urgency["ci_low"] > 0 and urgency["outcome"] == "as expected"


def test_a_persona_blind_respondent_reads_not_persona_sensitive(personas):
    t = audit(personas, answers(personas, BlindRespondent()))
    word, reasons = verdict(t)
    assert word == NOT_SENSITIVE and "artifacts" in reasons
    sens = t["sensitivity"]
    # speed alone follows the persona, through the mobility caps applied after mapping:
    # why the verdict asks the answers, not the parameters
    assert set(sens.loc[sens["sensitive"], "target"]) == {"speed_mps"}
    assert not t["spread"]["stuck"].any()  # varied answers: the shuffle, not the spread, decides
    assert t["verdict"]["answer_rows"].iloc[0] == 600


def test_a_constant_respondent_is_flagged(personas):
    t = audit(personas, answers(personas, ConstantRespondent()))
    word, reasons = verdict(t)
    assert word == NOT_SENSITIVE and "every answer is constant" in reasons
    assert t["spread"]["stuck"].all() and t["verdict"]["answer_rows"].iloc[0] == 1
    assert t["sensitivity"]["r2"].iloc[:15].isna().all()


def with_noise(responses: pd.DataFrame, share: float, seed: int = 0) -> pd.DataFrame:
    """``responses`` with a ``share`` of every item's answers replaced by a uniform level."""
    rng = np.random.default_rng(seed)
    noisy = responses.copy()
    for col in Q_COLUMNS:
        hit = rng.random(len(noisy)) < share
        noisy.loc[hit, col] = rng.integers(0, 5, hit.sum()) / 4
    return noisy


def test_injected_noise_shows_at_its_level(personas, rule):
    share = 0.5
    noisy = with_noise(rule, share)
    agree = agreement(rule, noisy, pd.DataFrame(), pd.DataFrame()).set_index("target")
    expected = 1 - share * 4 / 5  # a replaced answer keeps its level one time in five
    sd = np.sqrt(expected * (1 - expected) / len(rule))
    assert np.abs(agree.loc[list(Q_COLUMNS), "agree"] - expected).max() < 4 * sd
    assert (agree.loc[[c for c in agree.index if c.startswith("action_")], "kappa"] == 1).all()
    r2 = {s: audit(personas, with_noise(rule, s))["sensitivity"].set_index("target")
          .loc[list(Q_COLUMNS), "r2"] for s in (0.0, share, 1.0)}
    assert (r2[0.0] > r2[share]).all() and (r2[share] > r2[1.0]).all()
    word, reasons = verdict(audit(personas, with_noise(rule, 1.0)))
    assert word == WEAK  # the actions still follow the persona, the items no longer
    assert all(c in reasons.split("not persona-sensitive:")[1] for c in Q_COLUMNS)


def _no_deadline_effect(r: pd.DataFrame) -> pd.DataFrame:
    base = r[r["variant"] == "baseline"].set_index("persona_id")
    dead = r[r["variant"] == "deadline"].copy()
    cols = [c for c in r.columns if c.startswith(("q_", "action_"))]
    for c in cols:
        dead[c] = base.loc[dead["persona_id"], c].to_numpy()
    return pd.concat([base.reset_index(), dead], ignore_index=True)[r.columns]


@pytest.mark.parametrize("change, named", [
    (_no_deadline_effect, "the deadline moved urgency by +0.00"),
    (lambda r: r.assign(q_trust=1 - r["q_trust"]), "trust_level → q_trust"),
    (lambda r: r.assign(q_clearance=0.0), "stuck: q_clearance"),
])
def test_each_failure_of_a_weak_respondent_is_named(personas, rule, change, named):
    word, reasons = verdict(audit(personas, change(rule)))
    assert word == WEAK and named in reasons, reasons
    assert "nan" not in reasons  # a constant answer's ρ is said as such, not "+nan"


def test_a_reversed_direction_reads_reversed():
    assert direction_outcome(-1, 0.2, 0.4) == "reversed"
    assert direction_outcome(-1, -0.4, -0.2) == "as expected"
    assert direction_outcome(1, -0.1, 0.3) == "flat"
    assert direction_outcome(1, np.nan, 0.3) == "undefined"


def test_same_seed_same_audit_other_seed_other_null(personas, rule):
    a, b, c = audit(personas, rule, 0), audit(personas, rule, 0), audit(personas, rule, 1)
    pd.testing.assert_frame_equal(a["sensitivity"], b["sensitivity"])
    assert not np.allclose(a["sensitivity"]["null_mean"], c["sensitivity"]["null_mean"])


def test_two_respondents_are_audited_and_compared(personas, rule):
    second = answers(personas, RuleRespondent(seed=1, scale=0.8))
    second = second[second["persona_id"].isin(second.loc[second["variant"] == "deadline",
                                                         "persona_id"])]
    rs = [RespondentTables("first", rule, build_profiles(rule, personas, "A")),
          RespondentTables("second", second, build_profiles(second, personas, "A"))]
    t = audit_tables(personas, rs, n_perm=N_PERM, n_boot=N_BOOT)
    assert list(t["audit_verdict"]["respondent"]) == ["first", "second"]
    assert t["audit_verdict"]["personas"].tolist() == [600, 202]
    g = t["audit_agreement"].set_index("target")
    assert (g["n"] == 404).all()
    assert 0 < g.loc["q_trust", "rho"] < 1 and 0 < g.loc["speed_mps", "r"] < 1
    same = agreement(rule, rule, rs[0].profiles, rs[0].profiles).set_index("target")
    assert (same["agree"].dropna() == 1).all() and (same["kappa"].dropna() == 1).all()
    assert np.allclose(same["r"].dropna(), 1)


def test_too_few_permutations_to_reach_the_level_is_an_error(personas, rule):
    r = RespondentTables("first", rule, build_profiles(rule, personas, "A"))
    with pytest.raises(ConfigError, match=f"at least {MIN_PERMUTATIONS}"):
        audit_tables(personas, [r], n_perm=MIN_PERMUTATIONS - 1)
