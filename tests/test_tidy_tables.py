"""Tidy study tables: explicit seed_set / profile_set / run_id, and popnavshift.load by part."""

from __future__ import annotations

import re
from pathlib import Path

import pandas as pd
import pytest

import popnavshift
from forked_cli import run_cli
from popnavshift.errors import ConfigError, InputError, UnknownNameError
from popnavshift.populations.perturb import ProfileSet, with_profile_set_columns
from popnavshift.tables import PROFILE_SET_COLUMNS

EPISODES = ["sidewalk-w4.2-d0.06-s1.0-v1", "head_on-w4.2-d0.06-s1.0-v1"]
STUDY = f"""
name: tidy
seed: 0
personas: {{source: synthetic, n: 600}}
parts:
  main:
    populations: [mixed, matched_base, matched_deadline]
    controllers: [robot_orca]
    episodes: {{ids: {EPISODES}}}
  matched:
    populations: [matched_base, matched_deadline]
    controllers: [robot_orca]
    seeds: [1]
    episodes: {{ids: {EPISODES}}}
  structure:
    populations: [mixed]
    controllers: [robot_orca]
    mapping: [A, A~shuffle]
    episodes: {{ids: [{EPISODES[0]}]}}
"""
DOCS = Path(__file__).resolve().parents[1] / "docs" / "data.md"


@pytest.fixture(scope="module")
def study(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("tidy")
    (folder / "tidy.yaml").write_text(STUDY, "utf-8")
    proc = run_cli("run", str(folder / "tidy.yaml"), "--out", str(folder / "out"),
                   "--no-report", timeout=600)
    assert proc.returncode == 0, proc.stderr
    return folder / "out"


def test_explicit_seed_set_profile_set_and_run_id(study):
    runs = pd.read_parquet(study / "runs.parquet")
    peds = pd.read_parquet(study / "pedestrians.parquet")
    assert len(runs) == 22 and runs["run_id"].is_unique
    at = runs.set_index("episode")
    assert set(at.loc[[e + "@s1" for e in EPISODES], "seed_set"]) == {1}
    assert set(at.loc[EPISODES, "seed_set"]) == {0}
    assert runs.groupby("mapping")["profile_set"].unique().map(list).to_dict() == {
        "A": ["original"], "A~shuffle": ["shuffle"]
    }
    sets = runs[["mapping", *PROFILE_SET_COLUMNS]].drop_duplicates().set_index("mapping")
    assert sets.to_dict("index") == {
        "A": {"profile_set": "original", "profile_base": "A", "perturbation": "none",
              "perturbation_arg": ""},
        "A~shuffle": {"profile_set": "shuffle", "profile_base": "A", "perturbation": "shuffle",
                      "perturbation_arg": ""},
    }
    assert (peds.merge(runs, on="run_id")[[f"{c}_x" for c in PROFILE_SET_COLUMNS]].to_numpy()
            == peds.merge(runs, on="run_id")[[f"{c}_y" for c in PROFILE_SET_COLUMNS]].to_numpy()
            ).all()
    assert str(runs["seed_set"].dtype) == "int64" and str(peds["seed_set"].dtype) == "int64"
    joined = peds.merge(runs[["run_id", "episode", "controller"]], on="run_id")
    assert len(joined) == len(peds)
    assert (joined["episode_x"] == joined["episode_y"]).all()


def test_error_column_is_typed_string_even_when_empty(study):
    import pyarrow.parquet as pq

    assert pq.read_schema(study / "runs.parquet").field("error").type in (
        __import__("pyarrow").string(), __import__("pyarrow").large_string()
    )
    assert pd.read_parquet(study / "runs.parquet")["error"].isna().all()


def test_load_selects_every_run_a_part_plans(study):
    runs = pd.read_parquet(study / "runs.parquet")
    stored = runs[runs["part"] == "matched"]
    matched = popnavshift.load(study, part="matched")
    assert len(stored) == 8  # the seed-set-1 repeats only: seed set 0 is stored under main
    assert len(matched) == 16 and set(matched["part"]) == {"matched"}
    assert set(matched["seed_set"]) == {0, 1}
    assert set(matched["population"]) == {"matched_base", "matched_deadline"}
    assert len(popnavshift.load(study)) == 12  # main
    structure = popnavshift.load(study, part="structure")
    assert sorted(structure["profile_set"]) == ["original", "original", "shuffle", "shuffle"]
    peds = popnavshift.load(study, part="matched", table="pedestrians")
    assert set(peds["run_id"]) == set(matched["run_id"])
    assert len(popnavshift.load(study, part=None)) == 22


def test_load_errors_name_what_is_wrong(study, tmp_path):
    with pytest.raises(UnknownNameError, match="did you mean 'matched'"):
        popnavshift.load(study, part="matchd")
    with pytest.raises(ConfigError, match="table must be one of runs, pedestrians"):
        popnavshift.load(study, table="profiles")
    with pytest.raises(InputError, match="runs.parquet: not found"):
        popnavshift.load(tmp_path)


def test_profile_set_labels_are_read_once_into_typed_sets():
    labels = ("B", "A~reassign", "A~shuffle", "A~block-trust", "A~rule-2", "A~my-llm-2")
    sets = [ProfileSet.parse(m) for m in labels]
    assert [s.profile_set for s in sets] == [
        "original", "reassign", "shuffle", "block-trust", "second_respondent",
        "second_respondent"]
    assert [(s.base, s.perturbation, s.arg) for s in sets] == [
        ("B", "none", ""), ("A", "reassign", ""), ("A", "shuffle", ""), ("A", "block", "trust"),
        ("A", "second_respondent", "rule"), ("A", "second_respondent", "my-llm")]
    assert [s.label for s in sets] == list(labels)  # the label round-trips
    assert [s.is_structure for s in sets] == [False, True, True, True, False, False]
    for bad in ("A~shufle", "A~block-speed", "A~rule"):
        with pytest.raises(ConfigError, match=re.escape(repr(bad))):
            ProfileSet.parse(bad)
    with pytest.raises(ConfigError, match="argument"):
        ProfileSet("A", "block")


def test_rows_stored_before_the_profile_set_columns_get_them_from_their_label():
    old = pd.DataFrame({"mapping": ["A", "A~block-caution", "A~rule-2"], "x": [1, 2, 3]})
    filled = with_profile_set_columns(old)
    assert filled["perturbation"].tolist() == ["none", "block", "second_respondent"]
    assert filled["perturbation_arg"].tolist() == ["", "caution", "rule"]
    assert filled["profile_set"].tolist() == ["original", "block-caution", "second_respondent"]
    mixed = pd.concat([filled.iloc[:1], old.iloc[1:]], ignore_index=True)  # a resumed study
    assert with_profile_set_columns(mixed).equals(filled)
    assert with_profile_set_columns(filled) is filled  # complete tables are left alone


def test_the_documented_duckdb_recipe_runs(study):
    duckdb = pytest.importorskip("duckdb")
    sql = re.search(r"```sql\n(.*?)```", DOCS.read_text("utf-8"), re.S).group(1)
    queries = [q for q in sql.replace("'study/", f"'{study}/").split(";") if q.strip()]
    assert len(queries) == 2
    rates = duckdb.sql(queries[0]).df()
    assert set(rates["population"]) == {"mixed", "matched_base", "matched_deadline"}
    assert rates["runs"].sum() == 6  # main's robot runs, shared ones included
    assert len(duckdb.sql(queries[1]).df()) > 0
