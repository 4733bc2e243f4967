"""Issue 34: cards and comparisons you can trust after any fault. A card is reused only when
it is whole and was made under the same rules (else made again, with one line saying
why); a damaged card is one clear error from Python; ``evaluate -o`` never writes over
the study; names become safe folder names; ``compare -o`` is checked before any work;
labels are text in every renderer. On the finished tiny study with `reactive`'s card
(the ``carded`` fixture), copied before any change."""

from __future__ import annotations

import json
import os
import signal
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import popnavshift
from cli_helpers import assert_one_line_error, study_copy, table_hashes
from forked_cli import run_cli
from popnavshift.design.study import load_study
from popnavshift.errors import InputError
from popnavshift.evaluate import evaluate, make_card
from popnavshift.evaluate.card_files import card_folder, card_identity, card_is_current, slug
from popnavshift.io import read_csv
from popnavshift.read.access import card_intact

pytestmark = pytest.mark.slow  # each copy holds a study run and a card made once (~20 s)


def compare(folder: Path, *args: str):
    return run_cli("compare", "reactive", "-s", str(folder.parent / "tiny.yaml"), "-d",
                   str(folder), "--n-boot", "20", "-w", "1", *args)


def card_lines(proc) -> list[str]:
    return [ln for ln in proc.stderr.splitlines() if ln.startswith("reactive: card")]


def test_compare_reuses_only_a_whole_card_made_under_the_same_rules(carded, tmp_path):
    s = study_copy(carded, tmp_path / "s")
    tables = table_hashes(s)
    card = s / "evaluate" / "reactive"
    steps = [((), "card reused"),
             (("--seed", "3"), "made again: it was made with --seed 0 (now 3)"),
             (("--seed", "3", "--safety-threshold", "0.5", "--baselines", "robot_orca"),
              "made again: it was made against early_yield, robot_orca (now robot_orca)")]
    for args, said in steps:
        proc = compare(s, *args)
        assert proc.returncode == 0, proc.stderr
        assert len(card_lines(proc)) == 1 and said in card_lines(proc)[0], proc.stderr
    doc = json.loads((card / "card.json").read_text())
    assert (doc["seed"], doc["safety_threshold"], doc["baselines"]) == (3, 0.5, ["robot_orca"])
    page = json.loads((s / "compare" / "compare.json").read_text())
    assert page["settings"] == {"n_boot": 20, "seed": 3, "safety_threshold": 0.5,
                                "baselines": ["robot_orca"]}
    (card / "card.png").unlink()  # a card killed before its figure, as in the issue
    proc = compare(s, "--seed", "3", "--safety-threshold", "0.5", "--baselines", "robot_orca")
    assert proc.returncode == 0 and f"made again: {card / 'card.png'} is missing" in proc.stderr
    assert card_intact(card)[1] == "" and table_hashes(s) == tables


def test_a_card_killed_while_it_is_written_is_never_reused(carded, tmp_path):
    """kill -9 while a new card is being written: the old card stays whole, and the one
    asked for (another seed) is made again by compare (a kill after the renames, before
    card.json: test_outputs.py)."""
    s = study_copy(carded, tmp_path / "s")
    card = s / "evaluate" / "reactive"
    pid = os.fork()
    if pid == 0:  # pragma: no cover - the child: a card whose writing hangs, then is killed
        try:
            import popnavshift.evaluate.run as run

            original = run.write_card

            def slow(*args, **kwargs):
                paths = original(*args, **kwargs)
                time.sleep(60)
                return paths

            run.write_card = slow
            study = load_study(str(s.parent / "tiny.yaml"))
            make_card(evaluate("reactive", study, s, workers=1, show_progress=False),
                      n_boot=20, seed=7)
        finally:
            os._exit(0)
    deadline = time.monotonic() + 120
    while not list(card.glob(".card.html.*.tmp")) and time.monotonic() < deadline:
        time.sleep(0.2)
    os.kill(pid, signal.SIGKILL)
    os.waitpid(pid, 0)
    doc, why = card_intact(card)
    assert why == "" and doc["seed"] == 0  # the old card, whole
    proc = compare(s, "--seed", "7")
    assert proc.returncode == 0 and "made again: it was made with --seed 0 (now 7)" in proc.stderr
    assert not list(card.glob(".*.tmp"))  # the killed writer's leftovers are gone


DAMAGED = ["", "[]", "{", '{"files": {}}', '{"files": {}, "verdict": "unsafe", "tables": []}']


def test_a_damaged_card_json_is_a_reason_to_rebuild_and_an_error_from_python(carded, tmp_path):
    """(compare rebuilding on that reason: the tests above and test_fuzz_outputs.py)"""
    s = study_copy(carded, tmp_path / "s")
    card = s / "evaluate" / "reactive"
    good = (card / "card.json").read_text()
    identity = {k: json.loads(good)[k] for k in ("controller", "n_boot", "seed")}
    for text in DAMAGED:
        (card / "card.json").write_text(text)
        assert card_is_current(card, identity), text
        with pytest.raises(InputError, match="card.json"):
            popnavshift.cards(s)
    (card / "card.json").write_text(good)
    assert card_is_current(card, identity) == "" and popnavshift.cards(s)["reactive"]


def test_cards_and_load_from_python(carded, tmp_path):
    with pytest.raises(InputError, match="no such study folder"):
        popnavshift.cards(tmp_path / "nowhere")
    cards = popnavshift.cards(carded)
    assert list(cards) == ["reactive"] and isinstance(cards["reactive"]["outcomes"], pd.DataFrame)
    assert set(popnavshift.load(carded, part=None)["controller"]) >= {"reactive"}
    s = study_copy(carded, tmp_path / "s")
    mark = json.loads((s / "study.json").read_text())
    (s / "study.json").write_text(json.dumps({**mark, "config_hash": "another"}))
    with pytest.warns(UserWarning, match="another configuration"):
        assert popnavshift.cards(s) == {}
    with pytest.warns(UserWarning, match="another configuration"):
        assert "reactive" not in set(popnavshift.load(s, part=None)["controller"])
    (s / "manifest.json").write_text("[]")
    with pytest.raises(InputError, match="manifest.json is damaged"):
        popnavshift.load(s, part="main", evaluated=False)
    (s / "runs.parquet").write_bytes(b"PAR1 not really")
    with pytest.raises(InputError, match="runs.parquet is damaged"):
        popnavshift.load(s, part=None, evaluated=False)


def test_evaluate_out_never_writes_over_the_study(carded, tmp_path):
    s = study_copy(carded, tmp_path / "s")
    tables = table_hashes(s)
    yaml = str(s.parent / "tiny.yaml")
    for out, said in ((s, "is the baseline study's folder"), (tmp_path, "or holds it"),
                      (s / "report", "but not in its evaluate/ folder"),
                      (s / "evaluate" / "..", "is the baseline study's folder"),
                      (s / "runs.parquet", "is not a folder")):
        assert_one_line_error(run_cli("evaluate", "HRVO", "-s", yaml, "-d", str(s), "-o",
                                      str(out)), said)
    (tmp_path / "notes").mkdir()
    (tmp_path / "notes" / "runs.parquet").write_text("my own file")
    assert_one_line_error(run_cli("evaluate", "HRVO", "-s", yaml, "-d", str(s), "-o",
                                  str(tmp_path / "notes")), "not empty and holds no card")
    assert table_hashes(s) == tables and not (s / "evaluate" / "HRVO").exists()
    assert not (s / "report").exists()


def test_a_card_and_its_comparison_name_the_study_folder_never_its_path(carded, tmp_path):
    """Given as an absolute path, the study folder is named by its name in the card, its
    evaluation.json and the comparison (#35 item 4: no machine path in a study's outputs)."""
    s = study_copy(carded, tmp_path / "s")
    proc = compare(s.resolve(), "--seed", "5")  # a new seed: the card is written again
    assert proc.returncode == 0 and "made again" in proc.stderr, proc.stderr
    written = [p for p in (*(s / "evaluate").rglob("*"), *(s / "compare").rglob("*"))
               if p.is_file()]
    assert {"evaluation.json", "card.html", "card.json", "compare.html"} <= {
        p.name for p in written}
    for path in {str(tmp_path), str(tmp_path.resolve())}:
        assert [p.name for p in written if path.encode() in p.read_bytes()] == []
    assert json.loads((s / "evaluate" / "reactive" / "evaluation.json").read_text())[
        "base_folder"] == "s"


@pytest.mark.parametrize("name", ["..", ".", "../..", "a/../../b", ".hidden", "-", "x" * 300,
                                  "HRVO{\"horizon\": 4}", "pkg.mod:Class"])
def test_a_controller_name_is_a_folder_inside_evaluate(name, tmp_path):
    folder = card_folder(tmp_path, name)
    assert folder.parent == tmp_path / "evaluate" and folder.resolve().parent == (
        tmp_path / "evaluate").resolve()
    assert not folder.name.startswith(".") and len(folder.name) <= 69
    assert slug(name) != slug(name + "x")


def test_compare_out_is_checked_before_any_work(carded, tmp_path):
    s = study_copy(carded, tmp_path / "s")
    (tmp_path / "dir.html").mkdir()
    (tmp_path / "mine.tex").write_text("\\section{mine}")
    (tmp_path / "f.txt").write_text("x")
    for out, said in ((tmp_path / "dir.html", "is a folder"),
                      (tmp_path / "mine.html", "would replace"),
                      (tmp_path / "f.txt" / "c.html", "is a file, not a folder"),
                      (tmp_path / "page.csv", "must name an .html page")):
        proc = run_cli("compare", "HRVO", "-s", str(s.parent / "tiny.yaml"), "-d", str(s),
                       "-o", str(out))
        assert_one_line_error(proc, said)
    assert (tmp_path / "mine.tex").read_text() == "\\section{mine}"
    assert not (s / "evaluate" / "HRVO").exists() and not (s / "compare").exists()


# ---- labels are text in every renderer ----------------------------------------------
HOSTILE = ("=HYPERLINK(\"http://evil\")", "a$x^$b", "<b>bold</b>|x")


def test_hostile_controller_names_in_the_comparisons_files_and_the_card(tmp_path):
    """A plug-in's name is data: a formula stays text in the CSV, ``$…$`` is no mathtext
    in either figure, markup is escaped in the HTML, Markdown and LaTeX."""
    from popnavshift.design.study import study_from_dict
    from popnavshift.evaluate.card import card_tables
    from popnavshift.evaluate.card_page import write_card
    from popnavshift.evaluate.compare import Comparison, compare_table
    from popnavshift.evaluate.compare_page import write_comparison
    from popnavshift.evaluate.robustness import robustness_tables
    from popnavshift.outputs import FileSet
    from report_study import STUDY
    from synth_study import no_effect, synthetic_study

    runs, peds = synthetic_study({"p1": no_effect, "p2": no_effect}, n_cells=3, variants=2,
                                 controllers=HOSTILE)
    verdicts = {c: {"robustness": {"label": "undecided", "text": f"{c} text", "row": {}},
                    "safety": {"label": "unsafe", "text": f"{c} collides",
                               "findings": [f"{c} collides"]}} for c in HOSTILE}
    table, per_pop = compare_table(runs, peds, HOSTILE, verdicts)
    cards = {c: tmp_path / "evaluate" / slug(c) / "card.html" for c in HOSTILE}
    paths = write_comparison(Comparison(HOSTILE, table, per_pop, cards, verdicts,
                                        study_from_dict(STUDY), tmp_path),
                             tmp_path / "compare" / "compare.html")
    raw = paths["csv"].read_text()
    assert "'=HYPERLINK" in raw and "\n=HYPERLINK" not in raw
    assert list(read_csv(paths["csv"])["controller"]) == list(HOSTILE)  # read back as given
    assert "&lt;b&gt;bold&lt;/b&gt;" in paths["html"].read_text()
    assert "\\<b\\>bold\\</b\\>\\|x" in paths["md"].read_text()
    assert "a\\$x\\textasciicircum{}\\$b" in paths["tex"].read_text()
    rob = robustness_tables(runs, peds, HOSTILE[1], HOSTILE[::2], {}, ["p1", "p2"], n_boot=20)
    card = card_tables(runs, peds, HOSTILE[1], HOSTILE[::2], rob, rng=np.random.default_rng(0),
                       n_boot=20)
    with FileSet(tmp_path / "card", "card.json") as files:  # the figure draws "$x^$" as text
        html, png = write_card(card, {"n_boot": 20, "seed": 0, "study": "s", "part": "main",
                                      "check": "-", "reused": 0, "executed": 0, "n_runs": 1,
                                      "n_errors": 0, "n_cells": 3, "n_populations": 2,
                                      "backends": "orca", "mappings": "A", "replay_note": "",
                                      "base_folder": "-", "seed_sets": 1, "n_used": 1,
                                      "safety_threshold": 0.01, "parts": "main", "n_every": 1,
                                      "version": "0", "config_hash": "h", "made": "today"},
                                     files, None)
        files.commit({})
    assert png.stat().st_size > 10_000 and "a$x^$b" in html.read_text()


def test_card_settings_from_python_are_checked_before_any_work(carded):
    study = load_study(str(carded.parent / "tiny.yaml"))
    from popnavshift.errors import ConfigError
    from popnavshift.evaluate.compare import compare as compare_api

    for bad in ({"n_boot": 0}, {"n_boot": 1.5}, {"seed": -1}, {"safety_threshold": float("nan")},
                {"safety_threshold": 2}):
        with pytest.raises(ConfigError):
            compare_api(["reactive"], study, carded, **bad)
    assert card_identity("reactive", ["early_yield"], "h", "digest", n_boot=1, seed=0,
                         safety_threshold=None)["runs"] == "digest"
