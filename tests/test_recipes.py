"""The recipes of docs/architecture.md ("Where to add"), each followed literally on a copy
of the package (tests/recipes.py) until what it adds reaches a study's report, and the
paper's study left as it was. The ranked-metric recipe is in test_analysis_ranked.py."""

from __future__ import annotations

import pytest

from popnavshift.paper import PAPER_CONTROLLERS, PAPER_POPULATIONS
from popnavshift.populations.build import is_known
from popnavshift.sim.controllers import CONTROLLERS
from recipes import package_with, run_with

EPISODES = {"scenes": ["sidewalk"], "widths": [1.8], "densities": [0.06],
            "robot_speeds": [1.0], "variants": [1]}


def study_script(folder, controllers, populations) -> str:
    """Run a one-part study of ``controllers`` × ``populations`` into ``folder``, report it,
    after checking that the paper's study is still the paper's."""
    study = {"name": "recipe", "seed": 0, "personas": {"source": "synthetic", "n": 300},
             "matched_n": 60, "parts": {"main": {"populations": populations,
                                                 "controllers": controllers,
                                                 "episodes": EPISODES}}}
    return f"""
from pathlib import Path
from popnavshift.engine.runner import run_study
from popnavshift.engine.study import load_study, study_from_dict
from popnavshift.evaluate.run import BASELINES
from popnavshift.paper import PAPER_CONTROLLERS, PAPER_POPULATIONS
from popnavshift.report import build_report
paper = load_study("paper").parts["main"]
assert paper.controllers == PAPER_CONTROLLERS == BASELINES == {PAPER_CONTROLLERS!r}
assert paper.populations == PAPER_POPULATIONS == {PAPER_POPULATIONS!r}
run_study(study_from_dict({study!r}), Path({str(folder)!r}), workers=1, show_progress=False)
build_report(Path({str(folder)!r}), n_boot=20, replays=0)
"""


def test_the_paper_runs_registered_controllers_and_known_populations():
    """The paper's design is data, checked against the registries it draws from."""
    assert [c for c in PAPER_CONTROLLERS if c not in CONTROLLERS.names()] == []
    assert [p for p in PAPER_POPULATIONS if not is_known(p)] == []


#: "A controller": a factory in sim/controllers/ plus one line of BUILTINS.
CREEP = '''"""A test built-in: the reactive controller keeping 0.5 m of clearance."""

from typing import Any

from .reactive import Reactive


class Creep(Reactive):
    name = "creep"

    def __init__(self, **params: Any) -> None:
        super().__init__(**{"buffer": 0.5, **params})
'''
CONTROLLER_RECIPE = {
    "sim/controllers/creep.py": [("", CREEP)],
    "sim/controllers/builtin.py": [("from . import early_yield, reactive",
                                    "from . import creep, early_yield, reactive"),
                                   ('    "robot_orca": RobotORCA,\n',
                                    '    "robot_orca": RobotORCA,\n    "creep": creep.Creep,\n')],
}


def test_the_recipe_for_a_controller(recipe_study):
    import pandas as pd

    cells = pd.read_csv(recipe_study / "report" / "tables" / "cell_metrics.csv")
    assert set(cells["controller"]) == {"reactive", "creep"}
    assert cells["robot_time"].notna().all()


#: "A population condition": a selector in _SELECTORS and its name in POPULATIONS.
POPULATION_RECIPE = {"populations/build.py": [
    ('    "low_robot_trust",\n    "matched_base",',
     '    "low_robot_trust",\n    "low_caution",\n    "matched_base",'),
    ('    "low_robot_trust": lambda b: b["q_trust"] <= LOW_TRUST_MAX,\n',
     '    "low_robot_trust": lambda b: b["q_trust"] <= LOW_TRUST_MAX,\n'
     '    "low_caution": lambda b: b["caution"] <= b["caution"].quantile(0.25),\n'),
]}


def test_the_recipe_for_a_population(recipe_study):
    import pandas as pd

    pops = pd.read_parquet(recipe_study / "populations.parquet")
    low, high = (pops.loc[pops["population"] == p, "persona_id"] for p in ("low_caution",
                                                                          "high_caution"))
    assert len(low) > 0 and not set(low) & set(high)  # the selector, not a copy
    cells = pd.read_csv(recipe_study / "report" / "tables" / "cell_metrics.csv")
    assert set(cells["population"]) == {"high_caution", "low_caution"}


def test_a_part_role_is_declared_named_or_read_from_its_content():
    from popnavshift.engine.study import study_from_dict
    from popnavshift.errors import ConfigError

    parts = {"grid": {}, "profile_sets": {"mapping": ["A", "B"]},
             "robots": {"backends": ["orca", "hl"]}, "blocks": {"mapping": ["A", "A~shuffle"]},
             "second": {"mapping": "A~rule-2"}, "sized": {"null_design": {"kind": "sized"}},
             "mine": {"role": "mapping", "mapping": "A"}}
    study = study_from_dict({"name": "t", "parts": {**parts, "mine": {"mapping": "A"}}})
    assert {n: study.role(n) for n in study.parts} == {
        "grid": "main", "profile_sets": "mapping", "robots": "backend", "blocks": "structure",
        "second": "respondent", "sized": "other", "mine": "other"}
    named = study_from_dict({"name": "t", "parts": {"main": {}, "backend": {"mapping": "B"}}})
    assert named.role("backend") == "backend"  # a role's name is its role, as in paper.yaml
    with pytest.raises(ConfigError, match="more than one part has role mapping"):
        study_from_dict({"name": "t", "parts": parts})
    with pytest.raises(ConfigError, match="role"):
        study_from_dict({"name": "t", "parts": {"main": {"role": "mapings"}}})


#: "A study part": any name; its role declared or read from its content.
@pytest.mark.slow
def test_a_renamed_part_keeps_its_report_section(tmp_path):
    from popnavshift.engine.runner import run_study
    from popnavshift.engine.study import study_from_dict
    from popnavshift.report import build_report

    parts = {"grid": {"populations": ["mixed", "high_caution"], "episodes": EPISODES},
             "profile_sets": {"populations": ["mixed", "high_caution"], "mapping": ["A", "B"],
                              "episodes": EPISODES}}
    study = study_from_dict({"name": "renamed", "seed": 0, "matched_n": 60, "parts": parts,
                             "personas": {"source": "synthetic", "n": 300}})
    run_study(study, tmp_path, workers=1, show_progress=False)
    build_report(tmp_path, n_boot=20, replays=0)
    import pandas as pd

    rates = pd.read_csv(tmp_path / "report" / "tables" / "robust_mapping.csv")
    assert set(rates["mapping"]) == {"A", "B"}


#: "A report section": a function returning a Section, and one line of SECTIONS.
SECTION_RECIPE = {
    "report/study_sections.py": [("", '''

def episodes_count_section(a: Analysis) -> Section:
    """How many cells the analysis holds (a test section)."""
    s = Section("episodes", "Cells analysed")
    s.blocks.append(para(f"{a.cells['cell'].nunique()} cells were analysed."))
    return s
''')],
    "report/page.py": [("    replays_section,\n",
                        "    episodes_count_section,\n    replays_section,\n"),
                       ('    ("replays", lambda p: replays_section(p.a)),\n',
                        '    ("episodes", lambda p: episodes_count_section(p.a)),\n'
                        '    ("replays", lambda p: replays_section(p.a)),\n')],
}


def test_the_recipe_for_a_report_section(recipe_study):
    html = (recipe_study / "report" / "index.html").read_text("utf-8")
    assert '<section id="episodes">' in html
    assert html.index('id="episodes"') < html.index('id="replays"')
    assert "cells were analysed." in html


@pytest.fixture(scope="module")
def recipe_study(tmp_path_factory):
    """One copy of the package with the controller, population and section recipes (they
    edit different modules, so each is still the whole of its own change), one study of
    the new controller × the new population, reported: ~25 s instead of three times it."""
    recipes = (CONTROLLER_RECIPE, POPULATION_RECIPE, SECTION_RECIPE)
    assert sum(map(len, recipes)) == len({m for r in recipes for m in r})  # disjoint edits
    tmp = tmp_path_factory.mktemp("recipes")
    root = package_with(tmp, {**CONTROLLER_RECIPE, **POPULATION_RECIPE, **SECTION_RECIPE})
    folder = tmp / "study"
    run_with(root, "from popnavshift.sim.check import check_controller\n"
                   "from popnavshift.sim.controllers import CONTROLLERS\n"
                   "check_controller(CONTROLLERS.make('creep'))\n"
                   + study_script(folder, ["reactive", "creep"], ["high_caution",
                                                                   "low_caution"]))
    return folder
