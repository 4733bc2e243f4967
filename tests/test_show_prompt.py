"""show-prompt prints exactly the messages an LLM respondent was sent (loopback server)."""

from __future__ import annotations

import pandas as pd
import pytest

from forked_cli import run_cli
from llm_server import serve
from popnavshift.io import write_parquet
from popnavshift.pipeline import (
    PersonaSource,
    PopulationSettings,
    RespondentSpec,
    run_personas,
    run_responses,
)


def show(*args):
    return run_cli("show-prompt", *args)  # forked: the fixture's server thread has ended


@pytest.fixture(scope="module")
def asked(tmp_path_factory):
    """A 12-persona study probed by the openai respondent; the server's recorded bodies."""
    study = tmp_path_factory.mktemp("study")
    with serve() as server:
        settings = PopulationSettings(
            personas=PersonaSource(n=12), matched_n=2, respondent=RespondentSpec(
                name="openai",
                options={"base_url": server.openai_url, "model": "m", "api_key_env": None}),
        )
        run_personas(study, settings)
        run_responses(study, settings)
        bodies = [r.body["messages"] for r in server.requests]
    return study, bodies


def test_printed_messages_are_the_ones_sent(asked):
    study, bodies = asked
    responses = pd.read_parquet(study / "responses.parquet")
    pid = responses.loc[responses["variant"] == "deadline", "persona_id"].iloc[0]
    proc = show(pid, "--study", str(study))
    assert proc.returncode == 0, proc.stderr
    sections = proc.stdout.split("── system ──\n")[1:]
    assert len(sections) == 2  # baseline and deadline
    sent = {(m[0]["content"], m[1]["content"]) for m in bodies}
    for section, variant in zip(sections, ("baseline", "deadline"), strict=True):
        system, user = section.split("\n── user ──\n")
        user, answer = user.split("\n── recorded answer ──\n")
        assert (system, user) in sent, variant
        row = responses[(responses["persona_id"] == pid) & (responses["variant"] == variant)]
        assert answer.startswith(f"actions  P1: {row['action_1'].iloc[0]}, P2: ")  # recorded
    assert "Time pressure: their time pressure is Deadline" in sections[1]
    assert "respondent openai (m)" in proc.stdout


def test_one_variant_and_an_unknown_persona(asked):
    study, _ = asked
    pid = pd.read_parquet(study / "personas.parquet")["persona_id"].iloc[0]
    proc = show(pid, "--study", str(study), "--variant", "baseline")
    assert proc.returncode == 0 and proc.stdout.count("── user ──") == 1
    proc = show(pid[:-1] + "x", "--study", str(study))
    assert proc.returncode == 2 and "no persona" in proc.stderr and "did you mean" in proc.stderr


def test_markup_in_ids_and_values_is_printed_literally(tmp_path):
    run_personas(tmp_path, PopulationSettings(PersonaSource(n=3)))
    personas = pd.read_parquet(tmp_path / "personas.parquet")
    personas.loc[0, "persona_id"] = "[bold]odd[/bold]"
    write_parquet(personas, tmp_path / "personas.parquet")
    proc = show("[bold]odd[/bold]", "--study", str(tmp_path))
    assert proc.returncode == 0, proc.stderr
    assert "persona [bold]odd[/bold] · variant baseline · not asked in this study" in proc.stdout
    assert '{"actions": {"P1": ..., "P8": ...}' in proc.stdout
