"""Two recipes of docs/architecture.md ("Where to add") followed literally on one copy of the
package (tests/recipes.py), into one study's tables and report: a new null kind (a
label-permutation null of a pair of populations: their members pooled and split again at
their sizes) and a new verdict rule (a prediction t on the median and MAD of the replicates,
which one outlying replicate cannot inflate), with the paper's study left as it was."""

from __future__ import annotations

import inspect
import json
import re
from pathlib import Path
from typing import get_args

import pandas as pd
import pytest

from popnavshift.design.part import NullDesign
from popnavshift.design.study import load_study
from popnavshift.populations.identity import NULL_KINDS, Role
from recipes import package_with, run_with

ARCHITECTURE = Path(__file__).resolve().parents[1] / "docs" / "architecture.md"
PAIR = ("high_caution", "low_robot_trust")
REPLICATES = 4  # a placebo of the prediction t needs 3 other replicates
EPISODES = {"scenes": ["sidewalk"], "widths": [1.8], "densities": [0.06],
            "robot_speeds": [1.0], "variants": [1]}

#: "A population identity": a role of PopulationSpec and its NULL_KINDS entry (its name, its
#: replicate k, its members drawn from the study's records, its pairing, its labels).
NULL_RECIPE = {
    "populations/identity.py": [
        ('Role = Literal["observed", "swap_null", "sized_null", "half"]',
         'Role = Literal["observed", "swap_null", "sized_null", "half", "relabel_null"]'),
        ("#: Every null design kind, by its name in a study file",
         '''def relabelled(k: int, pair: tuple[str, ...]) -> tuple[PopulationSpec, ...]:
    """Arms a and b of relabelling k of a pair of populations (its base: the pair)."""
    if len(pair) != 2:
        raise ValueError(f"a relabel null stands in for two populations, got {list(pair)}")
    return tuple(PopulationSpec(tuple(pair), "relabel_null", k, arm) for arm in ARMS)


def pooled_split(spec: PopulationSpec, records: Records) -> Members:
    """The pair's members pooled and split again at their sizes."""
    first, second = (records.members(PopulationSpec(p)) for p in spec.bases)
    pool, n = first + second, len(first)
    order = records.rng("relabel", spec.bases, spec.replicate).permutation(len(pool))
    return sorted(pool[i] for i in (order[:n] if spec.arm == "a" else order[n:]))


#: Every null design kind, by its name in a study file'''),
        ('        listed="size-matched random subsets of mixed (one per cohort)"),\n',
         '        listed="size-matched random subsets of mixed (one per cohort)"),\n'
         '    "relabel": NullKind(\n'
         '        "relabel_null",\n'
         '        lambda s: f"{s.base[0]}_{s.base[1]}_relabel{s.replicate}_{s.arm}",\n'
         '        relabelled, pooled_split, lambda pair, k: relabelled(k, pair),\n'
         '        "random relabellings of the pooled pair",\n'
         '        "a crossover among relabel subsets"),\n'),
    ],
}

#: "A verdict rule": a function in verdicts.py returning a verdict, a line in CHECKS.
VERDICT_RECIPE = {
    "analysis/verdicts.py": [("", '''

def robust_test(observed: float, null: np.ndarray, *, alpha: float = ALPHA,
                floor: float = 0.0) -> dict:
    """A prediction t on the median and MAD of the replicates: (observed − median) over
    1.4826·MAD·√(1 + 1/P) against t on P − 1 df; above or below the null, else undecided.
    ``floor``: taken for the rules' common signature (the binomial floor), not used."""
    null = np.asarray(null, float)
    null = null[np.isfinite(null)]
    if null.size < MIN_NULLS_T or not np.isfinite(observed):
        return {"verdict": UNDECIDED}
    centre = float(np.median(null))
    scale = 1.4826 * float(np.median(np.abs(null - centre))) * np.sqrt(1 + 1 / null.size)
    if scale == 0:
        return {"verdict": UNDECIDED}
    t, cut = (observed - centre) / scale, stats.t.ppf(1 - alpha / 2, null.size - 1)
    return {"verdict": ABOVE if t > cut else BELOW if t < -cut else UNDECIDED}
''')],
    "analysis/calibrate.py": [
        ("    prediction_test,\n)", "    prediction_test,\n    robust_test,\n)"),
        ('          lambda d: d["verdict"] == ABOVE),\n)\n',
         '          lambda d: d["verdict"] == ABOVE),\n'
         '    Check(Test("robust t", robust_test, MIN_NULLS_T), "raw", "an effect (above or '
         'below)",\n'
         '          "false positive", ALPHA, 0.0, lambda d: d["verdict"] in (ABOVE, BELOW)),\n'
         ')\n'),
    ],
}


def relabel_name(k: int, arm: str) -> str:
    return f"{PAIR[0]}_{PAIR[1]}_relabel{k}_{arm}"


def paper_design() -> dict:
    """The paper study's configuration hash and every part's planned populations."""
    paper = load_study("paper")
    return {"hash": paper.config_hash(),
            "planned": {n: list(p.planned_populations) for n, p in paper.parts.items()}}


def test_every_null_kind_is_a_study_kind_and_a_role():
    """A study's null design kinds are those of NULL_KINDS, each with a role of its own."""
    assert [NullDesign(kind=k).kind for k in NULL_KINDS] == list(NULL_KINDS)
    with pytest.raises(ValueError, match="unknown null design kind 'swapp'.*did you mean 'swap'"):
        NullDesign(kind="swapp")
    roles = [k.role for k in NULL_KINDS.values()]
    assert len(set(roles)) == len(roles) and set(roles) <= set(get_args(Role))


@pytest.mark.parametrize("title,recipe", [("A population identity", NULL_RECIPE),
                                          ("A verdict rule", VERDICT_RECIPE)])
def test_the_recipe_names_every_module_it_edits(title, recipe):
    text = ARCHITECTURE.read_text("utf-8")
    bullet = re.search(rf"^- \*\*{title}\*\*.*?(?=^- \*\*|^## )", text, re.S | re.M)
    assert bullet is not None, title
    words = " ".join(bullet.group(0).split())
    assert [m for m in recipe if f"`{m}`" not in words] == []


@pytest.fixture(scope="module")
def null_study(tmp_path_factory):
    """One copy of the package with the null-kind and verdict-rule recipes (disjoint modules),
    one study of a pair of cohorts and 4 relabellings of it, reported; the calibrate
    command's output and the copy's paper study (:func:`paper_design`, run by the copy)."""
    assert not set(NULL_RECIPE) & set(VERDICT_RECIPE)
    tmp = tmp_path_factory.mktemp("recipe_null")
    root = package_with(tmp, {**NULL_RECIPE, **VERDICT_RECIPE})
    folder = tmp / "study"
    parts = {"main": {"populations": list(PAIR), "controllers": ["reactive", "early_yield"],
                      "episodes": EPISODES},
             "relabelled": {"populations": list(PAIR), "controllers": ["reactive", "early_yield"],
                            "episodes": EPISODES,
                            "null_design": {"kind": "relabel", "replicates": REPLICATES}}}
    study = {"name": "recipe-null", "seed": 0, "personas": {"source": "synthetic", "n": 300},
             "matched_n": 60, "parts": parts}
    out = run_with(root, f"""
import json
from pathlib import Path
from popnavshift.cli.calibrate import calibrate
from popnavshift.engine.runner import run_study
from popnavshift.cli.app import stdout
from popnavshift.design.study import load_study, study_from_dict
from popnavshift.report import build_report
folder = Path({str(folder)!r})
run_study(study_from_dict({study!r}), folder, workers=1, show_progress=False)
build_report(folder, n_boot=20, replays=0)
stdout.width = 200
with stdout.capture() as printed:  # calibrate's tables are its output: stdout
    calibrate(folder)
{inspect.getsource(paper_design)}
print(json.dumps({{"calibrate": printed.get(), "paper": paper_design()}}))
""")
    return folder, json.loads(out.splitlines()[-1])


@pytest.mark.slow
def test_the_paper_study_is_unchanged_by_the_recipes(null_study):
    assert null_study[1]["paper"] == paper_design()


@pytest.mark.slow
def test_the_recipe_for_a_null_kind_builds_its_populations(null_study):
    folder, _ = null_study
    pops = pd.read_parquet(folder / "populations.parquet", filters=[("mapping", "==", "A")])
    members = {p: sorted(g["persona_id"]) for p, g in pops.groupby("population")}
    pool = sorted(members[PAIR[0]] + members[PAIR[1]])
    for k in range(1, REPLICATES + 1):
        a, b = members[relabel_name(k, "a")], members[relabel_name(k, "b")]
        assert (len(a), len(b)) == (len(members[PAIR[0]]), len(members[PAIR[1]]))
        assert sorted(a + b) == pool  # the pair's members, split again
    assert members[relabel_name(1, "a")] != members[relabel_name(2, "a")]
    runs = pd.read_parquet(folder / "runs.parquet")
    null = runs[runs["population"].str.contains("_relabel")]
    assert set(null["population_role"]) == {"relabel_null"}
    assert set(null["null_replicate"]) == set(range(1, REPLICATES + 1))
    observed = runs[runs["population"].isin(PAIR)]
    assert set(observed["population_role"]) == {"observed"}
    assert set(observed["null_replicate"]) == {0}


@pytest.mark.slow
def test_the_recipe_for_a_null_kind_reaches_the_headline(null_study):
    folder, _ = null_study
    tables = folder / "report" / "tables"
    head = pd.read_csv(tables / "evidence_headline.csv")
    assert set(head["comparison"]) == {"all_pairs"} and set(head["null"]) == {"relabel"}
    raw = head[head["rule"] == "raw"]
    # a rate exists where some ordering is not tied (blocked_pct: none, when nobody is blocked)
    has = raw["comparable"] > 0
    assert has[raw["metric"] != "blocked_pct"].all()
    assert (raw.loc[has, "n_null"] == REPLICATES).all() and raw.loc[has, "null_mean"].notna().all()
    rates = pd.read_csv(tables / "evidence_null_rates.csv")
    assert set(rates["replicate"]) == set(range(1, REPLICATES + 1))
    html = (folder / "report" / "index.html").read_text("utf-8")
    html = " ".join(html.split())
    assert f"against {REPLICATES} random relabellings of the pooled pair" in html
    assert f"null: {REPLICATES} random relabellings of the pooled pair, 8 populations" in html


@pytest.mark.slow
def test_the_recipe_for_a_verdict_rule_is_calibrated(null_study):
    folder, out = null_study
    cal = pd.read_csv(folder / "report" / "tables" / "evidence_calibration.csv")
    robust = cal[(cal["test"] == "robust t") & (cal["comparison"] == "all")]
    assert len(robust) == 1 and robust["placebos"].iloc[0] > 0
    assert robust["nominal"].iloc[0] == 0.05
    assert "a crossover among relabel subsets" in set(cal["claim"])
    printed = " ".join(out["calibrate"].split())
    assert "robust t (raw)" in printed
