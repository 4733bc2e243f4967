"""The HTML report: its numbers equal a recomputation from the Parquet tables, data text is
escaped, replays reproduce their runs, and sections degrade on a partial study."""

from __future__ import annotations

import json
import re
import shutil
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from popnavshift.analysis import (
    cell_metrics,
    controller_outcomes,
    delay_change,
    no_robot_checks,
    noise_floor,
    paired_delays,
    paper_findings,
    reversal_table,
)
from popnavshift.analysis.study import analyse
from popnavshift.errors import InputError
from popnavshift.read.folder import main_grid, open_study
from popnavshift.report import build_report
from report_study import N_BOOT

EVIL = "<script>alert(1)</script>"
STUDY_FILES = ("runs.parquet", "pedestrians.parquet", "populations.parquet", "episodes.parquet",
               "manifest.json", "personas.json", "responses.json", "figures")


@pytest.fixture
def quick(reported_study) -> Path:
    """A quick-like study (4 populations, 10 episodes) with its report (rng seed 0,
    :data:`N_BOOT` resamples, one replay per kind), run once a session."""
    return reported_study


def copy_study(src: Path, dst: Path) -> Path:
    """The files a report reads (not the shards), so a test can alter them."""
    dst.mkdir(parents=True, exist_ok=True)
    for name in STUDY_FILES:
        if (src / name).is_dir():
            shutil.copytree(src / name, dst / name)
        else:
            shutil.copyfile(src / name, dst / name)
    return dst


def raw_cells(folder: Path) -> tuple[pd.DataFrame, pd.DataFrame, pd.DataFrame]:
    runs = pd.read_parquet(folder / "runs.parquet")
    peds = pd.read_parquet(folder / "pedestrians.parquet")
    return runs, peds, cell_metrics(runs, paired_delays(peds))


def csv(folder: Path, name: str) -> pd.DataFrame:
    return pd.read_csv(folder / "report" / "tables" / f"{name}.csv")


class Tables(HTMLParser):
    """Every <table> of a page as (caption, rows of cell texts)."""

    def __init__(self) -> None:
        super().__init__()
        self.tables: list[tuple[str, list[list[str]]]] = []
        self._cell: list[str] | None = None
        self._caption = False

    def handle_starttag(self, tag, attrs):
        if tag == "table":
            self.tables.append(("", []))
        elif tag == "tr":
            self.tables[-1][1].append([])
        elif tag in ("td", "th"):
            self._cell = []
        elif tag == "caption":
            self._caption = True

    def handle_endtag(self, tag):
        if tag in ("td", "th") and self._cell is not None:
            self.tables[-1][1][-1].append("".join(self._cell).strip())
            self._cell = None
        elif tag == "caption":
            self._caption = False

    def handle_data(self, data):
        if self._cell is not None:
            self._cell.append(data)
        elif self._caption:
            self.tables[-1] = (self.tables[-1][0] + data, self.tables[-1][1])


def page_tables(html: str) -> dict[str, list[list[str]]]:
    parser = Tables()
    parser.feed(html)
    return {caption: rows for caption, rows in parser.tables if caption}


# --- Outputs -----------------------------------------------------------------------------------


def test_report_writes_page_tables_figures_and_replays(quick):
    out = quick / "report"
    html = (out / "index.html").read_text("utf-8")
    for name in ("reversals", "controller_outcomes", "delay_change", "sensitivity_by_width",
                 "kendall_tau", "tradeoff", "no_robot_checks", "findings", "replays"):
        assert (out / "tables" / f"{name}.csv").is_file(), name
        assert f'href="tables/{name}.csv"' in html
    for name in ("reversal_rates", "fig2_delay_change", "fig4_width_sensitivity", "kendall_tau",
                 "tradeoff", "fig3a_profiles", "fig3b_matched_shift", "evidence_nulls"):
        assert (out / "figures" / f"{name}.png").stat().st_size > 1000, name
        assert (out / "figures" / f"{name}.svg").is_file(), name
    assert html.count('src="data:image/png;base64,') == 8  # self-contained figures
    assert "<script" not in html.lower()


def test_sections_appear_in_order_sanity_checks_before_any_score(quick):
    html = (quick / "report" / "index.html").read_text("utf-8")
    ids = re.findall(r'<section id="([a-z0-9]+)">', html)
    assert ids.index("checks") < min(ids.index(s) for s in ("summary", "table1", "table2"))
    assert "the noise floor was not run" in html  # the quick study has no split halves
    from popnavshift.report.page import SECTIONS

    assert ids == [s.id for s in SECTIONS]  # the page is its table of sections, in order


# --- Numbers equal a recomputation from the Parquet tables --------------------------------------


def test_table_one_equals_reversal_table_on_raw_tables(quick):
    _, _, cells = raw_cells(quick)
    want = reversal_table(cells, rng=np.random.default_rng(0), n_boot=N_BOOT)
    got = csv(quick, "reversals")
    key = ["comparison", "cells", "metric"]
    got, want = got.sort_values(key, ignore_index=True), want.sort_values(key, ignore_index=True)
    assert got[key].to_numpy().tolist() == want[key].to_numpy().tolist()
    for col in ("reversals", "comparisons"):
        assert (got[col].to_numpy() == want[col].to_numpy()).all()
    for col in ("rate", "ci_low", "ci_high"):
        np.testing.assert_allclose(got[col], want[col], rtol=1e-12, equal_nan=True)
    paper = got.set_index(key)["paper_rate"]
    assert paper[("all_pairs", "completed", "mean_delay")] == pytest.approx(0.215)
    assert np.isnan(paper[("matched", "completed", "mean_delay")])  # the paper gives none


def test_page_shows_the_csv_rates(quick):
    html = (quick / "report" / "index.html").read_text("utf-8")
    tables = page_tables(html)
    rows = tables[next(k for k in tables if k.startswith("All 6 population pairs — main grid"))]
    t = csv(quick, "reversals")
    t = t[(t["comparison"] == "all_pairs") & (t["cells"] == "all")].set_index("metric")
    shown = {r[0]: r[1] for r in rows[2:]}
    assert shown["Mean pedestrian delay"] == f"{100 * t.at['mean_delay', 'rate']:.1f}%"
    assert shown["Robot travel time"] == f"{100 * t.at['robot_time', 'rate']:.1f}%"


def test_table_two_and_delay_change_equal_recomputation(quick):
    runs, peds, cells = raw_cells(quick)
    want = controller_outcomes(runs, cells)
    got = csv(quick, "controller_outcomes").set_index("controller").loc[want.index]
    for col in ("success_pct", "timeout_pct", "robot_time", "mean_delay", "worst_decile"):
        np.testing.assert_allclose(got[col], want[col], rtol=1e-12)
    change = csv(quick, "delay_change")
    mean = change[change["metric"] == "mean_delay"].set_index(["controller", "population"])
    ref = delay_change(cells).set_index(["controller", "population"])
    np.testing.assert_allclose(mean.loc[ref.index, "change"], ref["change"], rtol=1e-12)
    checks = csv(quick, "no_robot_checks").set_index("population")
    np.testing.assert_allclose(checks["travel_time_mean"],
                               no_robot_checks(peds).set_index("population")["travel_time_mean"])


def test_findings_are_paper_findings_of_the_recomputed_tables(quick):
    study = open_study(quick)
    runs, peds, _ = main_grid(study)
    a = analyse(runs, peds, rng_seed=0, n_boot=N_BOOT)
    t = a.tables
    widths = {"pooled": t["sensitivity_by_width"].query(
        "scenes == 'sidewalk+bottleneck' and cells == 'all' and controller == 'pooled'")}
    direct = paper_findings(t["reversals"], t["controller_outcomes"].set_index("controller"),
                            widths, t["delay_change"].query("metric == 'mean_delay'"))
    got = csv(quick, "findings")
    assert direct[0].statement == got["statement"][0] and direct[0].holds == got["holds"][0]
    assert len(got) == 14 and set(got["statement"]) >= {f.statement for f in direct}
    assert "14 qualitative findings" in (quick / "report" / "index.html").read_text("utf-8")


def test_same_seed_same_intervals_and_another_seed_others(quick):
    runs, peds, _ = main_grid(open_study(quick))
    first = analyse(runs, peds, rng_seed=3, n_boot=100).tables["reversals"]
    again = analyse(runs, peds, rng_seed=3, n_boot=100).tables["reversals"]
    other = analyse(runs, peds, rng_seed=4, n_boot=100).tables["reversals"]
    pd.testing.assert_frame_equal(first, again)
    assert not np.allclose(first["ci_high"], other["ci_high"], equal_nan=True)
    assert np.allclose(first["rate"], other["rate"], equal_nan=True)


# --- Replays, provenance, escaping ------------------------------------------------------------


def test_replays_reproduce_their_stored_runs(quick):
    reps = csv(quick, "replays")
    assert set(reps["case"]) == {"reversal", "delay"}
    assert len(reps) == 4 + 2  # one reversal (2 controllers × 2 populations), one delay + baseline
    assert reps["reproduced"].all(), reps["differences"].tolist()
    for f in reps["file"]:
        page = quick / "report" / f
        assert page.is_file() and page.with_suffix(".svg").is_file()
    html = (quick / "report" / "index.html").read_text("utf-8")
    assert "6 of 6 re-simulated runs reproduce" in html


def test_a_run_that_cannot_be_resimulated_is_reported_not_fatal(quick, tmp_path, monkeypatch):
    from popnavshift.errors import PopNavShiftError
    from popnavshift.report import replays

    def fail(*args, **kwargs):
        raise PopNavShiftError("controller raised")

    monkeypatch.setattr(replays, "resimulate", fail)
    study = open_study(quick)
    runs, peds, _ = main_grid(study)
    a = analyse(runs, peds, n_boot=10)
    reps = replays.write_replays(study, a, runs, tmp_path, 1)
    assert reps is not None and not reps["reproduced"].any()
    assert reps["differences"].str.startswith("could not re-simulate: controller raised").all()
    assert list(tmp_path.iterdir()) == []


def test_manifest_and_rule_respondent_are_stated(quick):
    html = (quick / "report" / "index.html").read_text("utf-8")
    manifest = json.loads((quick / "manifest.json").read_text())
    assert manifest["config_hash"] in html and manifest["probe_set"] in html
    assert "rule-based surrogate respondent" in html and "NOT a language model" in html


def test_persona_ids_and_model_strings_are_escaped(quick, tmp_path):
    folder = copy_study(quick, tmp_path / "evil")
    manifest = json.loads((folder / "manifest.json").read_text())
    manifest["respondent"]["model"] = EVIL
    (folder / "manifest.json").write_text(json.dumps(manifest))
    for name in ("populations.parquet", "pedestrians.parquet"):
        t = pd.read_parquet(folder / name)
        t["persona_id"] = EVIL + t["persona_id"]  # same prefix: slot order is unchanged
        t.to_parquet(folder / name, index=False)
    index = build_report(folder, n_boot=50, replays=1)
    html = index.read_text("utf-8")
    assert "<script" not in html.lower()
    assert html.count("&lt;script&gt;alert(1)&lt;/script&gt;") >= 2  # model and persona id
    for page in (folder / "report" / "replays").glob("*.html"):
        text = page.read_text("utf-8").lower()
        # the page's one script is ours (play, pause, the time slider); no data's is run
        assert text.count("<script") == 1 and "<script>alert(1)" not in text
    assert csv(folder, "replays")["reproduced"].all()


# --- Partial studies ----------------------------------------------------------------------------


def partial(quick: Path, dst: Path, keep) -> Path:
    """A copy of the quick study with only the runs (and their pedestrians) ``keep`` selects."""
    folder = copy_study(quick, dst)
    for name in ("runs.parquet", "pedestrians.parquet"):
        t = pd.read_parquet(folder / name)
        t[keep(t)].to_parquet(folder / name, index=False)
    return folder


def test_one_population_reports_why_rankings_are_missing(quick, tmp_path):
    folder = partial(quick, tmp_path / "one", lambda t: t["population"] == "mixed")
    html = build_report(folder, n_boot=50, replays=0).read_text("utf-8")
    assert "rankings need at least 2 populations" in html
    assert "population sensitivity needs at least 2 populations" in html
    assert (folder / "report/tables/controller_outcomes.csv").exists()
    assert not (folder / "report/tables/reversals.csv").exists()
    assert "Not checked on this study" in html  # the findings that need rankings


def test_no_matched_pair_and_two_controllers(quick, tmp_path):
    def keep(t):
        return (t["population"].isin(["homogeneous", "mixed"])
                & t["controller"].isin(["none", "reactive", "early_yield"]))

    folder = partial(quick, tmp_path / "pair", keep)
    html = build_report(folder, n_boot=50, replays=0).read_text("utf-8")
    assert "All 1 population pairs" in html
    assert "the study lacks the matched pair" in html
    assert "replays were not asked for" in html
    t1 = csv(folder, "reversals")
    assert set(t1["comparison"]) == {"all_pairs"}


def test_without_baselines_there_are_no_checks_and_no_delays(quick, tmp_path):
    folder = partial(quick, tmp_path / "nobase", lambda t: t["controller"] != "none")
    html = build_report(folder, n_boot=50, replays=0).read_text("utf-8")
    assert "the study ran no no-robot baselines" in html
    assert "no pedestrian has a paired delay" in html
    assert (folder / "report/tables/controller_outcomes.csv").exists()


def test_only_baselines_reports_every_controller_section_missing(quick, tmp_path):
    folder = partial(quick, tmp_path / "base", lambda t: t["controller"] == "none")
    html = build_report(folder, n_boot=50, replays=1).read_text("utf-8")
    assert html.count("the study has no robot runs") >= 5
    assert (folder / "report/tables/no_robot_checks.csv").exists()


def test_split_halves_give_a_noise_floor_and_stay_out_of_the_other_sections(quick, tmp_path):
    halves = {"homogeneous": "mixed_half_a", "matched_base": "mixed_half_b"}
    folder = copy_study(quick, tmp_path / "halves")
    for name in ("runs.parquet", "pedestrians.parquet"):
        t = pd.read_parquet(folder / name)
        t["population"] = t["population"].replace(halves)
        t.to_parquet(folder / name, index=False)
    html = build_report(folder, n_boot=50, replays=0).read_text("utf-8")
    runs = pd.read_parquet(folder / "runs.parquet")
    peds = pd.read_parquet(folder / "pedestrians.parquet")
    want = noise_floor(runs, peds, ("mixed_half_a", "mixed_half_b"))
    got = csv(folder, "noise_floor").query("cells == 'all'").set_index("metric")
    np.testing.assert_allclose(got.loc[want["metric"], "rate"], want["rate"], equal_nan=True)
    assert set(csv(folder, "cell_metrics")["population"]) == {"mixed", "matched_deadline"}
    assert "All 1 population pairs" in html and "the noise floor was not run" not in html


def test_a_rebuild_leaves_no_stale_table_of_a_section_now_missing(quick, tmp_path):
    folder = copy_study(quick, tmp_path / "rebuild")
    build_report(folder, n_boot=20, replays=0)
    assert (folder / "report/tables/reversals.csv").exists()
    for name in ("runs.parquet", "pedestrians.parquet"):
        t = pd.read_parquet(folder / name)
        t[t["population"] == "mixed"].to_parquet(folder / name, index=False)
    build_report(folder, n_boot=20, replays=0)
    assert not (folder / "report/tables/reversals.csv").exists()
    assert not (folder / "report/figures/kendall_tau.png").exists()
    assert (folder / "report/figures/tradeoff.svg").exists()


def test_a_folder_without_runs_is_an_input_error(tmp_path):
    with pytest.raises(InputError, match="runs.parquet not found"):
        build_report(tmp_path)


def test_an_llm_respondent_is_named_with_the_endpoint_the_manifest_keeps():
    from popnavshift.report.page import respondent_note

    manifest = {"respondent": {"respondent": "openai", "model": "smollm2",
                               "endpoint": "http://127.0.0.1:8080/v1"}}
    kind, text = respondent_note(manifest)
    assert kind == "p" and "smollm2" in text and "at http://127.0.0.1:8080/v1" in text
    plugin = {"respondent": {"respondent": "steady", "model": "steady-v1"}}
    kind, text = respondent_note(plugin)  # no endpoint: not called a language model
    assert kind == "p" and "steady respondent (steady-v1)" in text
    assert "language model" not in text
