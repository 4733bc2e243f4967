"""``popnavshift leaderboard`` and ``compare``: controllers' cards side by side in one page
and one table, on the quick study (the leaderboard first: the study's controllers and every
navground behaviour; then a compare that reuses their cards); the table on synthetic runs;
Markdown and LaTeX export."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import popnavshift.cli.evaluate  # noqa: F401  (registers `compare`, as MAIN does)
from forked_cli import run_cli
from popnavshift.evaluate.compare import compare_table
from popnavshift.evaluate.compare_page import display_table
from popnavshift.evaluate.export import md_escape, to_latex, to_markdown
from synth_study import synthetic_study

#: `compare` is registered by importing popnavshift.cli.evaluate (as for test_evaluate)
MAIN = "import popnavshift.cli.evaluate; from popnavshift.cli import main; main()"
FOUR = ("reactive", "early_yield", "robot_orca", "HRVO")
CARD_TABLES = ("outcomes", "per_population", "gaps", "robustness", "robustness_by_baseline",
               "robustness_null_rates", "robustness_calibration",
               "robustness_interaction", "ranks", "wins",
               "crossovers", "safety_rates", "safety_differences", "errors")
#: the leaderboard's rows on the quick study: its controllers, then navground's behaviours
BOARD = ("reactive", "early_yield", "robot_orca", "Dummy", "HL", "HRVO", "ORCA",
         "SocialForce")


def cli(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", MAIN, *args], capture_output=True, text=True,
                          cwd=cwd, timeout=600)


@pytest.fixture(scope="module")
def quick(tmp_path_factory) -> tuple[Path, subprocess.CompletedProcess,
                                      subprocess.CompletedProcess]:
    """In a fresh folder, the leaderboard runs the quick study (as `popnavshift run quick`
    would, without its report), evaluates and cards every row (navground's behaviours
    simulated); then compare reads four of those cards."""
    root = tmp_path_factory.mktemp("compare")
    opts = ("--study-dir", "study-quick", "--n-boot", "30")
    first = cli("leaderboard", *opts, cwd=root)
    second = cli("compare", *FOUR, *opts, cwd=root)
    return root / "study-quick", first, second


@pytest.mark.slow  # the quick study run and every behaviour through the CLI (~60 s)
def test_the_leaderboard_has_every_behaviour_once_with_two_verdicts_each(quick):
    folder, first, _ = quick
    assert first.returncode == 0, first.stderr
    assert "HRVO on main: 0 runs reused, 40 to run" in first.stderr
    out = folder / "leaderboard"
    assert sorted(p.name for p in out.iterdir()) == [
        f"leaderboard.{x}" for x in ("csv", "html", "json", "md", "png", "tex")]
    manifest = json.loads((out / "leaderboard.json").read_text())
    assert manifest["controllers"] == list(BOARD) and manifest["settings"]["n_boot"] == 30
    assert manifest["what"] == "leaderboard" and manifest["made"] and manifest["config_hash"]
    table = pd.read_csv(out / "leaderboard.csv")
    assert list(table["controller"]) == list(BOARD)  # no '' and no PyDummy
    assert table["robustness"].isin(["population-sensitive", "robust", "undecided"]).all()
    assert table["safety"].isin(["safe", "unsafe", "undecided", "fails every run"]).all()
    assert (table["runs"] == 40).all() and table["min_clearance"].notna().all()
    for o in ("success", "pedestrian_collision", "standing_contact", "world_collision"):
        assert (table[f"{o}_low"] <= table[f"{o}_pct"]).all()
        assert (table[f"{o}_pct"] <= table[f"{o}_high"]).all()
    assert table["rank_mean_delay"].between(1, len(BOARD)).all()
    html = (out / "leaderboard.html").read_text()
    assert html.count("<img") == 1 and 'src="data:image/png;base64,' in html
    assert "<script" not in html and all(c in html for c in BOARD)
    md = (out / "leaderboard.md").read_text()
    assert md.count("\n") == 2 + len(BOARD) and "rank worst-decile delay" in md
    tex = (out / "leaderboard.tex").read_text()
    assert tex.startswith("\\begin{table}") and "\\label{tab:leaderboard}" in tex
    assert "early\\_yield" in tex and manifest["config_hash"] in tex


@pytest.mark.slow  # the quick study run and compared through the CLI (~30 s)
def test_each_card_writes_its_verdict_and_every_table_as_csv(quick):
    folder, _, _ = quick
    for ctrl in FOUR:
        card = folder / "evaluate" / ctrl
        verdict = json.loads((card / "card.json").read_text())
        assert verdict["verdict"]["robustness"]["label"] and verdict["verdict"]["safety"][
            "label"] and verdict["popnavshift"] and verdict["made"] and verdict["tables"] == [
            f"{t}.csv" for t in CARD_TABLES]
        for t in CARD_TABLES:
            assert (card / f"{t}.csv").exists(), (ctrl, t)
        outcomes = pd.read_csv(card / "outcomes.csv")
        assert outcomes["controller"].iloc[0] == ctrl  # then its baselines: the others
        assert len(outcomes) == (4 if ctrl == "HRVO" else 3)
        assert (card / "outcomes.md").read_text().startswith("| controller | success % |")
        assert "\\toprule" in (card / "outcomes.tex").read_text()


@pytest.mark.slow  # the quick study run and compared through the CLI (~30 s)
def test_a_compare_after_it_reads_the_cards_and_simulates_nothing(quick):
    folder, _, second = quick
    assert second.returncode == 0, second.stderr
    assert second.stderr.count("card reused") == len(FOUR)
    assert "HRVO on main: 40 runs reused, 0 to run" in second.stderr
    assert "160 runs reused, 0 executed" in second.stderr
    table = pd.read_csv(folder / "compare" / "compare.csv")
    assert list(table["controller"]) == list(FOUR)
    assert sorted(table["rank_mean_delay"]) == [1, 2, 3, 4]


@pytest.mark.slow  # reads the quick study's cards
def test_a_current_card_is_reused_without_running_anything(quick):
    folder = quick[0]
    proc = cli("evaluate", "HRVO", "--study-dir", "study-quick", "--n-boot", "30",
               cwd=folder.parent)
    assert proc.returncode == 0, proc.stderr
    assert "card is current, reused" in proc.stderr and "runs reused" not in proc.stderr
    proc = cli("evaluate", "HRVO", "--study-dir", "study-quick", "--n-boot", "29",
               cwd=folder.parent)  # another rule: made again, on the same runs
    assert proc.returncode == 0 and "card is current" not in proc.stderr, proc.stderr


DOC = Path(__file__).resolve().parents[1] / "docs" / "leaderboard.md"


def _doc_table(text: str) -> list[str]:
    """The lines of the Markdown table between the doc's leaderboard markers."""
    body = text.split("<!-- leaderboard:begin -->")[1].split("<!-- leaderboard:end -->")[0]
    return [ln for ln in body.splitlines() if ln.startswith("|")]


@pytest.mark.slow  # reads the quick study's leaderboard
def test_the_docs_leaderboard_is_in_the_format_the_command_writes(quick):
    written = (quick[0] / "leaderboard" / "leaderboard.md").read_text().splitlines()
    doc = _doc_table(DOC.read_text())
    assert doc[:2] == written[:2]  # the same columns, in the same order and alignment
    cells = len(written[0].split(" | "))
    assert all(len(row.split(" | ")) == cells for row in doc[2:])  # [1]: the rule row
    rows = [row.split(" | ")[0].strip("| ") for row in doc[2:]]
    assert rows[:len(BOARD)] == [md_escape(c) for c in BOARD]


def test_the_leaderboards_rows_are_every_behaviour_once():
    import popnavshift.sim.controllers.early_yield  # noqa: F401  registers its navground type
    import popnavshift.sim.controllers.reactive  # noqa: F401  likewise
    from popnavshift.design.study import load_study
    from popnavshift.evaluate.leaderboard import NOT_CONTROLLERS, leaderboard_controllers
    from popnavshift.sim.controllers.builtin import OWN_BEHAVIORS
    from popnavshift.sim.controllers.navground_type import navground_types

    rows = leaderboard_controllers(load_study("quick"), ["HRVO", "ORCA{}", "Dummy"])
    # types other tests of this process registered (plug-ins) are rows too, sorted in
    plugins = set(rows) - set(BOARD)
    assert plugins <= set(navground_types()) and not plugins & {"Dummy", "HL", "HRVO", "ORCA"}
    assert tuple(r for r in rows if r not in plugins) == BOARD  # extras not repeated
    assert not set(rows) & (set(NOT_CONTROLLERS) | OWN_BEHAVIORS)  # '' and PyDummy, ours


LATEX_DOC = r"""\documentclass[a4paper]{article}
\usepackage[T1]{fontenc}
\usepackage[utf8]{inputenc}
\usepackage{booktabs}
\usepackage{graphicx}
\begin{document}
\input{leaderboard.tex}
\end{document}
"""


@pytest.mark.slow  # the quick study's leaderboard, compiled (~2 s)
@pytest.mark.skipif(shutil.which("pdflatex") is None, reason="pdflatex is not installed "
                    "(.ci/run installs Debian's texlive-latex-base and -recommended)")
def test_the_leaderboards_latex_compiles_on_an_a4_page_without_an_overfull_box(quick, tmp_path):
    shutil.copy(quick[0] / "leaderboard" / "leaderboard.tex", tmp_path)
    (tmp_path / "doc.tex").write_text(LATEX_DOC)
    proc = subprocess.run(["pdflatex", "-interaction=nonstopmode", "-halt-on-error", "doc.tex"],
                          cwd=tmp_path, capture_output=True, text=True, timeout=120)
    log = (tmp_path / "doc.log").read_text(errors="replace")
    assert proc.returncode == 0, log[-2000:]
    assert "Overfull" not in log and (tmp_path / "doc.pdf").stat().st_size > 0


def test_user_mistakes_are_one_line_errors_before_anything_runs(tmp_path):
    for args, needle in ((("HRV0",), "did you mean 'HRVO'"),
                         (("reactive", "--out", "x.csv"), "--out must name an .html page")):
        proc = run_cli("compare", *args, "--study-dir", "s", cwd=tmp_path)  # forked
        assert proc.returncode == 2, proc.stderr
        lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
        assert len(lines) == 1 and needle in lines[0], proc.stderr
    assert not (tmp_path / "s" / "stages.json").exists()


# ---- the table on synthetic runs -----------------------------------------------------
def _faster_b(cell: int, controller: str) -> float:
    return -1.0 if controller == "b" else 0.0  # b delays pedestrians 1 s less everywhere


@pytest.fixture(scope="module")
def synthetic() -> tuple[pd.DataFrame, pd.DataFrame]:
    runs, peds = synthetic_study({"p1": _faster_b, "p2": _faster_b}, n_cells=4, variants=2)
    runs.loc[(runs["controller"] == "c") & (runs["variant"] == 1), "outcome"] = "timeout"
    return runs, peds


def _verdict(robustness: str, safety: str, findings: list[str]) -> dict:
    row = {"design": "matched", "metric": "mean_delay", "excess": 0.02, "ci_low": -0.01,
           "ci_high": 0.05} if robustness != "undecided" else {}
    return {"robustness": {"label": robustness, "text": "", "decide": "", "row": row},
            "safety": {"label": safety, "text": "", "findings": findings, "threshold": 0.01}}


VERDICTS = {"a": _verdict("undecided", "undecided", []),
            "b": _verdict("robust", "safe", []),
            "c": _verdict("population-sensitive", "unsafe",
                          ["pedestrian collisions in 9%", "wall contacts"])}


def test_compare_table_ranks_shares_and_verdicts(synthetic):
    runs, peds = synthetic
    table, per_pop = compare_table(runs, peds, ["c", "a", "b"], VERDICTS)
    t = table.set_index("controller")
    assert list(table["controller"]) == ["c", "a", "b"]  # the order given
    assert t.loc["b", "rank_mean_delay"] == 1 and t.loc["b", "rank_mean_delay_worst"] == 1
    assert t.loc["c", "timeout_pct"] == 50.0 and t.loc["a", "timeout_pct"] == 0.0
    assert 0 < t.loc["c", "timeout_low"] < 50 < t.loc["c", "timeout_high"] < 100
    assert t.loc["c", "safety_findings"] == 2 and "wall contacts" in t.loc["c", "safety_text"]
    assert t.loc["b", "excess_pp"] == pytest.approx(2.0) and np.isnan(t.loc["a", "excess_pp"])
    assert set(per_pop["population"]) == {"p1", "p2"} and len(per_pop) == 6
    shown = display_table(table)
    assert shown.loc[0, "timeout %"].startswith("50.0 [") and shown.loc[2, "robustness"] == (
        "robust") and shown.loc[2, "excess over null"].startswith("+2.0 [-1.0, +5.0] pp")


def test_markdown_and_latex_escape_every_cell():
    t = pd.DataFrame({"controller": ["a|b", "x_y & 50%"], "value [s]": [1.23456, np.nan]})
    md = to_markdown(t)
    assert md.splitlines()[0] == "| controller | value [s] |"
    assert "a\\|b" in md and "| 1.23 |" in md and "| – |" in md
    tex = to_latex(t, digits=1)
    assert "x\\_y \\& 50\\%" in tex and "1.2" in tex and "--" in tex
    assert tex.startswith("\\begin{tabular}{lr}")
