"""The card's two verdicts on synthetic tables where the answer is known: robustness decided
against the controller's own null runs, safety under one rule."""

from __future__ import annotations

import numpy as np
import pytest

from popnavshift.evaluate.advice import Advice, advise, decides
from popnavshift.evaluate.card import card_tables
from popnavshift.evaluate.card_page import render_html
from popnavshift.evaluate.robustness import (
    ROBUST,
    SENSITIVE,
    UNDECIDED_LABEL,
    deciding_row,
    robustness_label,
    robustness_tables,
)
from popnavshift.populations.build import population_order
from popnavshift.populations.identity import MATCHED_PAIR
from synth_study import design_specs, no_effect, swap_study, synthetic_study

BASELINES = ("b", "c")


def robustness(runs, peds, controller="a", n_boot=80, seed=0, interaction=True):
    specs = {s.name: s for s in design_specs(runs, "swap")}
    return robustness_tables(runs, peds, controller, [c for c in ("a", *BASELINES)
                                                      if c != controller],
                             specs, list(MATCHED_PAIR), rng_seed=seed, n_boot=n_boot,
                             interaction=interaction)


def meta(runs):
    return {"study": "synthetic", "part": "main", "check": "skipped", "reused": 0,
            "executed": 0, "n_runs": int((runs["controller"] == "a").sum()),
            "n_errors": int((runs["outcome"] == "controller_error").sum()), "n_cells": 12,
            "n_populations": runs["population"].nunique(), "backends": "orca",
            "mappings": "A", "replay_note": "", "n_boot": 80, "seed": 0,
            "base_folder": "-", "seed_sets": 1, "parts": "main", "n_every": len(runs),
            "version": "test", "config_hash": "-", "made": "-"}


def test_a_controller_whose_orderings_cross_with_the_population_is_sensitive():
    runs, peds = swap_study(9, inject=1.5, seed=3)
    r = robustness(runs, peds)
    assert r.label == SENSITIVE
    raw = r.headline[r.headline["rule"] == "raw"].set_index("metric")
    assert raw.loc["mean_delay", "verdict"] == "above the null" and raw["family"].eq(4).all()
    assert r.row["verdict"] == "above the null" and r.row["ci_low"] > 0
    # each baseline's own rates carry it too, decided over their own table (2 × 4 rates)
    by = r.by_baseline[r.by_baseline["rule"] == "raw"]
    assert set(by["baseline"]) == set(BASELINES) and by["family"].eq(8).all()
    assert "against b, c alone" in r.text


def test_the_baselines_own_crossover_is_not_the_controllers():
    """Controller b crosses over between the populations, a does not: b's card is
    population-sensitive, a's counts only its own orderings (a–b, a–c), never b–c."""
    runs, peds = swap_study(9, inject=1.5, seed=4, shifted="b")
    assert robustness(runs, peds, controller="b").label == SENSITIVE
    mine = robustness(runs, peds, controller="a")
    by = mine.by_baseline[mine.by_baseline["rule"] == "raw"].set_index(["baseline", "metric"])
    assert by.loc[("b", "mean_delay"), "verdict"] == "above the null"  # a–b flips: b moved
    assert by.loc[("c", "mean_delay"), "verdict"] != "above the null"  # a–c does not


def test_every_rate_ruling_out_5pp_reads_robust():
    """The label's rule on a decided table: robust only when every rate's simultaneous
    interval ends under 5 pp; one undecided rate keeps it undecided."""
    import pandas as pd

    rows = [{"design": "matched", "baseline": "all", "metric": m, "rule": "raw",
             "observed": 0.10, "null_mean": 0.11, "excess": -0.01, "ci_low": -0.04,
             "ci_high": high, "t": -0.5, "verdict": "no excess ≥ 5 pp"}
            for m, high in (("robot_time", 0.03), ("mean_delay", 0.045))]
    head = pd.DataFrame(rows)
    label, text = robustness_label(head, head.iloc[:0], "a")
    assert label == ROBUST and "largest upper end +4.5 pp" in text
    assert deciding_row(head, label)["metric"] == "mean_delay"
    open_row = head.assign(verdict=["no excess ≥ 5 pp", "undecided"], ci_high=[0.03, 0.09])
    assert robustness_label(open_row, head.iloc[:0], "a")[0] == UNDECIDED_LABEL


def test_a_wide_null_is_undecided_and_the_advice_says_what_would_decide_it():
    runs, peds = swap_study(4, inject=0.0, seed=6, n_cells=6, variants=3, noise=1.5)
    r = robustness(runs, peds)
    assert r.label == UNDECIDED_LABEL and "least decided" in r.text
    advice = advise(r.headline)
    assert advice.rows >= 1
    raw = r.headline[(r.headline["rule"] == "raw") & (r.headline["verdict"] == "undecided")]
    if advice.seed_sets or advice.replicates:  # the point it names decides every open row
        k = advice.seed_sets or int(raw["seed_sets"].max())
        p = advice.replicates or int(raw["n_null"].max())
        assert all(decides(row, k, p) for row in raw.itertuples())
        assert not all(decides(row, int(row.seed_sets), int(row.n_null))
                       for row in raw.itertuples())
    assert advise(r.headline.assign(verdict="robust")) == Advice(None, None, 0)


@pytest.mark.slow  # 20 synthetic studies of pure noise through the card's verdict (~20 s)
def test_pure_noise_rarely_reads_population_sensitive():
    """The card's label claims an effect only when one of its family's rates is above its
    null at α/m: on studies without any population effect, at most about 5% of cards."""
    labels = []
    for seed in range(20):
        runs, peds = swap_study(9, inject=0.0, seed=400 + seed, n_cells=6, variants=3,
                                n_peds=5)
        # the label only: the interaction question is tested on its own below
        labels.append(robustness(runs, peds, n_boot=40, seed=seed, interaction=False).label)
    assert labels.count(SENSITIVE) <= 2, labels


def test_a_controller_that_fails_every_run_never_reads_robust():
    runs, peds = swap_study(4, inject=0.0, seed=7, n_cells=6, variants=3)
    main = runs["population"].isin(MATCHED_PAIR)
    runs.loc[runs["controller"] == "a", "outcome"] = "timeout"
    card = card_tables(runs[main], peds[peds["population"].isin(MATCHED_PAIR)], "a", BASELINES,
                       robustness(runs, peds), rng=np.random.default_rng(0), n_boot=50)
    assert card.verdict.robustness == "fails every run"
    page = " ".join(render_html(card, meta(runs), "card.png", None).split())
    assert "Where it does worst" not in page and "Rank per population" not in page
    assert "no ranking or win below says anything about it" in page


def test_the_card_shows_both_verdicts_and_the_null_beside_every_rate():
    runs, peds = swap_study(9, inject=1.5, seed=3, n_cells=6, variants=3)
    main = runs["population"].isin(MATCHED_PAIR)
    card = card_tables(runs[main], peds[peds["population"].isin(MATCHED_PAIR)], "a", BASELINES,
                       robustness(runs, peds), rng=np.random.default_rng(0), n_boot=50)
    page = " ".join(render_html(card, meta(runs), "card.png", None).split())
    assert "Robustness: population-sensitive." in page and "Safety: " in page
    assert "null rate (mean)" in page and "9 replicates" in page
    assert "On this card's own placebos" in page  # its calibration beside the verdict
    assert set(card.tables()) >= {"robustness", "robustness_by_baseline",
                                  "robustness_null_rates", "robustness_calibration"}


@pytest.mark.parametrize("given", [["mixed", "zeta", "homogeneous", "alpha", "matched_base"]])
def test_populations_come_in_a_fixed_order(given):
    assert population_order(given) == ["homogeneous", "mixed", "matched_base", "alpha", "zeta"]


def test_the_card_uses_the_study_make_run_built(tmp_path, monkeypatch):
    import json
    from pathlib import Path

    from popnavshift.cli.evaluate import _baseline_study

    monkeypatch.chdir(tmp_path)
    s, folder = _baseline_study(None)
    assert s.name == "quick" and folder == Path("study-quick")  # nothing built yet
    cfg = {"name": "built", "seed": 3, "parts": {"main": {"populations": ["mixed"]}}}
    (tmp_path / "study").mkdir()
    (tmp_path / "study" / "manifest.json").write_text(json.dumps({"study_config": cfg}))
    s, folder = _baseline_study(None)
    assert (s.name, s.seed, folder) == ("built", 3, Path("study"))
    assert _baseline_study("quick")[0].name == "quick"  # an explicit name wins


def test_a_design_with_one_episode_per_cell_shows_no_ranks():
    runs, peds = synthetic_study({"P": no_effect, "Q": no_effect}, variants=1)
    specs = {s.name: s for s in design_specs(runs, "swap")}
    rob = robustness_tables(runs, peds, "a", BASELINES, specs, ["P", "Q"], n_boot=20)
    assert rob.label == UNDECIDED_LABEL and "no null design" in rob.text
    card = card_tables(runs, peds, "a", BASELINES, rob, rng=np.random.default_rng(0), n_boot=50)
    page = " ".join(render_html(card, meta(runs), "card.png", None).split())
    assert "need at least 2 episodes per cell" in page and "Rank per population" not in page
    assert "No null design to decide against" in page


def test_a_controller_that_blocks_people_is_judged_on_blocked_pedestrians_too():
    """Blocked pedestrians are a ranked metric like the delays: where the controller blocks
    some (here a random 15 % of its pedestrians, in every population alike), its
    orderings on ``blocked_pct`` get a rate, a null and a verdict in the card's family."""
    runs, peds = swap_study(9, inject=1.5, seed=3)
    rng = np.random.default_rng(0)
    stuck = (peds["controller"] == "a").to_numpy() & (rng.random(len(peds)) < 0.15)
    peds = peds.assign(arrived=~stuck, travel_time=peds["travel_time"].where(~stuck))
    r = robustness(runs, peds)
    raw = r.headline[r.headline["rule"] == "raw"].set_index("metric")
    assert raw.loc["blocked_pct", "n_null"] == 9 and np.isfinite(raw.loc["blocked_pct",
                                                                         "observed"])
    assert raw["family"].eq(5).all()  # robot time, three delays and blocked pedestrians
    assert raw.loc["blocked_pct", "verdict"] != "above the null"  # no population effect on it
    assert raw.loc["mean_delay", "verdict"] == "above the null"  # the delays still decide


def test_the_card_asks_whether_its_differences_change_and_says_it_in_words():
    planted = robustness(*swap_study(9, inject=1.5, seed=3))
    inter = planted.interaction
    tested = inter[inter["verdict"] != "descriptive"]  # a metric with no terms is not tested
    assert len(tested) >= 4 and (tested["n_null"] == 9).all()
    assert (inter["verdict"] == "changes more than under the null").any()
    assert "change with the population more than under its own null runs" in \
        planted.interaction_text
    # its placebos are in the card's calibration, at the card's level and at 5 %
    cal = planted.calibration
    assert cal["test"].str.startswith("interaction").any()
    nothing = robustness(*swap_study(9, inject=0.0, seed=3))
    assert not (nothing.interaction["verdict"] == "changes more than under the null").any()
    assert "not shown to change" in nothing.interaction_text
