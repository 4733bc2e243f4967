"""Paired delays and cell metrics on tiny hand-made tables (every number known)."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from popnavshift.analysis import (
    cell_key,
    cell_metrics,
    controller_outcomes,
    paired_delays,
    tail_count,
    worst_decile,
)
from popnavshift.analysis.delay import cvar
from popnavshift.episodes.specs import Cell
from popnavshift.errors import InputError
from popnavshift.tables import TIME_LIMIT
from synth_study import no_effect, synthetic_study

SIDEWALK = ("sidewalk", 1.8, 0.12, 0.6)
NARROW = "sidewalk-w1.8-d0.12-s0.6"


def episode(cell=SIDEWALK, variant=1) -> str:
    return f"{cell_key(*cell)}-v{variant}"


def ped(slot, arrived, t, dist=None, *, controller="reactive", population="mixed",
        backend="orca", variant=1, persona=None):
    return {
        "part": "main", "episode": episode(variant=variant), "population": population,
        "controller": controller, "backend": backend, "mapping": "A", "slot": slot,
        "persona_id": persona or f"p{slot}", "arrived": arrived,
        "travel_time": t if arrived else np.nan,
        "walk_distance": dist if dist is not None else (t or 0.0) * 1.2,
    }


def run(controller, outcome, robot_time, *, cell=SIDEWALK, variant=1, population="mixed"):
    scene, width, density, speed = cell
    return {
        "part": "main", "episode": episode(cell, variant), "scene": scene, "width": width,
        "density": density, "robot_speed": speed, "variant": variant, "population": population,
        "controller": controller, "backend": "orca", "mapping": "A", "outcome": outcome,
        "robot_time": robot_time,
    }


def test_cell_key_matches_episode_cells_even_for_numpy_floats():
    key = cell_key("sidewalk", np.float64(1.8), np.float64(0.12), np.float64(0.6))
    assert key == NARROW
    assert key == Cell("sidewalk", 1.8, 0.12, 0.6).key


def test_a_delay_only_when_both_runs_arrived_blocked_pedestrians_kept_without_one():
    peds = pd.DataFrame([
        # baseline (no robot)
        ped(0, True, 10.0, 12.0, controller="none"),
        ped(1, True, 11.0, controller="none"),
        ped(2, False, np.nan, 3.0, controller="none"),
        ped(3, True, 9.0, 10.0, controller="none"),
        ped(5, False, np.nan, 3.0, controller="none"),
        # the same slot under another population or backend must not be used
        ped(1, True, 5.0, controller="none", population="high_caution"),
        ped(1, True, 5.0, controller="none", backend="hl"),
        # robot run
        ped(0, True, 12.5, 13.0),
        ped(1, False, np.nan, 4.0),  # blocked: arrived without the robot, not with it
        ped(2, True, 15.0),  # baseline: not arrived, so no added delay is defined
        ped(3, True, 8.5, 10.5),  # faster with the robot: negative delay kept
        ped(4, True, 20.0),  # no baseline row
        ped(5, False, np.nan, 2.0),  # arrived in neither run
    ])
    out = paired_delays(peds)
    assert out["slot"].tolist() == [0, 1, 3]
    assert out["blocked"].tolist() == [False, True, False]
    # SPEC §7: a delay only when both arrived; the blocked pedestrian has none
    assert out["delay"].tolist()[0::2] == pytest.approx([2.5, -0.5])
    assert out["added_distance"].tolist()[0::2] == pytest.approx([1.0, 0.5])
    assert math.isnan(out["delay"].iloc[1]) and math.isnan(out["added_distance"].iloc[1])
    assert set(out["controller"]) == {"reactive"}
    assert "part" not in out.columns


def test_the_records_are_the_same_pedestrians_under_every_controller():
    """Which pedestrians a cell's delays average over depends on the baseline only."""
    peds = pd.DataFrame([ped(s, s != 2, 10.0 + s, controller="none") for s in range(4)]
                        + [ped(s, s != 1, 12.0 + s, controller="reactive") for s in range(4)]
                        + [ped(s, True, 11.0 + s, controller="robot_orca") for s in range(4)])
    out = paired_delays(peds)
    slots = out.groupby("controller")["slot"].apply(list).to_dict()
    assert slots == {"reactive": [0, 1, 3], "robot_orca": [0, 1, 3]}
    assert out.groupby("controller")["blocked"].sum().to_dict() == {"reactive": 1,
                                                                    "robot_orca": 0}


def test_paired_delays_pair_each_controller_with_the_shared_baseline():
    peds = pd.DataFrame([
        ped(0, True, 10.0, controller="none"),
        ped(0, True, 11.0, controller="reactive"),
        ped(0, True, 13.0, controller="robot_orca"),
    ])
    out = paired_delays(peds).set_index("controller")["delay"]
    assert out.to_dict() == pytest.approx({"reactive": 1.0, "robot_orca": 3.0})


def test_paired_delays_reject_duplicates_and_broken_slot_assignment():
    dup = pd.DataFrame([ped(0, True, 10.0, controller="none")] * 2 + [ped(0, True, 11.0)])
    with pytest.raises(InputError, match="duplicate"):
        paired_delays(dup)
    mismatch = pd.DataFrame([ped(0, True, 10.0, controller="none", persona="a"),
                             ped(0, True, 11.0, persona="b")])
    with pytest.raises(InputError, match="persona"):
        paired_delays(mismatch)


@pytest.mark.parametrize(("n", "k"), [(0, 0), (1, 1), (9, 1), (10, 1), (11, 2), (20, 2),
                                      (21, 3), (30, 3)])
def test_tail_count_is_ceil_of_a_tenth(n, k):
    assert tail_count(n) == k == math.ceil(n / 10)


def test_worst_decile_by_hand():
    assert worst_decile(np.arange(1.0, 11.0)) == 10.0  # n = 10 → the largest 1
    assert worst_decile(np.arange(11.0, 0.0, -1.0)) == 10.5  # n = 11 → mean of 11 and 10
    assert worst_decile(np.arange(1.0, 31.0)) == 29.0  # n = 30 → mean of 28, 29, 30
    assert math.isnan(worst_decile(np.array([])))


def _paired(controller, variant, delays, blocked=()):
    """Records of one run; those at positions ``blocked`` have no delay (NaN)."""
    return pd.DataFrame({
        "episode": episode(variant=variant), "population": "mixed", "controller": controller,
        "backend": "orca", "mapping": "A", "slot": range(len(delays)), "persona_id": "p",
        "blocked": [i in blocked for i in range(len(delays))],
        "delay": [np.nan if i in blocked else d for i, d in enumerate(delays)],
        "added_distance": [np.nan if i in blocked else d / 2 for i, d in enumerate(delays)],
    })


def test_cell_metrics_pool_variants():
    wide = ("bottleneck", 4.2, 0.2, 1.0)
    runs = pd.DataFrame([
        run("reactive", "success", 20.0, variant=1),
        run("reactive", "success", 22.0, variant=2),
        run("reactive", "timeout", 45.0, variant=3),
        run("early_yield", "success", 30.0, variant=1),
        run("early_yield", "success", 31.0, variant=2),
        run("early_yield", "success", 32.0, variant=3),
        run("none", "none", np.nan, variant=1),
        run("reactive", "pedestrian_collision", 45.0, cell=wide),
    ])
    # reactive: delays 1..10 spread over the variants (4 + 3 + 3) and one blocked
    # pedestrian (its 99 is never read); none for early_yield
    paired = pd.concat([_paired("reactive", 1, [1.0, 2.0, 3.0, 4.0]),
                        _paired("reactive", 2, [5.0, 6.0, 7.0, 99.0], blocked=(3,)),
                        _paired("reactive", 3, [8.0, 9.0, 10.0])], ignore_index=True)
    out = cell_metrics(runs, paired).set_index(["cell", "controller"])
    assert len(out) == 3  # the no-robot run is not a controller
    r = out.loc[(NARROW, "reactive")]
    assert r["n_runs"] == 3
    assert r["robot_time"] == pytest.approx(29.0)
    assert r["success_share"] == pytest.approx(2 / 3)
    assert not r["completed"]
    assert r["n_paired"] == 10 and r["n_blocked"] == 1
    assert r["blocked_pct"] == pytest.approx(100 / 11)  # 1 of the 11 that arrived without it
    assert r["mean_delay"] == pytest.approx(5.5)
    assert r["worst_decile"] == pytest.approx(10.0)  # ⌈1.0⌉ = 1 → the largest paired delay
    assert r["mean_added_distance"] == pytest.approx(55 / 20)
    e = out.loc[(NARROW, "early_yield")]
    assert e["completed"]
    assert e["success_share"] == 1.0
    assert e["n_paired"] == 0 and e["n_blocked"] == 0
    assert math.isnan(e["mean_delay"]) and math.isnan(e["worst_decile"])
    assert math.isnan(e["blocked_pct"])
    w = out.loc[("bottleneck-w4.2-d0.2-s1.0", "reactive")]
    assert w["robot_time"] == 45.0 and not w["completed"]
    assert w["width"] == 4.2 and w["scene"] == "bottleneck"


def test_cell_metrics_from_pedestrians_end_to_end():
    runs = pd.DataFrame([run("reactive", "success", 20.0), run("none", "none", np.nan)])
    peds = pd.DataFrame([ped(s, True, 10.0 + s, controller="none") for s in range(10)]
                        + [ped(s, True, 10.0 + 2 * s) for s in range(10)])
    out = cell_metrics(runs, paired_delays(peds)).iloc[0]
    assert out["n_paired"] == 10
    assert out["mean_delay"] == pytest.approx(4.5)  # delays 0..9
    assert out["worst_decile"] == pytest.approx(9.0)


def test_cell_metrics_reject_an_episode_in_two_cells():
    a = run("reactive", "success", 20.0)
    b = {**run("early_yield", "success", 20.0), "width": 2.4}
    with pytest.raises(InputError, match="episode"):
        cell_metrics(pd.DataFrame([a, b]), _paired("reactive", 1, [1.0]))


# --- blocked pedestrians: their own metric, the delays as SPEC defines them -----------------


def _with_blocked(k: int):
    """A synthetic study where controller ``a`` blocks the pedestrians of slots < k in every
    episode (they do not arrive with it), ``b`` lets the same ones arrive 0.01 s before the
    limit, and ``c`` walks everyone as generated."""
    runs, peds = synthetic_study({"p": no_effect, "q": no_effect}, n_cells=2, variants=3,
                                 n_peds=12)
    chosen = peds["slot"] < k
    a, b = chosen & (peds["controller"] == "a"), chosen & (peds["controller"] == "b")
    peds.loc[a, ["arrived", "travel_time"]] = [False, np.nan]
    peds.loc[b, "travel_time"] = TIME_LIMIT - 0.01
    return runs, peds


def _survivors_reference(runs: pd.DataFrame, peds: pd.DataFrame) -> pd.DataFrame:
    """The delay metrics by their definition before blocked pedestrians were counted
    (SPEC §7), written independently: pair the pedestrians that arrived in both runs,
    pool a cell's variants, then mean, worst decile and CVaR-90 of the pooled delays."""
    arrived = peds[peds["arrived"]]
    key = ["episode", "population", "backend", "mapping", "slot"]
    base = arrived[arrived["controller"] == "none"][[*key, "travel_time"]]
    robot = arrived[arrived["controller"] != "none"]
    both = robot.merge(base, on=key, suffixes=("", "_base"))
    both["delay"] = both["travel_time"] - both["travel_time_base"]
    cells = runs[["episode", "scene", "width", "density", "robot_speed"]].drop_duplicates()
    cells["cell"] = [cell_key(*r) for r in cells.iloc[:, 1:].itertuples(index=False)]
    both = both.merge(cells[["episode", "cell"]], on="episode")
    g = both.groupby(["backend", "mapping", "cell", "population", "controller"])["delay"]
    return pd.DataFrame({"n_paired": g.size(), "mean_delay": g.mean(),
                         "worst_decile": g.agg(worst_decile), "cvar90": g.agg(cvar)})


def test_delay_metrics_are_the_survivor_definition_and_blocked_ones_their_own_metric():
    runs, peds = _with_blocked(k=2)
    cells = cell_metrics(runs, paired_delays(peds)).set_index(
        ["backend", "mapping", "cell", "population", "controller"])
    ref = _survivors_reference(runs, peds)
    assert len(ref) == len(cells) == 2 * 2 * 3
    for col in ("mean_delay", "worst_decile", "cvar90"):
        np.testing.assert_allclose(cells[col], ref.loc[cells.index, col], rtol=1e-12,
                                   err_msg=col)
    assert (cells["n_paired"] == ref.loc[cells.index, "n_paired"]).all()
    by = cells.groupby("controller")
    # a blocks 2 of 12 pedestrians in each of 3 variants: 6 of the 36 that arrived without it
    assert by["n_blocked"].sum().to_dict() == {"a": 24, "b": 0, "c": 0}
    assert by["blocked_pct"].apply(list).to_dict() == {
        "a": pytest.approx([100 * 6 / 36] * 4), "b": [0.0] * 4, "c": [0.0] * 4}
    assert (cells.loc[cells.index.get_level_values("controller") == "a", "n_paired"] == 30).all()
    # survivors only, a reads lighter than b on the delays: blocked_pct is what shows it
    assert (by["mean_delay"].mean()["a"] < by["mean_delay"].mean()["b"])
    table2 = controller_outcomes(runs, cells.reset_index())
    assert table2.at["a", "blocked_pct"] == pytest.approx(100 * 6 / 36)
    assert table2.at["c", "blocked_pct"] == 0.0


def test_a_blocked_record_never_enters_the_delay_statistics():
    """Dropping the blocked pedestrians' rows altogether gives bit-identical delay
    metrics: only ``n_blocked`` and ``blocked_pct`` see them."""
    runs, peds = _with_blocked(k=3)
    cols = ["n_paired", "mean_delay", "worst_decile", "cvar90", "mean_added_distance"]
    full = cell_metrics(runs, paired_delays(peds))
    gone = peds[peds["arrived"] | (peds["controller"] == "none")]
    without = cell_metrics(runs, paired_delays(gone))
    pd.testing.assert_frame_equal(full[cols], without[cols])
    assert full["n_blocked"].sum() == 3 * 3 * 4 and without["n_blocked"].sum() == 0
