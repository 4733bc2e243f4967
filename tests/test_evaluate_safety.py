"""The card's safety verdict on synthetic runs where the failures are known: which failure,
where, against the baselines on the same runs."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from popnavshift.evaluate.card import card_tables
from popnavshift.evaluate.card_page import render_html
from popnavshift.evaluate.safety import (
    failure_rates,
    paired_differences,
    safety_findings,
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


def findings(runs, threshold=None):
    rates = failure_rates(runs, ["a", *BASELINES])
    diffs = paired_differences(runs, "a", list(BASELINES), rng=np.random.default_rng(0),
                               n_boot=300)
    return safety_findings(rates, diffs, "a", list(BASELINES), threshold), rates, diffs


def test_a_blind_robot_reads_unsafe_for_pedestrian_collisions():
    runs, _ = study()
    runs = fail(fail(runs, "a", "pedestrian_collision", 0.3), "b", "pedestrian_collision", 0.03)
    found, rates, _ = findings(runs)
    assert len(found) == 1 and found[0].startswith("pedestrian collisions (robot moving) in 29.9%")
    assert "least safe baseline, b" in found[0] and "b 2.8%" in found[0]
    # the rate's interval is exact (Clopper–Pearson) and the scenes are listed
    r = rates[(rates["kind"] == "pedestrian_collision") & (rates["controller"] == "a")]
    assert set(r["scope"]) == {"all", "obstruction", "sidewalk"}
    assert (r["low"] <= r["rate"]).all() and (r["rate"] <= r["high"]).all()


def test_wall_contacts_in_one_scene_read_as_their_own_finding():
    runs, _ = study()
    runs = fail(runs, "a", "world_collision", 0.4, scene="obstruction")
    found, _, _ = findings(runs)
    assert len(found) == 1 and found[0].startswith("wall and obstacle contacts")
    assert "highest in obstruction" in found[0]


def test_a_failure_the_baselines_share_is_not_unsafe_unless_a_threshold_says_so():
    runs, _ = study()
    for c in ("a", "b", "c"):
        runs = fail(runs, c, "world_collision", 0.1, seed=1)  # the same runs fail for all
    found, _, diffs = findings(runs)
    assert found == []
    d = diffs[(diffs["kind"] == "world_collision") & (diffs["scope"] == "all")]
    assert (d["difference"] == 0).all() and (d["pairs"] == d["pairs"].iloc[0]).all()
    assert "above the threshold of 5% of its runs" in findings(runs, threshold=0.05)[0][0]


def test_timeouts_are_reported_but_never_unsafe():
    runs, _ = study()
    found, rates, _ = findings(fail(runs, "a", "timeout", 0.5))
    assert found == []
    assert rates[(rates["kind"] == "timeout") & (rates["scope"] == "all")
                 & (rates["controller"] == "a")]["rate"].iloc[0] == pytest.approx(0.5, abs=0.01)


def test_the_card_names_the_failure_and_shows_the_table():
    runs, peds = study(variants=4)
    runs = fail(runs, "a", "pedestrian_collision", 0.3)
    card = card_tables(runs, peds, "a", BASELINES, rng=np.random.default_rng(0), n_boot=100)
    assert card.verdict.label == "unsafe" and "pedestrian collisions" in card.verdict.text
    page = render_html(card, {"study": "s", "part": "main", "check": "skipped", "reused": 0,
                              "executed": 0, "n_runs": 1, "n_errors": 0, "n_cells": 12,
                              "n_populations": 2, "backends": "orca", "mappings": "A",
                              "replay_note": "", "n_boot": 100, "seed": 0, "base_folder": "-",
                              "seed_sets": 1, "safety_threshold": None}, "card.png", None)
    assert "Safety: each failure, against the baselines on the same runs" in page
    assert "difference to the least safe" in page and 'class="bad"' in page


def test_a_pedestrian_walking_into_a_standing_robot_is_not_the_robots_collision():
    runs, _ = study()
    runs = fail(runs, "a", "pedestrian_collision", 0.3)
    hit = (runs["controller"] == "a") & (runs["outcome"] == "pedestrian_collision")
    runs["contact_speed"] = np.where(hit, 0.0, np.nan)  # the robot stood still every time
    found, rates, _ = findings(runs)
    assert found == []
    standing = rates[(rates["kind"] == "standing_contact") & (rates["scope"] == "all")
                     & (rates["controller"] == "a")]["rate"].iloc[0]
    assert standing == pytest.approx(0.3, abs=0.01)
    runs["contact_speed"] = np.where(hit, 0.8, np.nan)  # now it drove into them
    assert findings(runs)[0][0].startswith("pedestrian collisions (robot moving)")
