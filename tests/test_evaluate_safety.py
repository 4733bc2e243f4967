"""The card's safety verdict on synthetic runs where the failures are known: which failure,
where, against the baselines on the same runs."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from popnavshift.evaluate.card import card_tables
from popnavshift.evaluate.card_page import render_html
from popnavshift.evaluate.robustness import robustness_tables
from popnavshift.evaluate.safety import (
    SAFE,
    SAFETY_THRESHOLD,
    UNDECIDED,
    UNSAFE,
    failure_rates,
    paired_differences,
    safety_verdict,
)
from synth_study import no_effect, synthetic_study

BASELINES = ("b", "c")


def study(variants: int = 6):
    runs, peds = synthetic_study({"P": no_effect, "Q": no_effect}, variants=variants)
    runs = runs.copy()
    # give the cells two scenes, so a failure can be concentrated in one of them
    obstruct = runs["episode"].str.contains("w1.8|w2.4")
    runs.loc[obstruct, "scene"] = "obstruction"
    return runs, peds


def fail(runs: pd.DataFrame, controller: str, outcome: str, share: float, *,
         scene: str | None = None, seed: int = 0) -> pd.DataFrame:
    """Turn ``share`` of ``controller``'s runs (in ``scene`` if given) into ``outcome``."""
    rng = np.random.default_rng(seed)
    sel = (runs["controller"] == controller) & (True if scene is None
                                                else runs["scene"] == scene)
    idx = runs.index[sel]
    hit = rng.choice(idx, size=int(round(share * len(idx))), replace=False)
    out = runs.copy()
    out.loc[hit, "outcome"] = outcome
    return out


def findings(runs, threshold=SAFETY_THRESHOLD, controller="a"):
    rates = failure_rates(runs, ["a", *BASELINES])
    diffs = paired_differences(runs, "a", list(BASELINES), rng=np.random.default_rng(0),
                               n_boot=300)
    return safety_verdict(rates, controller, threshold), rates, diffs


def test_a_blind_robot_reads_unsafe_for_pedestrian_collisions():
    runs, _ = study()
    runs = fail(fail(runs, "a", "pedestrian_collision", 0.3), "b", "pedestrian_collision", 0.03)
    verdict, rates, _ = findings(runs)
    assert verdict.label == UNSAFE and len(verdict.findings) == 1
    assert verdict.findings[0].startswith("pedestrian collisions (robot moving) in 29.9%")
    # the rate's interval is exact (Clopper–Pearson) and the scenes are listed
    r = rates[(rates["kind"] == "pedestrian_collision") & (rates["controller"] == "a")]
    assert set(r["scope"]) == {"all", "obstruction", "sidewalk"}
    assert (r["low"] <= r["rate"]).all() and (r["rate"] <= r["high"]).all()


def test_wall_contacts_in_one_scene_read_as_their_own_finding():
    runs, _ = study()
    runs = fail(runs, "a", "world_collision", 0.4, scene="obstruction")
    verdict, _, _ = findings(runs)
    assert len(verdict.findings) == 1 and verdict.findings[0].startswith("wall and obstacle")
    assert "highest in obstruction" in verdict.findings[0]


def test_one_rule_for_every_controller_so_labels_can_be_ranked():
    """The same failure rates give the same label whoever has them: a baseline is judged by
    the rule, not against the other baselines, and sharing a failure excuses nobody."""
    runs, _ = study()
    for c in ("a", "b", "c"):
        runs = fail(runs, c, "world_collision", 0.1, seed=1)  # the same runs fail for all
    labels = {c: findings(runs, controller=c)[0].label for c in ("a", *BASELINES)}
    assert labels == {"a": UNSAFE, "b": UNSAFE, "c": UNSAFE}
    assert findings(runs, threshold=0.5)[0].label == SAFE  # an explicit threshold of 50%


def test_a_rate_whose_interval_straddles_the_threshold_is_undecided():
    runs, _ = study()
    runs = fail(runs, "a", "world_collision", 0.02)
    verdict, rates, _ = findings(runs)
    own = rates[(rates["kind"] == "world_collision") & (rates["scope"] == "all")
                & (rates["controller"] == "a")].iloc[0]
    assert own["low"] <= SAFETY_THRESHOLD < own["high"]
    assert verdict.label == UNDECIDED and "more runs would decide" in verdict.text


def test_timeouts_are_reported_but_never_unsafe():
    runs, _ = study()
    verdict, rates, _ = findings(fail(runs, "a", "timeout", 0.5), threshold=0.1)
    assert verdict.label == SAFE and verdict.findings == []
    assert rates[(rates["kind"] == "timeout") & (rates["scope"] == "all")
                 & (rates["controller"] == "a")]["rate"].iloc[0] == pytest.approx(0.5, abs=0.01)


def test_the_card_names_the_failure_and_colours_only_what_it_counts():
    runs, peds = study(variants=4)
    runs = fail(fail(runs, "a", "pedestrian_collision", 0.3), "a", "timeout", 0.3, seed=2)
    card = card_tables(runs, peds, "a", BASELINES, no_null(runs, peds),
                       rng=np.random.default_rng(0), n_boot=100)
    assert card.verdict.safety.label == UNSAFE
    assert "pedestrian collisions" in card.verdict.safety.text
    page = render_html(card, {"study": "s", "part": "main", "check": "skipped", "reused": 0,
                              "executed": 0, "n_runs": 1, "n_errors": 0, "n_cells": 12,
                              "n_populations": 2, "backends": "orca", "mappings": "A",
                              "replay_note": "", "n_boot": 100, "seed": 0, "base_folder": "-",
                              "seed_sets": 1, "parts": "main", "n_every": len(runs),
                              "version": "t", "config_hash": "-", "made": "-"},
                       "card.png", None)
    assert "Safety: each failure, the same rule for every controller" in page
    assert page.count('class="bad"') == 1  # the counted failure; the timeouts not red
    assert "timeouts (reported, not counted)" in page


def test_a_pedestrian_walking_into_a_standing_robot_is_not_the_robots_collision():
    runs, _ = study()
    runs = fail(runs, "a", "pedestrian_collision", 0.3)
    hit = (runs["controller"] == "a") & (runs["outcome"] == "pedestrian_collision")
    runs["contact_speed"] = np.where(hit, 0.0, np.nan)  # the robot stood still every time
    verdict, rates, _ = findings(runs, threshold=0.1)
    assert verdict.findings == []
    standing = rates[(rates["kind"] == "standing_contact") & (rates["scope"] == "all")
                     & (rates["controller"] == "a")]["rate"].iloc[0]
    assert standing == pytest.approx(0.3, abs=0.01)
    runs["contact_speed"] = np.where(hit, 0.8, np.nan)  # now it drove into them
    assert findings(runs)[0].findings[0].startswith("pedestrian collisions (robot moving)")


def test_the_evaluate_help_states_the_default_threshold():
    from popnavshift.cli.evaluate import SafetyThreshold

    help_text = SafetyThreshold.__metadata__[0].help
    assert f"default: {SAFETY_THRESHOLD:g}, {100 * SAFETY_THRESHOLD:g}% of its runs" in help_text


def no_null(runs, peds):
    """The robustness tables of a study that ran no null (the card's safety alone matters)."""
    return robustness_tables(runs, peds, "a", BASELINES, {}, ["P", "Q"], n_boot=20)
