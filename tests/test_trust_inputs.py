"""Issue 34: values are checked where they enter (a study file, the command line, Python),
never after a stage ran; the smaller gaps of its item 8 that are not about LLMs."""

from __future__ import annotations

import pytest

from cli_helpers import assert_one_line_error, study_copy, tiny_study
from forked_cli import run_cli
from popnavshift.analysis.reversals import comparisons
from popnavshift.design.study import load_study
from popnavshift.engine.validate import validate_study
from popnavshift.episodes.specs import all_episodes
from popnavshift.errors import ConfigError, InputError
from popnavshift.personas.flat import read_flat_table
from popnavshift.personas.synthetic import generate_personas
from popnavshift.registry import Registry


@pytest.mark.parametrize("options, said", [
    ("{seed: 2024-01-01}", "parameter 'seed' must be an integer; got datetime.date(2024, 1, 1)"),
    ("{scale: 2024-01-01}", "parameter 'scale' must be a number"),
    ("{seed: true}", "parameter 'seed' must be an integer; got True"),
    ("{scale: [1, 2]}", "parameter 'scale' must be a number"),
    ("{seed: '3'}", "must be an integer; got '3'"),
])
def test_a_yaml_value_of_the_wrong_type_is_refused_by_plan(tmp_path, options, said):
    study = tiny_study(tmp_path, respondent=f"respondent: {{name: rule, options: {options}}}\n")
    s = load_study(str(study))
    with pytest.raises(ConfigError, match="tiny.yaml: respondent 'rule': ") as err:
        validate_study(s, all_episodes(s.seed))
    assert said in str(err.value)
    if options.startswith("{seed: 2024"):  # the case, as a user meets it
        assert_one_line_error(run_cli("plan", str(study)), said)


def test_simple_annotations_are_checked_others_left_to_the_factory():
    class Thing:
        def __init__(self, n: int = 1, x: float | None = None, label: str = "",
                     anything: object = None, **rest: object) -> None:
            pass

    reg: Registry = Registry("thing")
    reg.register("t", Thing)
    reg.make("t", n=2, x=3, label="a", anything=[1], extra=object())  # an int is a number
    for bad in ({"n": 1.0}, {"n": False}, {"x": "1"}, {"label": 3}):
        with pytest.raises(ConfigError, match=f"parameter '{next(iter(bad))}' must be"):
            reg.make("t", **bad)


def test_audit_refuses_a_negative_seed_in_one_line(finished):
    for seed in ("-1", "1.5"):
        assert_one_line_error(run_cli("audit", str(finished), "--seed", seed), "--seed")


def test_describe_runs_is_the_runs_table_and_a_missing_folder_says_how(tmp_path):
    proc = run_cli("describe", "runs", cwd=tmp_path)
    assert proc.returncode == 0 and "robot_time" in proc.stdout, proc.stderr
    assert_one_line_error(run_cli("describe", "nowhere", "runs", cwd=tmp_path),
                          "nowhere: no such study folder", "popnavshift describe STUDY runs")


def test_a_homoglyph_persona_value_shows_its_code_point(tmp_path):
    df = generate_personas(4, 0).drop(columns="source")
    df["persona_id"] = [f"p-{k}" for k in range(4)]
    value = df.loc[1, "time_pressure"]
    df.loc[1, "time_pressure"] = value.replace("o", "\u043e", 1)  # Cyrillic o
    df.to_csv(tmp_path / "p.csv", index=False)
    with pytest.raises(InputError, match="U\\+043E at"):
        read_flat_table(tmp_path / "p.csv")


def test_plan_from_a_report_without_the_power_table_says_so(finished, tmp_path):
    from popnavshift.report.build import build_report

    s = study_copy(finished, tmp_path / "s")
    build_report(s, n_boot=20, replays=0)
    proc = run_cli("plan", str(tmp_path / "tiny.yaml"), "--from", str(s))
    text = " ".join(proc.stdout.split())
    assert proc.returncode == 0, proc.stderr
    assert "has no power table" in text and "has no report" not in text


def test_reversals_of_a_study_with_one_population_are_an_empty_table():
    """`evaluate` on a study of one population crashed in the reversal count (no pair)."""
    from popnavshift.analysis import cell_metrics, paired_delays, population_pairs
    from synth_study import no_effect, synthetic_study

    runs, peds = synthetic_study({"p1": no_effect}, n_cells=2, variants=1)
    cells = cell_metrics(runs, paired_delays(peds))
    out = comparisons(cells, population_pairs(["p1"]))
    assert out.empty and {"reversal", "completed"} <= set(out.columns)
