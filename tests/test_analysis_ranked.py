"""The ranked cell metrics are declared once (analysis/ranked.py): every declared metric
is a cell-metrics column computed by its one function (unit weights: the point; episode
weights: a resample), docs/analysis.md shows the declaration, and adding one (the recipe
of docs/architecture.md) is one entry that reaches the report."""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from popnavshift.analysis import cell_metrics, paired_delays
from popnavshift.analysis.delay import CELL_KEY, cvar, worst_decile
from popnavshift.analysis.ranked import (
    RANKED_METRICS,
    TOLERANCES,
    metrics_markdown,
    ranked_metric,
)
from popnavshift.analysis.resample import build_design, resampled_metrics
from popnavshift.errors import UnknownNameError
from recipes import package_with, run_with
from synth_study import crossover, no_effect, synthetic_study

DOCS = Path(__file__).resolve().parents[1] / "docs"


@pytest.fixture(scope="module")
def study():
    runs, peds = synthetic_study({"p": no_effect, "q": crossover([0, 1], 2.0, 1.0)},
                                 n_cells=4, variants=3)
    return runs, peds, paired_delays(peds)


def test_every_declared_metric_is_a_cell_column_equal_to_its_reference(study):
    runs, _, paired = study
    cells = cell_metrics(runs, paired)
    assert [m.name for m in RANKED_METRICS if m.name not in cells.columns] == []
    cell = cells.iloc[0]
    mine = paired.merge(runs[["episode", "scene", "width", "density", "robot_speed"]]
                        .drop_duplicates("episode"), on="episode")
    mine = mine[(mine["population"] == cell["population"])
                & (mine["controller"] == cell["controller"])
                & (mine["scene"] == cell["scene"]) & (mine["width"] == cell["width"])]
    delays = mine["delay"].to_numpy()
    assert delays.size == cell["n_paired"] > 10
    assert cell["mean_delay"] == pytest.approx(delays.mean())
    assert cell["worst_decile"] == pytest.approx(worst_decile(delays))
    assert cell["cvar90"] == pytest.approx(cvar(delays))
    assert cell["worst_decile"] != pytest.approx(cell["cvar90"])  # two different statistics


def test_the_point_is_the_declared_function_with_unit_weights(study):
    runs, _, paired = study
    cells = cell_metrics(runs, paired)
    design = build_design(runs, paired)
    ones = np.ones((1, design.n_columns), dtype=np.int32)
    rows = design.rows.merge(cells, on=list(CELL_KEY), how="left")
    for m in RANKED_METRICS:
        np.testing.assert_array_equal(m.compute(design, ones)[0], rows[m.name].to_numpy(),
                                      err_msg=m.name)
    boot = resampled_metrics(design, ones)  # the bootstrap's storage: float32
    for m in RANKED_METRICS:
        assert boot[m.name].dtype == np.float32
        assert boot[m.name][0] == pytest.approx(rows[m.name].to_numpy(), rel=1e-6), m.name


def test_blocked_share_under_episode_weights_counts_each_drawn_pedestrian():
    """Two episodes of one cell, 4 records each: 1 and 3 blocked. Drawing the second
    twice and the first not at all gives 6 of 8 blocked."""
    runs, peds = synthetic_study({"p": no_effect}, n_cells=1, variants=2, n_peds=4,
                                 controllers=("a",))
    robot = (peds["controller"] == "a").to_numpy()
    first = peds["episode"].str.endswith("-v1").to_numpy()
    stuck = robot & ((first & (peds["slot"] == 0)) | (~first & (peds["slot"] > 0))).to_numpy()
    peds = peds.assign(arrived=~stuck, travel_time=peds["travel_time"].where(~stuck))
    design = build_design(runs, paired_delays(peds))
    w = np.array([[1, 1], [0, 2], [2, 0]], dtype=np.int32)  # columns: v1, v2 (sorted)
    got = resampled_metrics(design, w, ("blocked_pct",))["blocked_pct"][:, 0]
    assert got == pytest.approx([50.0, 75.0, 25.0])


def test_an_unknown_metric_is_named_with_the_close_ones():
    assert ranked_metric("cvar90").tolerance == TOLERANCES["cvar90"]
    with pytest.raises(UnknownNameError, match="did you mean 'cvar90'"):
        ranked_metric("cvar09")


def test_docs_show_the_declaration():
    text = (DOCS / "analysis.md").read_text(encoding="utf-8")
    block = re.search(r"<!-- ranked-metrics:begin -->\n(.*?)<!-- ranked-metrics:end -->",
                      text, re.S)
    assert block is not None and block.group(1) == metrics_markdown()


#: The recipe "A ranked metric" of docs/architecture.md: one entry and its function.
MAX_DELAY = '''

def max_delay_rows(d: Design, w: np.ndarray) -> np.ndarray:
    """The largest paired delay drawn at least once [s] (records sorted largest first)."""
    rec, out = d.records, np.full((w.shape[0], d.rows.shape[0]), np.nan)
    for r in range(out.shape[1]):
        drawn = w[:, rec.col[rec.ptr[r]:rec.ptr[r + 1]]] > 0
        first = rec.val[rec.ptr[r] + drawn.argmax(axis=1)] if drawn.size else np.nan
        out[:, r] = np.where(drawn.any(axis=1), first, np.nan) if drawn.size else np.nan
    return out


RANKED_METRICS = (*RANKED_METRICS, RankedMetric(
    "max_delay", "largest delay", "Largest delay", "s", 0.02, "burden", paper=False,
    summary=False, compute=max_delay_rows))
'''
RECIPE = {"analysis/ranked.py": [("\nRANKED: dict[str, RankedMetric]",
                                  MAX_DELAY + "\nRANKED: dict[str, RankedMetric]")]}
EPISODES = {"scenes": ["sidewalk"], "widths": [1.8, 4.2], "densities": [0.06],
            "robot_speeds": [1.0], "variants": [1]}
POPULATIONS = ["homogeneous", "mixed", "matched_base", "matched_deadline"]
TINY = {"name": "recipe", "seed": 0, "personas": {"source": "synthetic", "n": 300},
        "matched_n": 60,
        "parts": {"main": {"populations": POPULATIONS, "episodes": EPISODES},
                  "sized_null": {"populations": POPULATIONS, "episodes": EPISODES,
                                 "null_design": {"kind": "sized", "replicates": 2}}}}


@pytest.fixture(scope="module")
def tiny_study(tmp_path_factory) -> Path:
    from popnavshift.design.study import study_from_dict
    from popnavshift.engine.runner import run_study

    folder = tmp_path_factory.mktemp("tiny")
    run_study(study_from_dict(TINY), folder, workers=1, show_progress=False)
    return folder


@pytest.mark.slow
def test_the_recipe_for_a_ranked_metric_reaches_the_report(tiny_study, tmp_path):
    root = package_with(tmp_path, RECIPE)
    folder = tmp_path / "study"
    shutil.copytree(tiny_study, folder)
    run_with(root, f"from popnavshift.report import build_report\n"
                   f"build_report(__import__('pathlib').Path({str(folder)!r}), n_boot=50, "
                   f"replays=0)\n")
    tables = folder / "report" / "tables"
    cells = pd.read_csv(tables / "cell_metrics.csv")
    assert cells["max_delay"].notna().any()
    assert (cells["max_delay"].dropna() >= cells["cvar90"].dropna() - 1e-9).all()
    headline = pd.read_csv(tables / "evidence_headline.csv")
    assert "max_delay" in set(headline["metric"])
    assert "largest delay" in (folder / "report" / "index.html").read_text("utf-8")
