"""The edits of the recipes of docs/architecture.md ("Where to add") that
tests/test_recipes.py follows, each the whole of its recipe and nothing more: module path
under popnavshift/ → (anchor, text) for :func:`recipes.package_with`. Each recipe edits its
own modules, so all of them fit in one copy of the package (checked by the test).
"""

from __future__ import annotations

from recipes import Edits

#: "A controller": a factory in sim/controllers/ plus one line of BUILTINS.
CREEP = '''"""A test built-in: the reactive controller keeping 0.5 m of clearance."""

from typing import Any

from .reactive import Reactive


class Creep(Reactive):
    name = "creep"

    def __init__(self, **params: Any) -> None:
        super().__init__(**{"buffer": 0.5, **params})
'''
CONTROLLER: Edits = {
    "sim/controllers/creep.py": [("", CREEP)],
    "sim/controllers/builtin.py": [
        ('    "robot_orca": "popnavshift.sim.controllers.robot_orca:RobotORCA",\n',
         '    "robot_orca": "popnavshift.sim.controllers.robot_orca:RobotORCA",\n'
         '    "creep": "popnavshift.sim.controllers.creep:Creep",\n')],
}

#: "A population condition": a selector in _SELECTORS and its name in POPULATIONS.
POPULATION: Edits = {"populations/build.py": [
    ('    "low_robot_trust",\n    "matched_base",',
     '    "low_robot_trust",\n    "low_caution",\n    "matched_base",'),
    ('    "low_robot_trust": lambda b: b["q_trust"] <= LOW_TRUST_MAX,\n',
     '    "low_robot_trust": lambda b: b["q_trust"] <= LOW_TRUST_MAX,\n'
     '    "low_caution": lambda b: b["caution"] <= b["caution"].quantile(0.25),\n'),
]}

#: "A report section": a SectionSpec (id, title, content) and one line of SECTIONS.
SECTION: Edits = {
    "report/study_sections.py": [("", '''

def _episodes_count(p: Page, _: pd.DataFrame) -> list[Block]:
    """How many cells the analysis holds (a test section)."""
    return [para(f"{p.a.cells['cell'].nunique()} cells were analysed.")]


EPISODES_COUNT = SectionSpec("episodes", "Cells analysed", _episodes_count)
''')],
    "report/page.py": [
        ("from .study_sections import CHECKS, MANIFEST, POPULATIONS, REPLAYS\n",
         "from .study_sections import CHECKS, EPISODES_COUNT, MANIFEST, POPULATIONS, REPLAYS\n"),
        ("    REPLAYS,\n    MANIFEST,\n)", "    EPISODES_COUNT,\n    REPLAYS,\n    MANIFEST,\n)")],
}

#: "A paper finding": one Claim in CLAIMS (key, statement, needs, missing, check) with
#: its Interval (a statistic of finding_stats.py and its band).
FINDING: Edits = {"analysis/findings.py": [(")\nCLAIM_BY_KEY", '''\
    Claim("creep_delay", "creep has a lower mean delay than reactive",
          _needs("delays", "controller:creep", "controller:reactive"),
          "the creep finding",
          lambda i: controller_extreme(i.outcomes, "mean_delay", "creep", highest=False,
                                       among=("reactive", "creep")),
          Interval("reactive − creep mean delay [s]",
                   lambda c, v, _: fs.extreme_gap(c, v["mean_delay"], "creep", highest=False,
                                                  among=("reactive", "creep")),
                   _band(0, np.inf))),
)
CLAIM_BY_KEY''')]}

#: "A respondent": a Respondent subclass, registered in responses/respondent.py.
STEADY = '''"""A test respondent: the rule respondent's answers, but it always stops at probe P8."""

from collections.abc import Sequence

from .respondent import Answer, ProbeRequest, Progress, Respondent
from .rule import RuleRespondent


class Steady(Respondent):
    name = "steady"

    def __init__(self, seed: int = 0) -> None:
        self.rule = RuleRespondent(seed)

    @property
    def model(self) -> str:
        return "steady-v1"

    def answer_all(self, requests: Sequence[ProbeRequest],
                   progress: Progress | None = None) -> list[Answer]:
        answers = self.rule.answer_all(requests, progress)
        for a in answers:
            a.answer["actions"]["P8"] = "stop"
        return answers
'''
RESPONDENT: Edits = {
    "responses/steady.py": [("", STEADY)],
    "responses/respondent.py": [
        ("", 'RESPONDENTS.register("steady", "popnavshift.responses.steady:Steady")\n')],
}

#: "A mapping": @MAPPINGS.register("E") on a function in profiles/mappings.py.
MAPPING: Edits = {"profiles/mappings.py": [("", '''

@MAPPINGS.register("E")
def mapping_e(q: Q) -> MappingResult:
    """A test mapping: Mapping A's roles with clearance alone as the caution score."""
    c = q["clearance"]
    return _roles(q, c), c
''')]}

#: "A robustness profile set": one STRUCTURE entry in populations/perturb.py and its
#: builder (here at the populations stage, from Mapping A's populations).
PROFILE_SET: Edits = {"populations/perturb.py": [
    ("\n\n#: The structure perturbations of Mapping A", '''

def reverse_members(populations: pd.DataFrame, arg: str, seed: int) -> pd.DataFrame:
    """Within each population, the members' profiles in reverse order (a test set)."""
    out = populations.copy()
    cols = [out.columns.get_loc(p) for p in PARAMS]
    for idx in out.groupby("population").indices.values():
        out.iloc[idx, cols] = out.iloc[idx[::-1], cols].to_numpy()
    out["mapping"] = label("reverse")
    return check_table(out, "populations")


#: The structure perturbations of Mapping A'''),
    ('    "block": Structure(tuple(BLOCKS), profiles=block_profiles, words="{arg} block only"),\n',
     '    "block": Structure(tuple(BLOCKS), profiles=block_profiles, words="{arg} block only"),\n'
     '    "reverse": Structure(populations=reverse_members),\n'),
]}

#: "A metric": its column in tables.py ROBOT_METRICS, computed in sim/metrics.py.
METRIC: Edits = {
    "tables.py": [('missing="no collision ended the run (or no robot)"),\n',
                   'missing="no collision ended the run (or no robot)"),\n'
                   '    _col("robot_mean_speed", "float", "robot path length over the time '
                   'of its outcome", "m/s",\n'
                   '         nullable=True, missing=_NO_ROBOT_NAN),\n')],
    "sim/metrics.py": [('        robot_min_clearance=float(_measure(tr)["robot_min_clearance"]),'
                        '\n    )\n',
                        '        robot_min_clearance=float(_measure(tr)["robot_min_clearance"]),'
                        '\n    )\n'
                        '    out["robot_mean_speed"] = (out["robot_path_length"] / out_time\n'
                        '                               if out_time > 0 else np.nan)\n')],
}

#: "A paper figure": a value of analysis/paper_reference.py.
PAPER_FIGURE: Edits = {"analysis/paper_reference.py": [("TAIL_TO_MEAN_RATIO = 4.0",
                                                        "TAIL_TO_MEAN_RATIO = 3.0")]}

#: every recipe the shared study follows, by the name of its test
ALL: dict[str, Edits] = {
    "controller": CONTROLLER, "population": POPULATION, "section": SECTION,
    "finding": FINDING, "respondent": RESPONDENT, "mapping": MAPPING,
    "profile_set": PROFILE_SET, "metric": METRIC, "paper_figure": PAPER_FIGURE}
