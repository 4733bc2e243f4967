"""A run is identified by its own inputs: extending a study simulates exactly the new runs,
`plan` counts them beforehand, and a folder compacted before the identity migrates."""

from __future__ import annotations

import json
import shutil

import pandas as pd
import pyarrow.parquet as pq
import pytest
import yaml

from engine_helpers import TINY, tables
from popnavshift.design.plan import count_runs
from popnavshift.design.study import study_from_dict
from popnavshift.engine.pending import pending_runs
from popnavshift.engine.runner import run_study
from popnavshift.engine.stages import legacy_batch_inputs
from popnavshift.engine.stamps import code_stamps
from popnavshift.episodes.specs import all_episodes
from popnavshift.read.checks import read_stamps
from popnavshift.tables import ROBOT_METRICS, RUN_KEY

EPISODES = {"scenes": ["sidewalk", "head_on"], "widths": [1.8], "densities": [0.06],
            "robot_speeds": [1.0], "variants": [1]}


def with_nulls(swaps: int, sized: int) -> dict:
    """The tiny study with a swap null and a size-matched null of ``swaps`` and ``sized``
    replicates on two episodes, one controller."""
    study = yaml.safe_load(yaml.safe_dump(TINY))
    study["parts"]["swap_null"] = {"null_design": {"kind": "swap", "replicates": swaps},
                                   "controllers": ["robot_orca"], "episodes": EPISODES}
    study["parts"]["sized_null"] = {"null_design": {"kind": "sized", "replicates": sized},
                                    "populations": ["mixed", "matched_base"],
                                    "controllers": ["robot_orca"], "episodes": EPISODES}
    return study


@pytest.fixture(scope="module")
def small_nulls(tmp_path_factory):
    folder = tmp_path_factory.mktemp("nulls")
    run_study(study_from_dict(with_nulls(1, 1)), folder, workers=1, show_progress=False)
    return folder


def keyed(df: pd.DataFrame) -> pd.DataFrame:
    return df.set_index(list(RUN_KEY)).sort_index()


def test_adding_null_replicates_simulates_exactly_the_new_runs(small_nulls, tmp_path):
    folder = tmp_path / "extended"
    shutil.copytree(small_nulls, folder)
    before_runs, before_peds = tables(folder)
    bigger = study_from_dict(with_nulls(3, 2))
    pending = pending_runs(bigger, folder)  # `plan`'s count, before anything runs
    report = run_study(bigger, folder, workers=1, show_progress=False)
    eps = all_episodes(0)
    new = (count_runs(bigger, eps)["distinct"]["total"]
           - count_runs(study_from_dict(with_nulls(1, 1)), eps)["distinct"]["total"])
    assert new > 0 and report.executed == pending.execute == new
    assert report.reused == pending.kept == len(before_runs)
    assert report.stages_run == ["populations"]  # a null design is that stage's setting
    runs, peds = tables(folder)
    # every earlier run is unchanged, row for row, pedestrians included
    old = keyed(runs).loc[keyed(before_runs).index].drop(columns="part")
    pd.testing.assert_frame_equal(old, keyed(before_runs).drop(columns="part"))
    peds_old = peds.merge(before_runs[list(RUN_KEY)], on=list(RUN_KEY))
    pd.testing.assert_frame_equal(
        peds_old.sort_values([*RUN_KEY, "slot"]).reset_index(drop=True).drop(columns="part"),
        before_peds.sort_values([*RUN_KEY, "slot"]).reset_index(drop=True).drop(columns="part"))
    # and the extended folder is the extended study run from scratch
    fresh = tmp_path / "fresh"
    run_study(bigger, fresh, workers=1, show_progress=False)
    for ours, theirs in zip(tables(folder), tables(fresh), strict=True):
        pd.testing.assert_frame_equal(ours, theirs)
    # removing them again simulates nothing
    again = run_study(study_from_dict(with_nulls(1, 1)), folder, workers=1, show_progress=False)
    assert again.executed == 0
    pd.testing.assert_frame_equal(tables(folder)[0], before_runs)


def test_equal_run_inputs_are_the_same_simulation(small_nulls):
    runs = pd.read_parquet(small_nulls / "runs.parquet")
    metrics = ["outcome", "steps", *(c.name for c in ROBOT_METRICS)]
    shared = runs[runs.duplicated("run_inputs", keep=False)]
    assert len(shared), "a swap arm that flips no pedestrian repeats a matched run"
    for _, group in shared.groupby("run_inputs"):
        assert group["population"].nunique() > 1  # different populations, same slots
        first = group[metrics].iloc[[0] * len(group)].reset_index(drop=True)
        pd.testing.assert_frame_equal(group[metrics].reset_index(drop=True), first)
    # and different inputs are different runs (the digest covers each key's own slots)
    assert runs.groupby(list(RUN_KEY))["run_inputs"].nunique().eq(1).all()


def _as_legacy(folder, code_edit: str = "") -> None:
    """Make ``folder`` look compacted before runs carried their inputs: no run_inputs
    column, and the old record (the populations' and episodes' stamp, code stamps)."""
    runs = pq.read_table(folder / "runs.parquet")
    pq.write_table(runs.drop(["run_inputs"]), folder / "runs.parquet")
    stamps = read_stamps(folder)
    controllers = pd.read_parquet(folder / "runs.parquet", columns=["controller"])
    code = code_stamps(controllers["controller"])
    code = {c: s + (code_edit if c == "reactive" else "") for c, s in code.items()}
    stamps["runs"] = {"inputs": legacy_batch_inputs(stamps), "code": code}
    (folder / "stages.json").write_text(json.dumps(stamps))


def test_a_folder_compacted_before_run_inputs_migrates_without_simulating(
        small_nulls, tmp_path):
    folder = tmp_path / "legacy"
    shutil.copytree(small_nulls, folder)
    _as_legacy(folder)
    study = study_from_dict(with_nulls(1, 1))
    assert pending_runs(study, folder).execute == 0
    report = run_study(study, folder, workers=1, show_progress=False)
    assert report.executed == 0 and report.compacted  # written once more, with the column
    for ours, ref in zip(tables(folder), tables(small_nulls), strict=True):
        pd.testing.assert_frame_equal(ours, ref)
    assert read_stamps(folder)["runs"] == {"run_inputs": 1}


def test_a_legacy_folder_reruns_what_its_record_cannot_vouch_for(small_nulls, tmp_path):
    folder = tmp_path / "legacy-edited"
    shutil.copytree(small_nulls, folder)
    _as_legacy(folder, code_edit="-older")  # reactive's runs were made with other code
    study = study_from_dict(with_nulls(1, 1))
    pending = pending_runs(study, folder)
    report = run_study(study, folder, workers=1, show_progress=False)
    reactive = int((tables(small_nulls)[0]["controller"] == "reactive").sum())
    assert report.executed == pending.execute == reactive > 0  # those runs only
    for ours, ref in zip(tables(folder), tables(small_nulls), strict=True):
        pd.testing.assert_frame_equal(ours, ref)
