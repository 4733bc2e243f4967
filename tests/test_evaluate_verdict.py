"""The robustness card's verdict on synthetic tables where the answer is known."""

from __future__ import annotations

import numpy as np
import pytest

from popnavshift.evaluate.card import card_tables
from popnavshift.evaluate.card_page import render_html
from popnavshift.evaluate.verdict import card_evidence, verdict
from popnavshift.populations.build import population_order
from synth_study import crossover, no_effect, synthetic_study

BASELINES = ("b", "c")


def evidence(runs, peds, **kw):
    return card_evidence(runs, peds, "a", BASELINES, rng=np.random.default_rng(0), n_boot=150,
                         **kw)


def meta(runs):
    return {"study": "synthetic", "part": "main", "check": "skipped", "reused": 0,
            "executed": 0, "n_runs": int((runs["controller"] == "a").sum()),
            "n_errors": int((runs["outcome"] == "controller_error").sum()), "n_cells": 12,
            "n_populations": runs["population"].nunique(), "backends": "orca",
            "mappings": "A", "replay_note": "", "n_boot": 150, "seed": 0,
            "base_folder": "-", "seed_sets": 1}


def test_a_crossing_controller_is_population_sensitive():
    runs, peds = synthetic_study({"P": crossover(range(6), 2.0, -1.0),
                                  "Q": crossover(range(6), 2.0, +1.0)}, variants=6)
    v = verdict(runs, "a", evidence(runs, peds))
    assert v.label == "population-sensitive"
    assert "significant reversal" in v.text


def test_no_effect_and_clear_differences_read_robust():
    runs, peds = synthetic_study({"P": no_effect, "Q": no_effect}, variants=8, noise=0.1)
    ev = evidence(runs, peds)
    assert ev.reversals["sig_reversals"].sum() == 0
    assert verdict(runs, "a", ev).label == "robust in this study"


def test_no_crossover_without_the_power_to_see_one_is_not_robust():
    """3 variants per cell: the orderings are decided, but a cell's crossover test has 2
    degrees of freedom and could see only a crossover of seconds — inconclusive, saying
    the size; 8 variants see a ±1 s crossover: robust."""
    runs, peds = synthetic_study({"P": no_effect, "Q": no_effect}, variants=3, noise=0.1)
    v = verdict(runs, "a", evidence(runs, peds))
    assert v.label == "inconclusive" and "had little power" in v.text
    size = float(v.text.split("crossover of ±")[1].split(" s")[0])
    assert size > 1.0
    runs, peds = synthetic_study({"P": no_effect, "Q": no_effect}, variants=8, noise=0.1)
    v = verdict(runs, "a", evidence(runs, peds))
    assert v.label == "robust in this study" and "with 80% power" in v.text


def test_noisy_small_designs_are_inconclusive_with_advice():
    runs, peds = synthetic_study({"P": no_effect, "Q": no_effect}, variants=2, noise=3.0,
                                 n_peds=3)
    ev = evidence(runs, peds)
    v = verdict(runs, "a", ev, seed_sets=1)
    assert v.label == "inconclusive"
    assert np.isfinite(v.seed_sets_to_decide) and v.seed_sets_to_decide > 1
    assert f"About {int(v.seed_sets_to_decide)} episode seed sets" in v.text


def test_a_crashing_controller_gets_a_safety_banner():
    runs, peds = synthetic_study({"P": no_effect, "Q": no_effect}, variants=4)
    crash = (runs["controller"] == "a") & (runs.index % 5 == 0)  # 20% of its runs raise
    runs.loc[crash, "outcome"] = "controller_error"
    card = card_tables(runs, peds, "a", BASELINES, rng=np.random.default_rng(0), n_boot=100)
    assert card.verdict.label == "unsafe"
    assert any("controller errors" in line for line in card.verdict.safety)
    page = render_html(card, meta(runs), "card.png", None)
    assert 'class="danger"' in page and "Verdict: unsafe" in page
    assert "robust in this study" not in page


def test_a_controller_that_fails_every_run_never_reads_robust():
    runs, peds = synthetic_study({"P": no_effect, "Q": no_effect}, variants=4, noise=0.1)
    runs.loc[runs["controller"] == "a", "outcome"] = "timeout"
    v = verdict(runs, "a", evidence(runs, peds))
    assert v.label == "fails every run"


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


def test_a_design_with_one_episode_per_cell_says_it_cannot_be_tested():
    runs, peds = synthetic_study({"P": no_effect, "Q": no_effect}, variants=1)
    card = card_tables(runs, peds, "a", BASELINES, rng=np.random.default_rng(0), n_boot=50)
    assert card.verdict.label == "inconclusive"
    assert card.verdict.text.startswith("This design cannot support the tests")
    page = " ".join(render_html(card, meta(runs), "card.png", None).split())
    assert "need at least 2 episodes per cell" in page and "Rank per population" not in page


def test_a_card_of_a_controller_that_fails_every_run_draws_no_ranking():
    runs, peds = synthetic_study({"P": no_effect, "Q": no_effect}, variants=4, noise=0.1)
    runs.loc[runs["controller"] == "a", "outcome"] = "timeout"
    card = card_tables(runs, peds, "a", BASELINES, rng=np.random.default_rng(0), n_boot=50)
    page = " ".join(render_html(card, meta(runs), "card.png", None).split())
    assert card.verdict.label == "fails every run"
    assert "Where it does worst" not in page and "Rank per population" not in page
    assert "no ranking, win or reversal below says anything about it" in page
