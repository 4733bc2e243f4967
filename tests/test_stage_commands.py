"""The stage commands (`popnavshift personas`, `probe`, `profiles`, `populations`) run the
declared stages and stamp them as `run` does: a folder built stage by stage is taken up by
`run` for the stages whose settings match, and redone where they differ."""

from __future__ import annotations

import json
from dataclasses import replace

from forked_cli import run_cli
from popnavshift.design.specs import PersonaSource
from popnavshift.engine.runner import run_stages
from popnavshift.pipeline import PopulationSettings

SETTINGS = PopulationSettings(PersonaSource(n=120), seed=3, matched_n=40,
                              mappings=("A", "B"))


def _stage_by_stage(folder, seed: int = 3) -> None:
    out = str(folder)
    for args in (("personas", "--n", "120", "--seed", "3"),
                 ("probe", "--matched-n", "40", "--seed", str(seed)),
                 ("profiles", "--mapping", "A", "--mapping", "B"),
                 ("populations", "--matched-n", "40", "--seed", str(seed))):
        proc = run_cli(*args, "--out", out)
        assert proc.returncode == 0, proc.stderr


def test_run_takes_up_the_stages_built_with_its_settings(tmp_path):
    _stage_by_stage(tmp_path)
    tables = {p: (tmp_path / p).stat().st_mtime_ns for p in
              ("personas.parquet", "responses.parquet", "profiles.parquet", "populations.parquet")}
    assert run_stages(tmp_path, SETTINGS, show_progress=False) == ["episodes"]
    assert tables == {p: (tmp_path / p).stat().st_mtime_ns for p in tables}


def test_run_redoes_a_stage_built_with_other_settings(tmp_path):
    _stage_by_stage(tmp_path)
    other = replace(SETTINGS, mappings=("A", "B", "C"))
    assert run_stages(tmp_path, other, show_progress=False) == ["profiles", "populations",
                                                                 "episodes"]
    other = replace(other, matched_n=41)
    assert run_stages(tmp_path, other, show_progress=False) == ["responses", "profiles",
                                                                 "populations"]


def test_a_stage_run_with_another_seed_is_not_stamped(tmp_path):
    # the matched sample's seed is covered by the personas' stamp only
    _stage_by_stage(tmp_path, seed=4)
    stamps = json.loads((tmp_path / "stages.json").read_text())
    assert set(stamps) == {"personas"}  # and nothing after the unstamped responses
    assert run_stages(tmp_path, SETTINGS, show_progress=False) == ["responses", "profiles",
                                                                  "populations", "episodes"]


def test_personas_written_elsewhere_leave_the_stamps_alone(tmp_path):
    _stage_by_stage(tmp_path)
    before = (tmp_path / "stages.json").read_text()
    proc = run_cli("personas", "--n", "50", "--out", str(tmp_path / "other.parquet"))
    assert proc.returncode == 0, proc.stderr
    assert (tmp_path / "stages.json").read_text() == before
    assert run_stages(tmp_path, SETTINGS, show_progress=False) == ["episodes"]
