"""Issue 34, item 7: property-based tests over the surfaces test_fuzz_study.py does not
reach — damaged card, report and stamp files; the Python API; the options of calibrate,
compare, audit and probe. Each property: one line and exit 2 (or a documented exit 1),
or a correct result; never a traceback; never a changed study table. Most examples run
in-process; command lines run forked (forked_cli.run_cli), a few examples each.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pandas as pd
import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

import popnavshift
from cli_helpers import study_copy, table_hashes
from forked_cli import run_cli
from popnavshift.analysis.calibrate import COLUMNS
from popnavshift.errors import PopNavShiftError
from popnavshift.evaluate.card_files import card_is_current
from popnavshift.io import write_csv
from popnavshift.outputs import folder_hashes, write_output_manifest
from popnavshift.read.access import card_intact, report_intact
from popnavshift.report.build import report_is_current

pytestmark = pytest.mark.slow  # on the carded and reported tiny studies (conftest)
ESCAPE = "\x1b]0;owned\x07\x1b[31m"
RUN = {"rng_seed": 0, "n_boot": 1000, "replays": 2}
FAST = settings(deadline=None, database=None,
                suppress_health_check=[HealthCheck.function_scoped_fixture])

json_junk = st.recursive(
    st.one_of(st.none(), st.booleans(), st.integers(-(2**70), 2**70), st.floats(),
              st.text(max_size=6), st.just(ESCAPE)),
    lambda inner: st.one_of(st.lists(inner, max_size=3),
                            st.dictionaries(st.sampled_from(
                                ["files", "verdict", "tables", "stamp", "label", "safety",
                                 "config_hash", "card.png", "controller"]), inner, max_size=4)),
    max_leaves=8)


@st.composite
def damage(draw, names: list[str]):
    """(file, how): one of ``names`` deleted, truncated, overwritten with bytes, given
    junk appended, or (a JSON file) replaced by any JSON value."""
    name = draw(st.sampled_from(names))
    how = draw(st.sampled_from(["delete", "truncate", "bytes", "append"]
                               + (["json", "keep-json"] if name.endswith(".json") else [])))
    return name, how, draw(st.binary(max_size=40)), draw(json_junk), draw(st.floats(0, 1))


def hurt(folder: Path, name: str, how: str, raw: bytes, value, cut: float) -> None:
    path = folder / name
    if how == "delete":
        path.unlink()
    elif how == "truncate":
        data = path.read_bytes()
        path.write_bytes(data[: int(cut * len(data))])
    elif how == "bytes":
        path.write_bytes(raw)
    elif how == "append":
        path.write_bytes(path.read_bytes() + raw)
    elif how == "json":
        path.write_text(json.dumps(value))
    else:  # keep-json: the same object with one key given a junk value
        doc = json.loads(path.read_text())
        doc[sorted(doc)[int(cut * (len(doc) - 1))]] = value
        path.write_text(json.dumps(doc))


def _restore(src: Path, dst: Path) -> None:
    shutil.rmtree(dst, ignore_errors=True)
    shutil.copytree(src, dst)


# ---- damaged cards: compare's reuse check and popnavshift.cards ---------------------
CARD_FILES = ["card.json", "card.png", "card.html", "outcomes.csv", "ranks.csv", "outcomes.md",
              "safety_rates.csv"]


@pytest.fixture(scope="module")
def carded_copy(carded, tmp_path_factory) -> Path:
    return study_copy(carded, tmp_path_factory.mktemp("fuzz_cards") / "s")


@settings(FAST, max_examples=40)
@given(damage(CARD_FILES))
def test_a_damaged_card_is_never_reused_nor_read_as_it_is(carded, carded_copy, hit):
    card, good = carded_copy / "evaluate" / "reactive", carded / "evaluate" / "reactive"
    _restore(good, card)
    before = {n: (card / n).read_bytes() for n in CARD_FILES}
    identity = {k: v for k, v in json.loads(before["card.json"]).items()
                if k not in ("files", "verdict", "tables")}
    hurt(card, *hit)
    same = all((card / n).is_file() and (card / n).read_bytes() == b for n, b in before.items())
    why = card_is_current(card, identity)
    assert (why == "") == same, (hit[:2], why)
    try:
        cards = popnavshift.cards(carded_copy)
    except PopNavShiftError as err:
        assert not same and "\n" not in str(err) and "reactive" in str(err)
    else:
        assert same and cards["reactive"]["verdict"]["robustness"]["label"]
        assert isinstance(cards["reactive"]["outcomes"], pd.DataFrame)


# ---- damaged reports: run's reuse check, results() ----------------------------------
REPORT_FILES = ["report/stamp.json", "report/index.html", "report/tables/cell_metrics.csv",
                "report/tables/controller_outcomes.csv", "report/figures/tradeoff.png"]


@pytest.fixture(scope="module")
def reported_copy(reported_tiny, tmp_path_factory) -> Path:
    return study_copy(reported_tiny, tmp_path_factory.mktemp("fuzz_report") / "s")


@settings(FAST, max_examples=40)
@given(damage(REPORT_FILES))
def test_a_damaged_report_is_rebuilt_and_never_read_back_as_it_is(reported_tiny, reported_copy,
                                                                   hit):
    _restore(reported_tiny / "report", reported_copy / "report")
    before = folder_hashes(reported_copy / "report")
    hurt(reported_copy, *hit)
    same = folder_hashes(reported_copy / "report") == before
    why = report_is_current(reported_copy, RUN)
    assert (why == "") == same, (hit[:2], why)
    assert (report_intact(reported_copy) == "") == same
    try:
        tables = popnavshift.results(reported_copy)
    except PopNavShiftError as err:
        assert not same and "\n" not in str(err)
    else:
        assert same and isinstance(tables["cell_metrics"], pd.DataFrame)


# ---- the Python API on damaged study files and odd arguments ------------------------
STUDY_FILES = ["manifest.json", "episodes.parquet", "runs.parquet", "pedestrians.parquet",
               "study.json", "evaluate/reactive/evaluation.json",
               "evaluate/reactive/runs.parquet"]
odd = st.one_of(st.sampled_from(["main", None, "matched", "", "m\u0430in", ESCAPE]),
                st.text(max_size=5), st.integers(), st.lists(st.text(max_size=2), max_size=2))


@settings(FAST, max_examples=40)
@given(st.one_of(st.none(), damage(STUDY_FILES)), odd,
       st.sampled_from(["runs", "pedestrians", "profiles", 3]), st.booleans(),
       st.sampled_from(["load", "results", "cards"]))
def test_the_python_api_returns_tables_or_raises_one_of_ours(carded, carded_copy, hit, part,
                                                             table, evaluated, call):
    for name in STUDY_FILES:
        if not name.startswith("evaluate/"):
            shutil.copy(carded / name, carded_copy / name)
    _restore(carded / "evaluate", carded_copy / "evaluate")
    if hit is not None:
        hurt(carded_copy, *hit)
    try:
        if call == "load":
            out = popnavshift.load(carded_copy, part=part, table=table, evaluated=evaluated)
            assert isinstance(out, pd.DataFrame) and "run_id" in out
        elif call == "results":
            popnavshift.results(carded_copy)  # no report here: always an error
            raise AssertionError("results() of a study without a report")
        else:
            assert isinstance(popnavshift.cards(carded_copy), dict)
    except PopNavShiftError as err:
        assert "\n" not in str(err)


# ---- command lines ------------------------------------------------------------------
def one_line_or_success(proc, ok=(0,)) -> None:
    event(f"exit {proc.returncode}")
    assert "Traceback" not in proc.stderr + proc.stdout, proc.stderr
    assert proc.returncode in (*ok, 2), (proc.args, proc.returncode, proc.stderr)
    if proc.returncode == 2:
        lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
        assert len(lines) == 1 and lines[0].startswith("error:"), (proc.args, proc.stderr)
        assert "\x1b" not in proc.stderr


numbers = st.sampled_from(["1", "5", "20", "0", "-1", "1e3", "x", "", "nan", str(2**64),
                           "100001", ESCAPE])
shares = st.sampled_from(["0", "0.5", "1", "1.5", "-0.1", "nan", "inf", "x"])


@st.composite
def compare_args(draw, root: Path):
    names = draw(st.one_of(st.just(["reactive"]), st.lists(st.sampled_from(
        ["reactive", "early_yield", "HRV0", "..", "=cmd()", "re\u0430ctive", ESCAPE]),
        min_size=1, max_size=2)))
    args = [*names]
    if draw(st.booleans()):
        args += ["--n-boot", draw(numbers)]
    else:
        args += ["--n-boot", draw(st.sampled_from(["1", "3", "8"]))]
    for flag, values in (("--seed", numbers), ("--safety-threshold", shares),
                         ("--baselines", st.sampled_from(["robot_orca", "", "nope", ",",
                                                          "reactive,robot_orca"])),
                         ("-o", st.sampled_from([str(root / "page.html"), str(root / "d.html"),
                                                 str(root / "f.txt" / "p.html"),
                                                 str(root / "mine.html"), "x.csv"]))):
        if draw(st.integers(0, 3)) == 0:
            args += [flag, draw(values)]
    return args


@pytest.fixture(scope="module")
def compare_root(carded, tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("fuzz_compare")
    study_copy(carded, root / "s")
    (root / "d.html").mkdir()
    (root / "f.txt").write_text("x")
    (root / "mine.tex").write_text("mine")
    return root


@settings(FAST, max_examples=5)
@given(st.data())
def test_compare_exits_0_or_2_in_one_line_and_never_changes_the_study(compare_root, data):
    s = compare_root / "s"
    tables = table_hashes(s)
    args = data.draw(compare_args(compare_root))
    proc = run_cli("compare", *args, "-s", str(compare_root / "tiny.yaml"), "-d", str(s),
                   "-w", "1", timeout=300)
    one_line_or_success(proc)
    assert table_hashes(s) == tables and (compare_root / "mine.tex").read_text() == "mine"
    if proc.returncode == 0:
        page = Path(args[args.index("-o") + 1]) if "-o" in args else (
            s / "compare" / "compare.html")
        manifest = json.loads(page.with_suffix(".json").read_text())
        assert manifest["kind"] == "popnavshift compare"
        for c in manifest["controllers"]:
            assert card_intact(s / "evaluate" / c)[1] == ""


@pytest.fixture(scope="module")
def calibrated(reported_tiny, tmp_path_factory) -> Path:
    """The reported tiny study with a calibration table in its report (as a study with
    nulls has), stamped as the report's own."""
    s = study_copy(reported_tiny, tmp_path_factory.mktemp("fuzz_calibrate") / "s")
    rows = [{"comparison": c, "test": "prediction t", "rule": "raw", "claim": "above the null",
             "kind": "false positive", "nominal": 0.025, "placebos": 40, "claims": 1,
             "rate": 0.025, "cp_low": 0.001, "cp_high": 0.13, "within": True,
             "status": "within"} for c in ("table", "all", "matched")]
    write_csv(pd.DataFrame(rows)[COLUMNS], s / "report" / "tables" / "evidence_calibration.csv")
    stamp = json.loads((s / "report" / "stamp.json").read_text())
    files = {k: v for k, v in folder_hashes(s / "report").items() if k != "stamp.json"}
    write_output_manifest(s / "report" / "stamp.json", {**stamp, "files": files})
    assert report_intact(s) == ""
    shutil.copytree(s / "report", s.parent / "report.good")  # restored before each example
    return s


@settings(FAST, max_examples=10)
@given(st.one_of(st.none(), damage(["report/tables/evidence_calibration.csv",
                                    "report/stamp.json"])),
       st.lists(st.sampled_from(["--by-comparison", "--fresh", "--no-fresh", "--bogus"]),
                max_size=2), st.sampled_from(["s", "nowhere", "s/report", ESCAPE]))
def test_calibrate_exits_0_1_or_2_in_one_line_and_never_changes_the_study(
        calibrated, hit, flags, where):
    _restore(calibrated.parent / "report.good", calibrated / "report")
    tables = table_hashes(calibrated)
    if hit is not None:
        hurt(calibrated, *hit)
    folder = calibrated if where == "s" else calibrated.parent / where
    proc = run_cli("calibrate", str(folder), *flags)
    one_line_or_success(proc, ok=(0, 1))
    assert table_hashes(calibrated) == tables
    if proc.returncode == 0:
        assert "prediction t" in proc.stdout


@settings(FAST, max_examples=6)
@given(st.lists(st.tuples(st.sampled_from(["--seed", "--permutations", "--boot"]), numbers),
                max_size=2), st.booleans())
def test_audit_options_exit_0_1_or_2_in_one_line(finished, args, strict):
    flat = [x for pair in args for x in pair] + (["--strict"] if strict else [])
    if "--permutations" not in flat:
        flat += ["--permutations", "319"]
    if "--boot" not in flat:
        flat += ["--boot", "100"]
    tables = table_hashes(finished)
    proc = run_cli("audit", str(finished), *flat)
    one_line_or_success(proc, ok=(0, 1))
    assert table_hashes(finished) == tables


@settings(FAST, max_examples=6)
@given(st.lists(st.tuples(st.sampled_from(["--seed", "--respondent-seed", "--matched-n",
                                           "--samples", "--respondent"]),
                          st.one_of(numbers, st.sampled_from(["rule", "rul", "openai"]))),
                max_size=2))
def test_probe_options_exit_0_or_2_in_one_line(finished, tmp_path_factory, args):
    folder = tmp_path_factory.mktemp("probe") / "s"
    folder.mkdir()
    shutil.copy(finished / "personas.parquet", folder / "personas.parquet")
    shutil.copy(finished / "personas.json", folder / "personas.json")
    flat = [x for pair in args for x in pair]
    if "--respondent" not in flat:
        flat += ["--respondent", "rule"]
    if "--matched-n" not in flat:
        flat += ["--matched-n", "10"]
    proc = run_cli("probe", "--out", str(folder), *flat)
    one_line_or_success(proc)
    if proc.returncode == 0:
        assert len(pd.read_parquet(folder / "responses.parquet")) > 0
