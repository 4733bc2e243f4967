"""Controller outcomes, sensitivity, delay change, noise floor, sanity checks, findings."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from popnavshift.analysis import (
    controller_outcomes,
    delay_change,
    no_robot_checks,
    noise_floor,
    paired_share,
    paper_findings,
    population_sensitivity,
    sensitivity_by_width,
)
from popnavshift.analysis import paper_reference as paper
from popnavshift.analysis.findings import (
    burden_exceeds_time,
    completed_lower,
    tail_ratio,
    width_decreases,
)


def run(controller, outcome, robot_time, clearance=np.nan, population="mixed", episode="e1"):
    return {"episode": episode, "scene": "sidewalk", "width": 1.8, "density": 0.12,
            "robot_speed": 0.6, "variant": 1, "population": population,
            "controller": controller, "backend": "orca", "mapping": "A", "outcome": outcome,
            "robot_time": robot_time, "robot_min_clearance": clearance}


def cell(cell_, pop, ctrl, mean_delay, *, worst=np.nan, scene="sidewalk", width=1.8,
         done=True, blocked=np.nan):
    return {"backend": "orca", "mapping": "A", "cell": cell_, "population": pop,
            "controller": ctrl, "scene": scene, "width": width, "density": 0.12,
            "robot_speed": 0.6, "mean_delay": mean_delay, "worst_decile": worst,
            "blocked_pct": blocked, "robot_time": 20.0, "completed": done}


def test_controller_outcomes_by_hand():
    runs = pd.DataFrame([
        run("reactive", "success", 20.0, 0.5), run("reactive", "success", 30.0, 0.7),
        run("reactive", "timeout", 45.0), run("reactive", "pedestrian_collision", 45.0, 0.9),
        run("robot_orca", "world_collision", 45.0, 0.4), run("zeta", "success", 10.0, 1.0),
        run("none", "none", np.nan),
    ])
    cells = pd.DataFrame([
        cell("c1", "mixed", "reactive", 1.0, worst=4.0, blocked=0.0),
        cell("c1", "high_caution", "reactive", 3.0, worst=8.0, blocked=5.0),
        cell("c2", "mixed", "reactive", np.nan),
        cell("c1", "mixed", "robot_orca", 0.5, worst=1.0),
    ])
    out = controller_outcomes(runs, cells)
    assert out.index.tolist() == ["reactive", "robot_orca", "zeta"]
    r = out.loc["reactive"]
    assert r[["success_pct", "pedestrian_collision_pct", "world_collision_pct",
              "timeout_pct"]].tolist() == [50.0, 25.0, 0.0, 25.0]
    assert r["robot_time"] == 35.0
    assert r["min_clearance"] == pytest.approx(0.7)
    assert r["mean_delay"] == 2.0 and r["worst_decile"] == 6.0 and r["blocked_pct"] == 2.5
    assert r["n_runs"] == 4 and r["n_cells"] == 2
    assert out.loc["robot_orca", "world_collision_pct"] == 100.0
    assert math.isnan(out.loc["zeta", "mean_delay"])
    assert set(paper.CONTROLLER_OUTCOMES["reactive"]) <= set(out.columns)


def test_population_sensitivity_by_hand():
    cells = pd.DataFrame([
        cell("c1", "A", "reactive", 1.0), cell("c1", "B", "reactive", 3.5),
        cell("c1", "C", "reactive", 2.0),
        cell("c1", "A", "early_yield", 1.0), cell("c1", "B", "early_yield", 1.0),
        cell("c1", "C", "early_yield", 1.0),
        cell("c2", "A", "reactive", 0.5, width=4.2), cell("c2", "B", "reactive", 0.7, width=4.2),
        cell("c2", "C", "reactive", np.nan, width=4.2),
        cell("c2", "A", "early_yield", 0.1, width=4.2),
        cell("c2", "B", "early_yield", 0.4, width=4.2),
        cell("c2", "C", "early_yield", 0.2, width=4.2, done=False),
    ])
    sens = population_sensitivity(cells).set_index(["cell", "controller"])
    assert sens.loc[("c1", "reactive"), "sensitivity"] == pytest.approx(2.5)
    assert sens.loc[("c1", "early_yield"), "sensitivity"] == 0.0
    assert math.isnan(sens.loc[("c2", "reactive"), "sensitivity"])  # C has no delay
    assert sens.loc[("c2", "early_yield"), "sensitivity"] == pytest.approx(0.3)
    assert sens.loc[("c1", "reactive"), "completed"]
    assert not sens.loc[("c2", "reactive"), "completed"]
    two = population_sensitivity(cells, populations=["A", "B"]).set_index(["cell", "controller"])
    assert two.loc[("c2", "reactive"), "sensitivity"] == pytest.approx(0.2)

    w = sensitivity_by_width(sens.reset_index()).set_index("width")
    assert w.loc[1.8, "sensitivity"] == pytest.approx(1.25) and w.loc[1.8, "n"] == 2
    assert w.loc[4.2, "sensitivity"] == pytest.approx(0.3) and w.loc[4.2, "n"] == 1
    per = sensitivity_by_width(sens.reset_index(), by=("controller",))
    assert len(per) == 3
    done = sensitivity_by_width(sens.reset_index(), completed_only=True)
    assert done["width"].tolist() == [1.8]
    assert sensitivity_by_width(sens.reset_index(), scenes=("bottleneck",)).empty


def test_delay_change_by_hand():
    cells = pd.DataFrame([
        cell("c1", "homogeneous", "reactive", 1.0), cell("c2", "homogeneous", "reactive", 2.0),
        cell("c1", "mixed", "reactive", 1.5), cell("c2", "mixed", "reactive", 3.0),
        cell("c1", "matched_base", "reactive", 2.0), cell("c2", "matched_base", "reactive", 2.0),
        cell("c1", "matched_deadline", "reactive", 1.0),
        cell("c2", "matched_deadline", "reactive", np.nan),
    ])
    out = delay_change(cells).set_index("population")
    assert out.index.tolist() == ["matched_deadline", "mixed"]
    assert out.loc["mixed", "change"] == pytest.approx(0.75)
    assert out.loc["mixed", "reference"] == "homogeneous"
    assert out.loc["matched_deadline", "change"] == -1.0
    assert out.loc["matched_deadline", "reference"] == "matched_base"
    assert out.loc["matched_deadline", "n_cells"] == 1
    vs_mixed = delay_change(cells, reference="mixed").set_index("population")
    assert vs_mixed.loc["homogeneous", "change"] == pytest.approx(-0.75)


def _ped(population, controller, slot, t, arrived=True):
    return {"episode": "sidewalk-w1.8-d0.12-s0.6-v1", "population": population,
            "controller": controller, "backend": "orca", "mapping": "A", "slot": slot,
            "persona_id": f"{population}-{slot}", "arrived": arrived,
            "travel_time": t if arrived else np.nan, "walk_distance": 1.5 * t}


def test_noise_floor_between_two_halves():
    episode = "sidewalk-w1.8-d0.12-s0.6-v1"
    delays = {"h1": {"reactive": 1.0, "early_yield": 2.0, "robot_orca": 3.0},
              "h2": {"reactive": 2.0, "early_yield": 1.0, "robot_orca": 3.0},
              "other": {"reactive": 9.0, "early_yield": 1.0, "robot_orca": 5.0}}
    times = {"reactive": 20.0, "early_yield": 25.0, "robot_orca": 30.0}
    runs, peds = [], []
    for pop, by_ctrl in delays.items():
        runs.append(run("none", "none", np.nan, population=pop, episode=episode))
        peds.append(_ped(pop, "none", 0, 10.0))
        for ctrl, d in by_ctrl.items():
            runs.append(run(ctrl, "success", times[ctrl], 0.5, population=pop, episode=episode))
            peds.append(_ped(pop, ctrl, 0, 10.0 + d))
    out = noise_floor(pd.DataFrame(runs), pd.DataFrame(peds), ("h1", "h2")).set_index("metric")
    assert out.loc["mean_delay", ["reversals", "comparisons"]].tolist() == [1, 3]
    assert out.loc["worst_decile", "rate"] == pytest.approx(1 / 3)
    assert out.loc["robot_time", "rate"] == 0.0


def test_no_robot_checks_and_stuck_flag():
    a = [_ped("A", "none", k, 10.0 + k) for k in range(19)] + [_ped("A", "none", 19, 0, False)]
    b = [_ped("B", "none", k, 10.0) for k in range(9)] + [_ped("B", "none", 9, 0, False)]
    robot = [_ped("A", "reactive", k, 0, False) for k in range(5)]  # ignored: robot run
    out = no_robot_checks(pd.DataFrame(a + b + robot)).set_index("population")
    assert out.loc["A", "n_peds"] == 20
    assert out.loc["A", "stuck_share"] == 0.05 and not out.loc["A", "stuck_flag"]  # > 5 % only
    assert out.loc["B", "stuck_share"] == pytest.approx(0.1) and out.loc["B", "stuck_flag"]
    assert out.loc["A", "travel_time_mean"] == 19.0 and out.loc["A", "travel_time_p50"] == 19.0
    assert out.loc["A", "speed_mean"] == pytest.approx(1.5)


def test_paired_share():
    peds = pd.DataFrame([_ped("A", "reactive", k, 10.0) for k in range(4)])
    paired = pd.DataFrame({"controller": ["reactive"] * 3, "blocked": [False, True, False]})
    row = paired_share(peds, paired).iloc[0]
    # 4 records: 3 arrived without the robot, 2 of those with it too (paired), 1 blocked
    assert row["n_paired"] == 2 and row["share"] == 0.5
    assert row["n_blocked"] == 1 and row["blocked_share"] == pytest.approx(1 / 3)


def rates(robot, mean, tail):
    return pd.Series({"robot_time": robot, "mean_delay": mean, "worst_decile": tail})


def test_single_findings_hold_and_fail():
    assert burden_exceeds_time(rates(0.09, 0.22, 0.24)).holds
    assert not burden_exceeds_time(rates(0.09, 0.22, 0.05)).holds
    assert completed_lower(rates(0.09, 0.26, 0.25), rates(0.05, 0.21, 0.22)).holds
    assert not completed_lower(rates(0.09, 0.26, 0.25), rates(0.05, 0.27, 0.22)).holds
    w = pd.DataFrame({"width": [4.2, 1.8, 2.4, 3.0], "sensitivity": [0.5, 2.2, 1.0, 1.2]})
    f = width_decreases(w)
    assert f.holds and f.numbers["monotonic"] is False and f.numbers[1.8] == 2.2
    assert not width_decreases(w.assign(sensitivity=[3.0, 2.2, 1.0, 1.2])).holds
    outcomes = pd.DataFrame({"mean_delay": [1.25, 0.65], "worst_decile": [5.13, 2.80]},
                            index=["reactive", "robot_orca"])
    assert tail_ratio(outcomes).holds
    assert not tail_ratio(outcomes.assign(worst_decile=[2.0, 2.8])).holds


def test_paper_findings_on_the_papers_own_numbers():
    rows = []
    for comparison, by_cells in paper.REVERSAL_RATE.items():
        for scope, by_metric in by_cells.items():
            for metric, rate in by_metric.items():
                rows.append({"comparison": comparison, "cells": scope, "metric": metric,
                             "rate": rate})
    table1 = pd.DataFrame(rows)
    outcomes = pd.DataFrame(paper.CONTROLLER_OUTCOMES).T
    ws = paper.WIDTH_SENSITIVITY
    widths = {"pooled": pd.DataFrame({"width": list(ws), "sensitivity": list(ws.values())})}
    sign = paper.MATCHED_CHANGE_SIGN
    change = pd.DataFrame({"controller": list(sign), "population": "matched_deadline",
                           "change": [0.1 * s for s in sign.values()]})
    found = paper_findings(table1, outcomes, widths, change)
    assert len(found) == 12
    failing = [f.statement for f in found if not f.holds]
    assert failing == []
    flipped = change.assign(change=-change["change"])
    assert not paper_findings(table1, outcomes, widths, flipped)[-1].holds
