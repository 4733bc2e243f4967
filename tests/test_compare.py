"""``popnavshift compare``: several controllers' cards side by side in one page and one
table, on the quick study; the table on synthetic runs; Markdown and LaTeX export."""

from __future__ import annotations

import json
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
from popnavshift.evaluate.export import to_latex, to_markdown
from synth_study import synthetic_study

#: `compare` is registered by importing popnavshift.cli.evaluate (as for test_evaluate)
MAIN = "import popnavshift.cli.evaluate; from popnavshift.cli import main; main()"
FOUR = ("reactive", "early_yield", "robot_orca", "HRVO")
CARD_TABLES = ("outcomes", "per_population", "gaps", "reversals", "significant_reversals",
               "ranks", "wins", "safety_rates", "safety_differences", "errors")


def cli(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", MAIN, *args], capture_output=True, text=True,
                          cwd=cwd, timeout=600)


@pytest.fixture(scope="module")
def quick(tmp_path_factory) -> tuple[Path, subprocess.CompletedProcess,
                                      subprocess.CompletedProcess]:
    """compare run twice in a fresh folder: the first runs the quick study (as
    `popnavshift run quick` would, without its report), evaluates and cards all four
    controllers (HRVO's runs simulated); the second reads every card."""
    root = tmp_path_factory.mktemp("compare")
    args = ("compare", *FOUR, "--study-dir", "study-quick", "--n-boot", "100")
    first = cli(*args, cwd=root)
    second = cli(*args, cwd=root)
    return root / "study-quick", first, second


@pytest.mark.slow  # the quick study run and compared through the CLI (~30 s)
def test_compare_writes_one_page_and_one_table_with_a_row_per_controller(quick):
    folder, first, _ = quick
    assert first.returncode == 0, first.stderr
    assert "HRVO on main: 0 runs reused, 40 to run" in first.stderr
    out = folder / "compare"
    assert sorted(p.name for p in out.iterdir()) == [
        "compare.csv", "compare.html", "compare.json", "compare.md", "compare.png", "compare.tex"]
    manifest = json.loads((out / "compare.json").read_text())
    assert manifest["controllers"] == list(FOUR) and manifest["settings"]["n_boot"] == 100
    assert set(manifest["files"]) == {f"compare.{x}" for x in ("csv", "html", "md", "png", "tex")}
    table = pd.read_csv(out / "compare.csv")
    assert list(table["controller"]) == list(FOUR)
    assert table["verdict"].notna().all() and (table["runs"] == 40).all()
    for o in ("success", "pedestrian_collision", "world_collision"):
        assert (table[f"{o}_low"] <= table[f"{o}_pct"]).all()
        assert (table[f"{o}_pct"] <= table[f"{o}_high"]).all()
    assert sorted(table["rank_mean_delay"]) == [1, 2, 3, 4]
    html = (out / "compare.html").read_text()
    assert html.count("<img") == 1 and 'src="data:image/png;base64,' in html
    assert "<script" not in html and all(c in html for c in FOUR)
    assert (out / "compare.md").read_text().count("\n") == 2 + len(FOUR)
    assert "early\\_yield" in (out / "compare.tex").read_text()


@pytest.mark.slow  # the quick study run and compared through the CLI (~30 s)
def test_each_card_writes_its_verdict_and_every_table_as_csv(quick):
    folder, _, _ = quick
    for ctrl in FOUR:
        card = folder / "evaluate" / ctrl
        verdict = json.loads((card / "card.json").read_text())
        assert verdict["verdict"]["label"] and verdict["tables"] == [
            f"{t}.csv" for t in CARD_TABLES]
        for t in CARD_TABLES:
            assert (card / f"{t}.csv").exists(), (ctrl, t)
        outcomes = pd.read_csv(card / "outcomes.csv")
        assert outcomes["controller"].iloc[0] == ctrl  # then its baselines: the others
        assert len(outcomes) == (4 if ctrl == "HRVO" else 3)
        assert (card / "outcomes.md").read_text().startswith("| controller | success % |")
        assert "\\toprule" in (card / "outcomes.tex").read_text()


@pytest.mark.slow  # the quick study run and compared through the CLI (~30 s)
def test_a_second_compare_reads_the_cards_and_simulates_nothing(quick):
    _, _, second = quick
    assert second.returncode == 0, second.stderr
    assert second.stderr.count("card reused") == len(FOUR)
    assert "HRVO on main: 40 runs reused, 0 to run" in second.stderr
    assert "160 runs reused, 0 executed" in second.stderr


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


VERDICTS = {"a": {"label": "inconclusive", "safety": []},
            "b": {"label": "robust in this study", "safety": []},
            "c": {"label": "unsafe", "safety": ["pedestrian collisions in 9%", "wall contacts"]}}


def test_compare_table_ranks_shares_and_verdicts(synthetic):
    runs, peds = synthetic
    table, per_pop = compare_table(runs, peds, ["c", "a", "b"], VERDICTS)
    t = table.set_index("controller")
    assert list(table["controller"]) == ["c", "a", "b"]  # the order given
    assert t.loc["b", "rank_mean_delay"] == 1 and t.loc["b", "rank_mean_delay_worst"] == 1
    assert t.loc["c", "timeout_pct"] == 50.0 and t.loc["a", "timeout_pct"] == 0.0
    assert 0 < t.loc["c", "timeout_low"] < 50 < t.loc["c", "timeout_high"] < 100
    assert t.loc["c", "safety_findings"] == 2 and "wall contacts" in t.loc["c", "safety"]
    assert set(per_pop["population"]) == {"p1", "p2"} and len(per_pop) == 6
    shown = display_table(table)
    assert shown.loc[0, "timeout %"].startswith("50.0 [") and shown.loc[2, "verdict"] == (
        "robust in this study")


def test_markdown_and_latex_escape_every_cell():
    t = pd.DataFrame({"controller": ["a|b", "x_y & 50%"], "value [s]": [1.23456, np.nan]})
    md = to_markdown(t)
    assert md.splitlines()[0] == "| controller | value [s] |"
    assert "a\\|b" in md and "| 1.23 |" in md and "| – |" in md
    tex = to_latex(t, digits=1)
    assert "x\\_y \\& 50\\%" in tex and "1.2" in tex and "--" in tex
    assert tex.startswith("\\begin{tabular}{lr}")
