"""Stage 5: cells, seeded episode specs, geometry and slot assignment."""

import dataclasses
import math

import numpy as np
import pandas as pd
import pytest

from popnavshift.episodes import (
    DENSITIES,
    PED_RADIUS,
    WIDTHS,
    all_cells,
    all_episodes,
    assign_slots,
    episodes_table,
    get_episode,
    layout,
    make_episode,
    pedestrian_count,
)
from popnavshift.episodes.scenes import ROUTE_LENGTH, distance_to_walls
from popnavshift.episodes.specs import ROBOT_KEEP_OUT
from popnavshift.errors import InputError, UnknownNameError
from popnavshift.hashing import stable_seed
from popnavshift.tables import PARAMS


@pytest.fixture(scope="module")
def episodes():
    return all_episodes(seed=0)


def test_104_cells_and_312_episodes_with_head_on_at_lowest_density_only(episodes):
    cells = all_cells()
    assert len(cells) == 104 and len({c.key for c in cells}) == 104
    head_on = [c for c in cells if c.scene == "head_on"]
    assert len(head_on) == 8 and {c.density for c in head_on} == {DENSITIES[0]}
    assert len(episodes) == 312 and len({e.id for e in episodes}) == 312
    assert {e.variant for e in episodes} == {1, 2, 3}
    assert get_episode("sidewalk-w1.8-d0.12-s0.6-v1").id == "sidewalk-w1.8-d0.12-s0.6-v1"
    assert all(e.n_peds == 1 for e in episodes if e.scene == "head_on")


def test_pedestrian_count_is_density_times_band_area(episodes):
    # band = last 20 m before an exit; checked by hand for three shapes
    assert layout("sidewalk", 2.4).walkable_area == pytest.approx(20 * 2.4)
    assert layout("obstruction", 3.0).walkable_area == pytest.approx(20 * 3.0 - math.pi * 0.16)
    # bottleneck w = 1.8: 4.2 m wide on x∈[4, 8] and [16, 24], tapers avg 3 m, 1.8 m on [10, 14]
    bottleneck = 12 * 4.2 + 2 * 2 * 3.0 + 4 * 1.8
    assert layout("bottleneck", 1.8).walkable_area == pytest.approx(bottleneck)
    for e in episodes:
        rounded = max(1, math.floor(e.density * e.walkable_area + 0.5))
        assert e.n_peds == (1 if e.scene == "head_on" else rounded)
    # densities grow the crowd, and the densest wide sidewalk has 17 pedestrians
    table = episodes_table(episodes)
    wide = table[(table.scene == "sidewalk") & (table.width == WIDTHS[-1])]
    assert wide.groupby("density").n_peds.max().tolist() == [5, 10, 17]
    assert pedestrian_count(all_cells()[0], 0.1) == 1


def test_initial_states_never_overlap(episodes):
    for e in episodes:
        starts = np.array(e.ped_starts)
        if len(starts) > 1:
            gaps = np.linalg.norm(starts[:, None] - starts[None], axis=2) + np.eye(len(starts)) * 9
            assert gaps.min() >= 2 * PED_RADIUS + 0.1 - 1e-9, e.id
        assert np.linalg.norm(starts - np.array(e.robot_start), axis=1).min() >= ROBOT_KEEP_OUT
        assert distance_to_walls(starts, e.walls).min() >= PED_RADIUS + 0.05 - 1e-9, e.id
        for x, y, r in e.obstacles:
            assert np.hypot(starts[:, 0] - x, starts[:, 1] - y).min() >= r + PED_RADIUS, e.id
        assert distance_to_walls(np.array([e.robot_start]), e.walls)[0] > 0.35


def test_routes_end_past_exits_and_start_within_the_band(episodes):
    for e in episodes:
        starts, dirs = np.array(e.ped_starts), np.array(e.ped_directions)
        progress = np.einsum("ij,ij->i", starts, dirs)
        to_exit = np.array(e.ped_exits) - progress
        assert (to_exit > 0).all() and (to_exit <= ROUTE_LENGTH + 1e-9).all(), e.id
        goals = np.einsum("ij,ij->i", np.array(e.ped_goals), dirs)
        assert np.allclose(goals, np.array(e.ped_exits) + 2.0)
        assert e.passing_side in (-1, 1)
        assert all(0.0 <= u < 1.0 for u in e.slot_draws) and len(e.slot_draws) == e.n_peds
    sidewalk = [e for e in episodes if e.scene == "sidewalk" and e.n_peds >= 4]
    assert all({d[0] for d in e.ped_directions} == {-1.0, 1.0} for e in sidewalk)  # both flows
    crossing = [e for e in episodes if e.scene == "crossing"]
    assert all(d[0] == 0.0 for e in crossing for d in e.ped_directions)  # they walk along y
    assert all(e.ped_vias == e.ped_goals for e in episodes if e.scene != "obstruction")
    rerouted = [
        (e, k) for e in episodes for k in range(e.n_peds) if e.ped_vias[k] != e.ped_goals[k]
    ]
    assert rerouted and all(e.scene == "obstruction" for e, _ in rerouted)
    for e, k in rerouted:  # the via point leaves the pedestrian clear of the obstacle
        ox, oy, r = e.obstacles[0]
        assert abs(e.ped_vias[k][1] - oy) >= r + PED_RADIUS + 0.2 - 1e-9


def test_seeds_come_from_a_stable_hash_and_the_study_seed_matters():
    cell = all_cells()[7]
    a, b = make_episode(cell, 2, seed=0), make_episode(cell, 2, seed=0)
    assert a == b
    assert a.seed == stable_seed("episode", 0, cell.scene, cell.width, cell.density,
                                 cell.robot_speed, 2)
    other = make_episode(cell, 2, seed=1)
    assert other.ped_starts != a.ped_starts and other.seed != a.seed
    assert make_episode(cell, 3, seed=0).ped_starts != a.ped_starts


def test_unknown_episode_suggests_close_ids():
    with pytest.raises(UnknownNameError, match="did you mean") as err:
        get_episode("sidewalk-w1.8-d0.12-s0.6-v4")
    assert "sidewalk-w1.8-d0.12-s0.6-v1" in str(err.value)


def test_episodes_table_has_one_typed_row_per_episode(episodes):
    table = episodes_table(episodes)
    assert list(table.columns[:7]) == [
        "id", "scene", "width", "density", "robot_speed", "variant", "n_peds"
    ]
    assert len(table) == 312 and table.id.is_unique
    assert table.n_peds.dtype == np.int64 and table.width.dtype == np.float64
    assert table.groupby("scene").size().to_dict() == {
        "bottleneck": 72, "crossing": 72, "head_on": 24, "obstruction": 72, "sidewalk": 72,
    }


def _members(population: str, ids: list[str], offset: float) -> pd.DataFrame:
    rows = []
    for m, pid in enumerate(ids):
        rows.append({"population": population, "member": m, "persona_id": pid,
                     "variant": "baseline", "mapping": "A", "speed_mps": 0.7 + offset + 0.01 * m,
                     "clearance_m": 0.5, "avoidance_gain": 1.0, "yield_fraction": 0.5,
                     "reaction_delay_s": 0.5, "detour_distance_m": 2.0, "gap_acceptance": 0.5})
    return pd.DataFrame(rows)


def test_slot_k_gets_member_floor_u_k_times_n_of_the_sorted_members():
    spec = get_episode("sidewalk-w4.2-d0.2-s1.0-v2")
    ids = [f"p{i:03d}" for i in range(37)]
    members = _members("mixed", ids, 0.0).sample(frac=1.0, random_state=3)  # shuffled rows
    slots = assign_slots(spec, members)
    expected = [ids[math.floor(u * len(ids))] for u in spec.slot_draws]
    assert slots.persona_id.tolist() == expected
    assert slots.slot.tolist() == list(range(spec.n_peds))
    assert set(PARAMS) <= set(slots.columns)


def test_matched_base_and_deadline_put_the_same_persona_in_every_slot():
    spec = get_episode("bottleneck-w3.0-d0.2-s0.6-v3")
    ids = [f"m{i:03d}" for i in range(50)]
    base = _members("matched_base", ids, 0.0)
    deadline = _members("matched_deadline", list(reversed(ids)), 0.5).iloc[::-1]
    a, b = assign_slots(spec, base), assign_slots(spec, deadline)
    assert a.persona_id.tolist() == b.persona_id.tolist()
    assert (b.speed_mps.to_numpy() > a.speed_mps.to_numpy()).all()  # same people, shifted profiles
    homogeneous = _members("homogeneous", ["median"], 0.0)
    assert set(assign_slots(spec, homogeneous).persona_id) == {"median"}


def test_assign_slots_rejects_bad_member_tables():
    spec = get_episode("head_on-w1.8-d0.06-s0.6-v1")
    with pytest.raises(InputError, match="missing column"):
        assign_slots(spec, pd.DataFrame({"persona_id": ["a"]}))
    two = pd.concat([_members("a", ["x"], 0.0), _members("b", ["y"], 0.0)])
    with pytest.raises(InputError, match="one population"):
        assign_slots(spec, two)
    with pytest.raises(InputError, match="empty"):
        assign_slots(spec, _members("a", [], 0.0).reindex(columns=_members("a", ["x"], 0).columns))


def test_specs_are_frozen_plain_data():
    spec = get_episode("crossing-w2.4-d0.12-s1.0-v3")
    with pytest.raises(dataclasses.FrozenInstanceError):
        spec.width = 3.0  # type: ignore[misc]
    d = spec.to_dict()
    assert d["id"] == spec.id and isinstance(d["ped_starts"], tuple)
    assert hash(spec) == hash(get_episode("crossing-w2.4-d0.12-s1.0-v3"))
