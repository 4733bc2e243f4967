"""The stepping loop's helpers: slot order, the robot's goal entry, per-wall distances."""

import math

import numpy as np
import pytest

from popnavshift.episodes import assign_slots, get_episode
from popnavshift.episodes.scenes import distance_to_walls
from popnavshift.errors import InputError
from popnavshift.sim.bench import synthetic_population
from popnavshift.sim.loop import _wall_distances
from popnavshift.sim.pedestrians import entry_fraction
from popnavshift.sim.slots import slot_profiles


def test_slot_rows_in_any_order_give_the_profiles_in_slot_order():
    spec = get_episode("sidewalk-w3.0-d0.2-s1.0-v3")
    slots = assign_slots(spec, synthetic_population(0, size=8))
    values, ids = slot_profiles(spec, slots)
    shuffled = slots.iloc[np.random.default_rng(0).permutation(len(slots))]
    assert shuffled["slot"].tolist() != list(range(spec.n_peds))
    again, ids_again = slot_profiles(spec, shuffled)
    np.testing.assert_array_equal(again, values)
    assert ids_again == ids
    numeric_ids = slots.assign(persona_id=np.arange(spec.n_peds))
    assert slot_profiles(spec, numeric_ids)[1][:3] == ["0", "1", "2"]  # not "0.0"
    with pytest.raises(InputError, match="'slot' must hold"):
        slot_profiles(spec, slots.assign(slot=slots["slot"] + 0.5))


def test_goal_entry_fraction_of_a_step():
    assert entry_fraction(0.0, 0.0, 2.0, 0.0, 2.0, 0.0, 1.0) == 0.5  # enters at x = 1
    assert entry_fraction(2.5, 0.0, 3.0, 0.0, 2.0, 0.0, 1.0) == 0.0  # starts inside
    assert entry_fraction(0.0, 2.0, 4.0, 2.0, 2.0, 0.0, 1.0) == -1.0  # passes by
    assert entry_fraction(0.0, 0.0, 0.5, 0.0, 2.0, 0.0, 1.0) == -1.0  # stops short
    assert entry_fraction(0.0, 0.0, 0.0, 0.0, 2.0, 0.0, 1.0) == -1.0  # stands outside


def test_wall_distances_are_per_wall_and_agree_with_the_nearest_wall():
    walls = [(-1.0, 0.0, 1.0, 0.0), (2.0, 0.0, 3.0, 0.0), (0.0, 3.0, 0.0, 4.0)]
    point = np.array([0.0, 1.0])
    d = _wall_distances(point, walls)
    assert d.tolist() == [1.0, math.sqrt(5.0), 2.0]
    rng = np.random.default_rng(3)
    for p in rng.uniform(-2.0, 4.0, (20, 2)):
        assert _wall_distances(p, walls).min() == distance_to_walls(p[None], walls)[0]
    assert _wall_distances(point, []).shape == (0,)
