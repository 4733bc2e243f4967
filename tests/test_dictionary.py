"""The data dictionary (docs/data.md) is generated from the table specs and complete."""

from __future__ import annotations

from pathlib import Path

import pytest

from forked_cli import run_cli
from popnavshift.design.specs import PersonaSource
from popnavshift.dictionary import STUDY_TABLES, data_markdown
from popnavshift.pipeline import PopulationSettings, run_personas
from popnavshift.tables import SPECS

DOCS = Path(__file__).resolve().parents[1] / "docs" / "data.md"


def describe(*args):
    return run_cli("describe", *args)  # forked: a real process without the start-up


def test_docs_data_md_is_the_generated_dictionary():
    assert DOCS.read_text("utf-8") == data_markdown(), (
        "docs/data.md is stale: popnavshift describe --markdown > docs/data.md"
    )


def test_cli_markdown_is_the_generated_text():
    proc = describe("--markdown")
    assert proc.returncode == 0 and proc.stdout == data_markdown()


@pytest.mark.parametrize("stage", STUDY_TABLES)
def test_every_column_is_explained(stage):
    spec = SPECS[stage]
    assert spec.doc.startswith("one ") and spec.file == f"{stage}.parquet"
    for c in spec.columns:
        assert c.doc, f"{stage}.{c.name} has no meaning"
        assert bool(c.missing) == c.nullable, f"{stage}.{c.name}: NaN meaning vs nullable"
        if c.refers:
            table, _, column = c.refers.partition(".")
            assert column in SPECS[table].names, c.refers


def test_every_declared_table_is_in_the_dictionary():
    assert set(STUDY_TABLES) == set(SPECS)


def test_describe_a_study_folder_and_one_table(tmp_path):
    run_personas(tmp_path, PopulationSettings(PersonaSource(n=5)))
    proc = describe(str(tmp_path))
    assert proc.returncode == 0, proc.stderr
    assert "personas.parquet · 5 rows" in proc.stdout and "runs.parquet" not in proc.stdout
    assert "not declared" not in proc.stdout
    proc = describe(str(tmp_path), "personas", "--markdown")
    assert proc.stdout.startswith("## `personas.parquet`")
    proc = describe(str(tmp_path), "runz")
    assert proc.returncode == 2 and "did you mean 'runs'" in proc.stderr
    proc = describe(str(tmp_path), "runs")
    assert proc.returncode == 2 and "holds none of the table(s) runs" in proc.stderr


def test_profile_columns_carry_meaning_and_unit_and_the_symbols_are_gone():
    from popnavshift.tables import PARAM_DOCS, PARAMS, Z_COLUMNS

    symbols = {"v", "d", "a", "y", "tau", "L", "g"}
    old = symbols | {f"z_{s}" for s in symbols}
    for stage, spec in SPECS.items():
        assert not old & set(spec.names), stage
    assert list(PARAM_DOCS) == list(PARAMS) == list(Z_COLUMNS)
    units = {p: PARAM_DOCS[p][0] for p in PARAMS}
    assert units["speed_mps"] == "m/s" and units["reaction_delay_s"] == "s"
    assert units["clearance_m"] == units["detour_distance_m"] == "m"
