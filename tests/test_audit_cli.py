"""The respondent audit as a user meets it: `popnavshift audit` on a study folder (real
processes, forked by :mod:`forked_cli`; exit codes, one-line errors) and the report's
banner and flag."""

from __future__ import annotations

from pathlib import Path

import pytest

from cli_helpers import assert_one_line_error
from forked_cli import run_cli
from popnavshift.analysis.audit_verdict import MIN_PERMUTATIONS
from popnavshift.personas.synthetic import generate_personas
from popnavshift.profiles.mappings import build_profiles
from popnavshift.responses.respondent import Respondent
from popnavshift.responses.rule import RuleRespondent
from respondent_helpers import BlindRespondent, answers, render_audit


def write_folder(folder: Path, respondent: Respondent) -> Path:
    """A study folder after the probe and profile stages (no runs)."""
    personas = generate_personas(300, seed=2)
    responses = answers(personas, respondent)
    folder.mkdir(parents=True, exist_ok=True)
    personas.to_parquet(folder / "personas.parquet")
    responses.to_parquet(folder / "responses.parquet")
    build_profiles(responses, personas, "A").to_parquet(folder / "profiles.parquet")
    return folder


@pytest.fixture(scope="module")
def rule_folder(tmp_path_factory) -> Path:
    return write_folder(tmp_path_factory.mktemp("rule"), RuleRespondent())


@pytest.fixture(scope="module")
def blind_folder(tmp_path_factory) -> Path:
    return write_folder(tmp_path_factory.mktemp("blind"), BlindRespondent())


def test_audit_prints_the_verdict_of_the_rule_respondent(rule_folder):
    proc = run_cli("audit", str(rule_folder), "--strict")
    assert proc.returncode == 0, proc.stderr
    last = proc.stdout.strip().splitlines()[-1]  # its tables are its output: on stdout
    assert last.startswith("first respondent rule") and last.endswith("usable"), last
    assert "expected directions" in proc.stdout and "matched intervention" in proc.stdout
    assert "smallest detectable" in proc.stdout and "nan" not in proc.stdout
    assert "expected directions" not in proc.stderr


def test_strict_audit_of_a_persona_blind_respondent_exits_1(blind_folder):
    proc = run_cli("audit", str(blind_folder), "--strict")
    assert proc.returncode == 1, proc.stderr
    assert "not persona-sensitive" in proc.stdout and "artifacts" in proc.stdout
    assert run_cli("audit", str(blind_folder)).returncode == 0  # without --strict: a report


@pytest.mark.parametrize("args, needles", [
    (["audit", "{tmp}/nowhere"], ["nowhere", "does not exist"]),
    (["audit", "{tmp}"], ["personas.parquet not found"]),
    (["audit", "{rule}", "--permutations", str(MIN_PERMUTATIONS - 1)],
     [f"--permutations {MIN_PERMUTATIONS - 1}", f"at least {MIN_PERMUTATIONS}"]),
])
def test_audit_mistakes_are_one_red_line_and_exit_2(tmp_path, rule_folder, args, needles):
    args = [a.format(tmp=tmp_path, rule=rule_folder) for a in args]
    assert_one_line_error(run_cli(*args), *needles)


def test_help_states_the_fewest_permutations():
    proc = run_cli("audit", "--help")
    assert proc.returncode == 0 and str(MIN_PERMUTATIONS) in proc.stdout
    assert "not persona-sensitive" in " ".join(proc.stdout.split())  # reflowed at the width


def test_the_report_says_a_blind_respondent_is_not_usable_before_any_rate(blind_folder):
    page = render_audit(blind_folder)
    banner = page.index('id="respondent-audit"')
    assert banner < page.index('id="answer"') < page.index("Read the rates below with care")
    assert page.index("Read the rates below with care") < page.index('id="ranks"')
    assert "NOT PERSONA-SENSITIVE" in page[banner: page.index("</p>", banner)]
    assert page.index('id="audit"') > 0


def test_the_report_of_a_usable_respondent_carries_no_flag(rule_folder):
    page = render_audit(rule_folder)
    banner = page.index('id="respondent-audit"')
    assert "USABLE" in page[banner: page.index("</p>", banner)]
    assert "Read the rates below with care" not in page
