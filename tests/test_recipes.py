"""The recipes of docs/architecture.md ("Where to add"), each followed literally on a copy
of the package (tests/recipes.py) until what it adds reaches a study's tables and report,
and the paper's study left as it was.

One copy holds every recipe's edits (tests/recipe_edits.py; each recipe edits its own
modules) and runs one study of them, reported (the ``recipe_study`` fixture). Its tests,
one per recipe: a controller (``creep``), a population condition (``low_caution``), a
report section, a paper finding (creep's delay against reactive's), a respondent
(``steady``), a mapping (``E``), a robustness profile set (``A~reverse``), a metric
(``robot_mean_speed``) and a paper figure (the tail-to-mean ratio). A study part is
followed by ``test_a_renamed_part_keeps_its_report_section``, the ranked cell metric in
test_analysis_ranked.py.
"""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

import recipe_edits as edits
from popnavshift.paper import PAPER_CONTROLLERS, PAPER_POPULATIONS
from popnavshift.populations.build import is_known
from popnavshift.sim.controllers import CONTROLLERS
from recipes import package_with, run_with

EPISODES = {"scenes": ["sidewalk"], "widths": [1.8], "densities": [0.06],
            "robot_speeds": [1.0], "variants": [1]}
CONTROLLERS_RUN, POPULATIONS_RUN = ["reactive", "creep"], ["high_caution", "low_caution"]
#: the new controller × the new population, asked of the new respondent, mapped by the new
#: mapping; a structure part beside it runs the new profile set
STUDY = {"name": "recipe", "seed": 0, "personas": {"source": "synthetic", "n": 300},
         "matched_n": 60, "respondent": {"name": "steady"},
         "parts": {"main": {"populations": POPULATIONS_RUN, "controllers": CONTROLLERS_RUN,
                            "episodes": EPISODES, "mapping": "E"},
                   "structure": {"populations": POPULATIONS_RUN,
                                 "controllers": CONTROLLERS_RUN, "episodes": EPISODES,
                                 "mapping": ["A", "A~reverse"]}}}


def study_script(folder, study) -> str:
    """Run ``study`` into ``folder`` and report it (with the data dictionary as
    ``data.md``), after checking that the paper's study is still the paper's."""
    return f"""
from pathlib import Path
from popnavshift.dictionary import data_markdown
from popnavshift.engine.runner import run_study
from popnavshift.design.study import load_study, study_from_dict
from popnavshift.evaluate.run import BASELINES
from popnavshift.paper import PAPER_CONTROLLERS, PAPER_POPULATIONS
from popnavshift.report import build_report
paper = load_study("paper").parts["main"]
assert paper.controllers == PAPER_CONTROLLERS == BASELINES == {PAPER_CONTROLLERS!r}
assert paper.populations == PAPER_POPULATIONS == {PAPER_POPULATIONS!r}
run_study(study_from_dict({study!r}), Path({str(folder)!r}), workers=1, show_progress=False)
build_report(Path({str(folder)!r}), n_boot=20, replays=0)
Path({str(folder)!r}, "data.md").write_text(data_markdown(), encoding="utf-8")
"""


@pytest.fixture(scope="module")
def recipe_study(tmp_path_factory):
    """One copy of the package with every recipe's edits (they edit different modules, so
    each is still the whole of its own change), one study of them, reported: one study
    instead of one per recipe."""
    modules = [m for recipe in edits.ALL.values() for m in recipe]
    assert len(modules) == len(set(modules))  # disjoint edits
    tmp = tmp_path_factory.mktemp("recipes")
    root = package_with(tmp, {m: e for recipe in edits.ALL.values() for m, e in recipe.items()})
    folder = tmp / "study"
    run_with(root, "from popnavshift.sim.check import check_controller\n"
                   "from popnavshift.sim.controllers import CONTROLLERS\n"
                   "check_controller(CONTROLLERS.make('creep'))\n"
                   + study_script(folder, STUDY))
    return folder


def tables(folder, name: str) -> pd.DataFrame:
    """A table the report wrote (report/tables/<name>.csv)."""
    return pd.read_csv(folder / "report" / "tables" / f"{name}.csv")


def section(folder, section_id: str) -> str:
    """The HTML of one section of the report."""
    html = (folder / "report" / "index.html").read_text("utf-8")
    start = html.index(f'<section id="{section_id}">')
    return html[start:html.index("</section>", start)]


def test_the_paper_runs_registered_controllers_and_known_populations():
    """The paper's design is data, checked against the registries it draws from."""
    assert [c for c in PAPER_CONTROLLERS if c not in CONTROLLERS.names()] == []
    assert [p for p in PAPER_POPULATIONS if not is_known(p)] == []


def test_the_recipe_for_a_controller(recipe_study):
    cells = tables(recipe_study, "cell_metrics")
    assert set(cells["controller"]) == {"reactive", "creep"}
    assert cells["robot_time"].notna().all()


def test_the_recipe_for_a_population(recipe_study):
    pops = pd.read_parquet(recipe_study / "populations.parquet")
    low, high = (pops.loc[pops["population"] == p, "persona_id"] for p in ("low_caution",
                                                                          "high_caution"))
    assert len(low) > 0 and not set(low) & set(high)  # the selector, not a copy
    assert set(tables(recipe_study, "cell_metrics")["population"]) == set(POPULATIONS_RUN)


def test_a_part_role_is_declared_named_or_read_from_its_content():
    from popnavshift.design.study import study_from_dict
    from popnavshift.errors import ConfigError

    parts = {"grid": {"role": "main"}, "profile_sets": {"mapping": ["A", "B"]},
             "robots": {"backends": ["orca", "hl"]}, "blocks": {"mapping": ["A", "A~shuffle"]},
             "second": {"mapping": "A~rule-2"}, "sized": {"null_design": {"kind": "sized"}},
             "mine": {"role": "mapping", "mapping": "A"}}
    study = study_from_dict({"name": "t", "parts": {**parts, "mine": {"mapping": "A"}}})
    assert {n: study.role(n) for n in study.parts} == {
        "grid": "main", "profile_sets": "mapping", "robots": "backend", "blocks": "structure",
        "second": "respondent", "sized": "other", "mine": "other"}
    named = study_from_dict({"name": "t", "parts": {"main": {}, "backend": {"mapping": "B"}}})
    assert named.role("backend") == "backend"  # a role's name is its role, as in paper.yaml
    assert named.main_part()[0] == "main"
    first = study_from_dict({"name": "t", "parts": {"grid": {}, "other": {"mapping": "B"}}})
    assert first.role("grid") == "other" and first.main_part() is None  # never by position
    with pytest.raises(ConfigError, match="more than one part has role mapping"):
        study_from_dict({"name": "t", "parts": parts})
    with pytest.raises(ConfigError, match="role"):
        study_from_dict({"name": "t", "parts": {"main": {"role": "mapings"}}})


#: "A study part": any name; its role declared or read from its content.
@pytest.mark.slow
def test_a_renamed_part_keeps_its_report_section(tmp_path):
    from popnavshift.design.study import study_from_dict
    from popnavshift.engine.runner import run_study
    from popnavshift.report import build_report

    parts = {"grid": {"populations": ["mixed", "high_caution"], "episodes": EPISODES,
                      "role": "main"},  # a main part is declared or named, never first
             "profile_sets": {"populations": ["mixed", "high_caution"], "mapping": ["A", "B"],
                              "episodes": EPISODES}}
    study = study_from_dict({"name": "renamed", "seed": 0, "matched_n": 60, "parts": parts,
                             "personas": {"source": "synthetic", "n": 300}})
    run_study(study, tmp_path, workers=1, show_progress=False)
    build_report(tmp_path, n_boot=20, replays=0)
    assert set(tables(tmp_path, "robust_mapping")["mapping"]) == {"A", "B"}


def test_the_recipe_for_a_report_section(recipe_study):
    html = (recipe_study / "report" / "index.html").read_text("utf-8")
    assert '<section id="episodes">' in html
    assert html.index('id="episodes"') < html.index('id="replays"')
    assert "cells were analysed." in html




def test_the_recipe_for_a_paper_finding(recipe_study):
    outcomes = tables(recipe_study, "controller_outcomes").set_index("controller")["mean_delay"]
    gap = outcomes["reactive"] - outcomes["creep"]  # the claim's statistic, from Table II
    found = tables(recipe_study, "findings").set_index("key")
    assert found.loc["creep_delay", "statement"] == "creep has a lower mean delay than reactive"
    assert bool(found.loc["creep_delay", "holds"]) == (gap > 0)
    assert json.loads(found.loc["creep_delay", "numbers"]) == pytest.approx(outcomes.to_dict())
    judged = tables(recipe_study, "evidence_findings").set_index("finding").loc["creep_delay"]
    assert judged["statistic"] == "reactive − creep mean delay [s]"
    assert judged["estimate"] == pytest.approx(gap)
    assert bool(judged["holds"]) == (gap > 0)
    html = section(recipe_study, "summary")
    assert "Creep has a lower mean delay than Reactive" in html
    assert f"reactive − creep mean delay [s] = {gap:.2f}" in html


def test_the_recipe_for_a_respondent(recipe_study):
    answers = pd.read_parquet(recipe_study / "responses.parquet")
    assert set(answers["respondent"]) == {"steady"} and set(answers["model"]) == {"steady-v1"}
    assert set(answers["action_8"]) == {"stop"}  # its answers, not the rule respondent's
    assert set(answers["action_1"]) != {"stop"}
    verdict = tables(recipe_study, "audit_verdict")
    assert verdict[["respondent", "name", "model"]].values.tolist() == [
        ["first", "steady", "steady-v1"]]
    assert "stuck: action_8" in verdict["reasons"].iloc[0]  # the audit read its answers
    assert "(steady, steady-v1)" in section(recipe_study, "audit")


def test_the_recipe_for_a_mapping(recipe_study):
    profiles = pd.read_parquet(recipe_study / "profiles.parquet")
    e = profiles[profiles["mapping"] == "E"].merge(
        pd.read_parquet(recipe_study / "responses.parquet"), on=["persona_id", "variant"])
    assert len(e) > 0
    np.testing.assert_allclose(e["caution"], e["q_clearance"])  # the function's caution
    assert set(pd.read_parquet(recipe_study / "runs.parquet", columns=["part", "mapping"])
               .drop_duplicates().itertuples(index=False, name=None)) >= {("main", "E")}
    assert set(tables(recipe_study, "cell_metrics")["mapping"]) == {"E"}


def test_the_recipe_for_a_robustness_profile_set(recipe_study):
    pops = pd.read_parquet(recipe_study / "populations.parquet")
    a, rev = (pops[pops["mapping"] == m].sort_values(["population", "member"])
              for m in ("A", "A~reverse"))
    assert len(rev) == len(a) > 0
    for name, members in a.groupby("population"):
        flipped = rev[rev["population"] == name]["speed_mps"].to_numpy()
        np.testing.assert_array_equal(flipped, members["speed_mps"].to_numpy()[::-1])
    runs = pd.read_parquet(recipe_study / "runs.parquet")
    sets = runs[runs["mapping"] == "A~reverse"]
    assert len(sets) > 0
    assert set(map(tuple, sets[["profile_set", "profile_base", "perturbation",
                                "perturbation_arg"]].to_numpy().tolist())) == {
        ("reverse", "A", "reverse", "")}
    robust = tables(recipe_study, "robust_structure")
    assert set(robust["mapping"]) == {"A", "A~reverse"}
    assert set(robust.loc[robust["mapping"] == "A~reverse", "perturbation"]) == {"reverse"}
    assert "A~reverse" in section(recipe_study, "structure")


def test_the_recipe_for_a_metric(recipe_study):
    runs = pd.read_parquet(recipe_study / "runs.parquet")
    robot = runs["controller"] != "none"
    assert robot.any() and runs.loc[~robot, "robot_mean_speed"].isna().all()
    np.testing.assert_allclose(runs.loc[robot, "robot_mean_speed"],
                               runs.loc[robot, "robot_path_length"]
                               / runs.loc[robot, "outcome_time"])
    assert "| `robot_mean_speed` | float64 | m/s |" in (recipe_study / "data.md").read_text("utf-8")


def test_the_recipe_for_a_paper_figure(recipe_study):
    statement = "Worst-decile delay is about 3× the mean delay"
    assert statement in set(tables(recipe_study, "findings")["statement"])
    assert statement in section(recipe_study, "summary")
    assert "about 4×" not in section(recipe_study, "summary")


def test_the_stored_study_keeps_its_parts_in_order(tmp_path):
    """The manifest's JSON sorts its keys; the part order it stores keeps the order of the
    study file (a run several parts plan belongs to the first), the main part is the one
    declared whatever the order, and a manifest of an earlier version of the study is
    written again by the next run."""
    import json

    from popnavshift.design.study import study_from_dict
    from popnavshift.engine.runner import _manifest_describes
    from popnavshift.read.folder import stored_study

    study = study_from_dict({"name": "t", "parts": {"zgrid": {"role": "main"}, "a_null": {
        "null_design": {"kind": "swap", "replicates": 2}}}})
    stored = json.loads(json.dumps(study.model_dump(mode="json"), sort_keys=True))
    assert list(stored["parts"]) == ["a_null", "zgrid"]
    manifest = {"study_config": stored, "part_order": list(study.parts)}
    assert list(stored_study(manifest).parts) == ["zgrid", "a_null"]
    assert list(stored_study({"study_config": stored}).parts) == ["a_null", "zgrid"]
    for order in (manifest, {"study_config": stored}):
        assert stored_study(order).main_part()[0] == "zgrid"
    (tmp_path / "manifest.json").write_text(json.dumps(
        {**manifest, "config_hash": study.config_hash()}))
    assert _manifest_describes(tmp_path, study)
    renamed = study_from_dict({"name": "t", "parts": {"grid": {"role": "main"}, "a_null": {
        "null_design": {"kind": "swap", "replicates": 2}}}})
    assert not _manifest_describes(tmp_path, renamed)
