"""The ranked cell metrics are declared once (analysis/ranked.py): every declared metric
is a cell-metrics column, its resampled function with unit weights is its point value,
docs/analysis.md shows the declaration, and adding one (the recipe of
docs/architecture.md) is one entry that reaches the report."""

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


def test_a_resample_of_unit_weights_is_the_point_value(study):
    runs, _, paired = study
    cells = cell_metrics(runs, paired)
    design = build_design(runs, paired)
    got = resampled_metrics(design, np.ones((1, design.n_columns), dtype=np.int32))
    rows = design.rows.merge(cells, on=list(CELL_KEY), how="left")
    for m in RANKED_METRICS:
        assert got[m.name][0] == pytest.approx(rows[m.name].to_numpy(), rel=1e-5), m.name


def test_an_unknown_metric_is_named_with_the_close_ones():
    assert ranked_metric("cvar90").tolerance == TOLERANCES["cvar90"]
    with pytest.raises(UnknownNameError, match="did you mean 'cvar90'"):
        ranked_metric("cvar09")


def test_docs_show_the_declaration():
    text = (DOCS / "analysis.md").read_text(encoding="utf-8")
    block = re.search(r"<!-- ranked-metrics:begin -->\n(.*?)<!-- ranked-metrics:end -->",
                      text, re.S)
    assert block is not None and block.group(1) == metrics_markdown()


#: The recipe "A ranked metric" of docs/architecture.md: one entry, its two functions.
MAX_DELAY = '''

def max_delay_cells(p: Pooled) -> pd.Series:
    """The largest paired delay of the cell [s]."""
    return p.records.groupby(p.key)["delay"].max()


def max_delay_resampled(d: Design, w: np.ndarray) -> np.ndarray:
    """The largest record drawn at least once [s] (records are sorted largest first)."""
    rec, out = d.records, np.full((w.shape[0], d.rows.shape[0]), np.nan)
    for r in range(out.shape[1]):
        drawn = w[:, rec.col[rec.ptr[r]:rec.ptr[r + 1]]] > 0
        first = rec.val[rec.ptr[r] + drawn.argmax(axis=1)] if drawn.size else np.nan
        out[:, r] = np.where(drawn.any(axis=1), first, np.nan) if drawn.size else np.nan
    return out


RANKED_METRICS = (*RANKED_METRICS, RankedMetric(
    "max_delay", "largest delay", "Largest delay", "s", 0.02, "burden", paper=False,
    summary=False, point=max_delay_cells, resampled=max_delay_resampled))
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
