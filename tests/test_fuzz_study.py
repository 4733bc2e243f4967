"""Issue #24: generated study files and command lines either run or fail in one line.

Hypothesis writes study files from good values, near misses (a typo, a homoglyph, a
negative seed, a duplicate, an empty list) and junk (None, booleans, huge integers,
NaN, text with escape sequences). Every one must be accepted by the one validation
(and then be plannable: everything `run` does before its first stage works), or be
refused with one line naming the file. Most examples run in-process; a few go through
the command line as real (forked) processes, which must exit 0 or 2 with one line and
write nothing outside their folder.
"""

from __future__ import annotations

import math
from pathlib import Path

import pytest
import yaml
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from forked_cli import run_cli
from popnavshift.design.part import SCENES
from popnavshift.design.plan import plan_study
from popnavshift.design.study import parse_study_yaml, study_from_dict
from popnavshift.engine.runner import population_settings
from popnavshift.engine.stages import stage_stamps
from popnavshift.engine.validate import validate_study
from popnavshift.episodes.specs import all_episodes, get_episode
from popnavshift.errors import PopNavShiftError
from popnavshift.populations.build import POPULATIONS

EPISODES = all_episodes(0)
ONE_EPISODE = "head_on-w1.8-d0.06-s0.6-v1"
ESCAPE = "\x1b]0;owned\x07\x1b[31m"

junk = st.one_of(
    st.none(), st.booleans(), st.integers(-(2**70), 2**70),
    st.floats(allow_nan=True, allow_infinity=True), st.text(max_size=8),
    st.just(ESCAPE), st.lists(st.integers(-2, 2), max_size=2),
    st.dictionaries(st.sampled_from(["a", "name"]), st.integers(), max_size=2),
)


def rarely(bad: st.SearchStrategy, good: st.SearchStrategy, odds: int = 7) -> st.SearchStrategy:
    """``good`` values, and 1 in ``odds + 1`` times ``bad``: deep fields are reached with
    valid parents, and an accepted study is common enough to check it plans."""
    return st.sampled_from(range(odds + 1)).flatmap(lambda i: bad if i == odds else good)


def often(good: st.SearchStrategy) -> st.SearchStrategy:
    return rarely(junk, good)


def some(good: list, bad: list | None = None, max_size: int = 3) -> st.SearchStrategy:
    """Lists of ``good`` values with now and then a near miss from ``bad`` (a typo, a
    homoglyph, an out-of-grid value): duplicates and empty lists come on their own."""
    one = st.sampled_from(good) if not bad else rarely(st.sampled_from(bad),
                                                       st.sampled_from(good), 10)
    distinct = st.lists(one, min_size=1, max_size=max_size, unique_by=repr)
    return rarely(st.lists(one, max_size=max_size), distinct)


def with_unknown_key(mapping: dict, key: str) -> st.SearchStrategy:
    """``mapping``, now and then with a misspelt key."""
    return rarely(junk.map(lambda v: {**mapping, key: v}), st.just(mapping), 10)


populations = some([*POPULATIONS, "mixed_half_a", "matched_swap1_a", "high_caution_sized2"],
                   ["mixed_sized1", "bogus", "m\u0456xed"])
controllers = some(["robot_orca", "reactive", "early_yield", {"name": "robot_orca", "params": {}}],
                   ["reactiv", "", {"name": "robot_orca", "x": 1}])
episodes = st.fixed_dictionaries({}, optional={
    "scenes": some(list(SCENES), ["bogus"]),
    "widths": some([1.8, 4.2], [4.0, math.nan, math.inf, "1.8", True]),
    "densities": some([0.06, 0.12], [0.2, -1.0]),
    "robot_speeds": some([0.6, 1.0], [1.1]),
    "variants": some([1, 2], [0, True, 1.0]),
    "ids": some([ONE_EPISODE, "sidewalk-w1.8-d0.06-s0.6-v1"], ["nope"], 2),
})
seeds = st.lists(rarely(st.sampled_from([-1, 2**32, 10**30, True, 1.5]),
                        st.sampled_from([0, 1, 2, 3, 2**32 - 1]), 10), max_size=3)
null_design = rarely(st.fixed_dictionaries(
    {"kind": rarely(st.just("bogus"), st.sampled_from(["swap", "sized"]))},
    optional={"replicates": rarely(st.integers(-1, 1000), st.integers(1, 3))}), st.none(), 4)
part = st.fixed_dictionaries({}, optional={
    "populations": often(populations), "episodes": often(episodes),
    "controllers": often(controllers), "backends": often(some(["orca", "hl"], ["orka"], 2)),
    "mapping": often(st.one_of(st.sampled_from(["A", "B", "A~shuffle"]),
                               some(["A", "B", "A~block-caution"], ["E", "A~shufle"]))),
    "baseline": often(st.booleans()), "seeds": often(seeds), "null_design": null_design,
}).flatmap(lambda p: with_unknown_key(p, "bogus_key"))
# extra_body and samples (#34 item 7): an openai respondent's request fields, now and then
# a refused one (stream, n, one the respondent sets), one past the size limit, or no mapping
extra_body = rarely(junk, st.one_of(
    st.dictionaries(st.sampled_from(["cache_prompt", "top_k", "stream", "n", "seed", "tools"]),
                    often(st.sampled_from([False, 3, "x"])), max_size=2),
    st.just({"pad": "x" * 5000})), 3)
samples = rarely(st.sampled_from([0, -1, 101, True, 1.5, "2", None]), st.integers(1, 3), 4)
respondent = st.fixed_dictionaries(
    {"name": rarely(st.just("rul"), st.sampled_from(["rule", "openai"]))},
    optional={"options": st.dictionaries(
        rarely(st.just("modle"), st.sampled_from(["seed", "scale", "temperature", "model",
                                                   "max_retry_after", "api_key_env"])),
        often(st.sampled_from([0, 1, 0.5, "m", "none"])), max_size=2),
        "samples": samples},
).flatmap(lambda r: rarely(st.just(r), extra_body.map(lambda e: {
    **r, "options": {**r.get("options", {}), "extra_body": e}}), 1)
    if r["name"] == "openai" else st.just(r))
names = rarely(st.sampled_from(["a" * 300, "a/b", "..", ESCAPE, ""]), st.just("fuzz"))
part_names = rarely(st.sampled_from(["bad name", "", ESCAPE]), st.sampled_from(["main", "two"]))
studies = st.fixed_dictionaries(
    {"name": often(names),
     "parts": often(rarely(st.just({}), st.dictionaries(part_names, part, min_size=1,
                                                         max_size=3)))},
    optional={"seed": often(rarely(st.just(-1), st.integers(0, 3))),
              "matched_n": often(rarely(st.integers(-1, 10**8), st.integers(1, 50))),
              "personas": often(st.fixed_dictionaries({}, optional={
                  "source": st.just("synthetic"),
                  "n": often(rarely(st.integers(-1, 10**8), st.integers(1, 50))),
                  "missing": rarely(st.just("drop"), st.sampled_from(["require", "fill"]),
                                    10)})),
              "respondent": often(respondent),
              "mappings": often(some(["A", "B", "C"], ["E", "A"])),
              "description": st.text(max_size=20)},
).flatmap(lambda s: with_unknown_key(s, "outptu"))


def _accepted_or_one_line(text: str):
    """The validated study, or None after checking that the refusal is one line naming
    the file."""
    try:
        study = study_from_dict(parse_study_yaml(text, "fuzz.yaml"), "fuzz.yaml")
        validate_study(study, EPISODES)
    except PopNavShiftError as err:
        line = str(err)
        assert line.startswith("fuzz.yaml: ") and "\n" not in line, line
        event("refused: " + line.split(":")[1].strip().split(".")[0][:20])
        return None
    event("accepted")
    return study


@settings(max_examples=300, deadline=None, database=None,
          suppress_health_check=list(HealthCheck))
@given(studies)
def test_a_study_file_is_accepted_and_plannable_or_refused_in_one_line(data):
    study = _accepted_or_one_line(yaml.safe_dump(data, allow_unicode=True))
    if study is None:
        return
    # accepted: everything `run` does before its first stage works, and plans runs
    assert plan_study(study, EPISODES)
    stage_stamps(population_settings(study))
    for part in study.parts.values():
        assert part.planned_populations and part.controllers and part.backends
        for seed in part.seeds:  # the episodes stage draws these
            get_episode(f"{ONE_EPISODE}@s{seed}", seed=study.seed)


@settings(max_examples=150, deadline=None, database=None,
          suppress_health_check=list(HealthCheck))
@given(st.one_of(respondent, st.builds(lambda body, k: {
    "name": "openai", "options": {"extra_body": body}, "samples": k}, extra_body, samples)))
def test_a_respondent_s_samples_and_extra_body_are_accepted_or_refused_in_one_line(spec):
    """In a study otherwise valid, so that the respondent's checks are reached: a refused
    ``samples`` or ``extra_body`` is one line naming the file; an accepted one plans."""
    text = yaml.safe_dump({"name": "fuzz", "parts": {"main": {}}, "respondent": spec})
    study = _accepted_or_one_line(text)
    if study is None:
        return
    k = study.respondent.samples
    assert plan_study(study, EPISODES) and type(k) is int and k in (1, 2, 3)  # `true` is not 1
    body = study.respondent.options.get("extra_body") or {}  # None: no extra fields
    assert isinstance(body, dict) and not {"stream", "n", "seed", "tools"} & set(body)


@settings(max_examples=150, deadline=None, database=None,
          suppress_health_check=list(HealthCheck))
@given(st.text(max_size=60), st.sampled_from(["name: x\n", "name: x\nparts: {main: {}}\n", ""]))
def test_any_text_as_a_study_file_is_one_line_or_a_study(noise, head):
    _accepted_or_one_line(head + noise)


@settings(max_examples=25, deadline=None, database=None,
          suppress_health_check=list(HealthCheck))
@given(studies)
def test_plan_on_a_generated_study_file_exits_0_or_2_in_one_line(tmp_path_factory, data):
    work = tmp_path_factory.mktemp("plan")
    (work / "s.yaml").write_text(yaml.safe_dump(data, allow_unicode=True), "utf-8")
    proc = run_cli("plan", "s.yaml", cwd=work)
    assert_clean(proc)
    assert sorted(p.name for p in work.iterdir()) == ["s.yaml"]  # plan writes nothing


def assert_clean(proc) -> None:
    """Exit 0, or exit 2 with one ``error:`` line; never a traceback."""
    assert "Traceback" not in proc.stderr, proc.stderr
    assert proc.returncode in (0, 2), (proc.returncode, proc.stderr)
    if proc.returncode == 2:
        lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
        assert len(lines) == 1 and lines[0].startswith("error:"), proc.stderr
    assert "\x1b]" not in proc.stdout + proc.stderr  # no data-borne escape sequence


text_arg = st.one_of(st.text(max_size=12), st.just(ESCAPE), st.just("[bold]x[/]"),
                     st.sampled_from(["head_on", "runs", "x.yaml", "s", "-1", "nan"]))
options = st.one_of(
    st.tuples(st.just("episodes"), st.sampled_from(["--scene", "--seed"]), text_arg),
    st.tuples(st.just("plan"), st.sampled_from(["quick", "s", "missing.yaml"]),
              st.just("--from"), st.sampled_from(["s", "f.txt", "nothere", "", ESCAPE])),
    st.tuples(st.just("describe"), st.sampled_from(["s", "f.txt", "nothere"]), text_arg),
    st.tuples(st.just("report"), st.sampled_from(["s", "f.txt", "nothere", "empty"]),
              st.just("--n-boot"), text_arg),
    st.tuples(st.just("run"), st.just("quick"), st.just("--out"), st.just("new"),
              st.sampled_from(["--executor", "--workers"]),
              text_arg.filter(lambda t: t not in ("local", "ray") and not t.isdigit())),
    st.tuples(st.just("replay"), st.just("-e"), text_arg, st.just("--out"),
              st.sampled_from(["s", "x.txt", "empty"]), st.just("--dir"), st.just("empty")),
    st.tuples(st.just("show-prompt"), text_arg, st.just("--study"),
              st.sampled_from(["s", "empty", "nothere"])),
    st.tuples(st.just("simulate"), st.just("-e"), st.just(ONE_EPISODE), st.just("--param"),
              st.sampled_from(["a=1", "=1", "a"]), st.just("--param"), st.just("a=2")),
)


@settings(max_examples=60, deadline=None, database=None,
          suppress_health_check=list(HealthCheck))
@given(options)
def test_any_option_set_exits_0_or_2_in_one_line_and_writes_nothing_else(tmp_path_factory,
                                                                           args):
    work = tmp_path_factory.mktemp("opts")
    for name in ("s", "empty"):
        (work / name).mkdir()
    (work / "s" / "stages.json").write_text("{}")  # a study folder, nothing run yet
    (work / "f.txt").write_text("not a folder")
    before = _tree(work)
    proc = run_cli(*args, cwd=work)
    event(f"{args[0]} exit {proc.returncode}")
    assert_clean(proc)
    assert _tree(work) == before  # none of these commands may write


def _tree(root: Path) -> set[str]:
    return {str(p.relative_to(root)) for p in root.rglob("*") if p.name != ".lock"}


@pytest.mark.parametrize("seed", [0, 2**32 - 1])
def test_the_extreme_seeds_a_study_accepts_draw_episodes(seed):
    assert all_episodes(seed) and get_episode(f"{ONE_EPISODE}@s{seed}", seed=seed)


def test_a_misspelt_profile_set_names_the_file():
    """Found by the fuzz test above: the profile-set label's own ConfigError (raised inside
    validation, not a ValueError) reached the user without the file's name."""
    data = {"name": "fuzz", "parts": {"two": {"mapping": ["A~shufle"]}}}
    with pytest.raises(PopNavShiftError) as err:
        study_from_dict(parse_study_yaml(yaml.safe_dump(data), "fuzz.yaml"), "fuzz.yaml")
    assert str(err.value).startswith("fuzz.yaml: profile set 'A~shufle'")
    assert "\n" not in str(err.value)
