"""A run's slot profiles: the (n, 7) profile array in PARAMS order and the persona ids.

:func:`slot_profiles` validates what :func:`popnavshift.sim.run.simulate` is given: a
slots table (:func:`popnavshift.episodes.assign_slots`), a :class:`SlotProfiles`
already in array form, or None (every pedestrian the mid-range profile).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from ..episodes.specs import EpisodeSpec, slot_members
from ..errors import InputError
from ..tables import PARAM_RANGES, PARAMS

DEFAULT_PROFILE = {p: (lo + hi) / 2 for p, (lo, hi) in PARAM_RANGES.items()}
# bounds of the slot profile check, PARAMS order
_PARAM_LO = np.array([PARAM_RANGES[p][0] for p in PARAMS]) - 1e-9
_PARAM_HI = np.array([PARAM_RANGES[p][1] for p in PARAMS]) + 1e-9


@dataclass(frozen=True)
class SlotProfiles:
    """Slot profiles already in the loop's form: ``values`` (n, 7) in PARAMS order,
    ``persona_ids`` (n,). What :func:`slot_profiles` makes of a slots table; a study
    worker builds it straight from its cached population arrays
    (:func:`profiles_of_members`), since a DataFrame per run costs more than the
    run's world build in small scenes."""

    values: np.ndarray
    persona_ids: list[str]


def profiles_of_members(spec: EpisodeSpec, values: np.ndarray,
                        persona_ids: list[str]) -> SlotProfiles:
    """The slot profiles of ``spec`` from one population's members sorted by
    persona_id: ``values`` (m, 7) in PARAMS order, ``persona_ids`` (m,); the same
    profiles as ``slot_profiles(spec, assign_slots(spec, members))``."""
    pick = slot_members(spec, len(persona_ids))
    chosen = values[pick]
    _check_profiles(spec, chosen)
    return SlotProfiles(chosen, [persona_ids[i] for i in pick])


def slot_profiles(spec: EpisodeSpec,
                  slots: pd.DataFrame | SlotProfiles | None) -> tuple[np.ndarray, list[str]]:
    """Validated (n, 7) profile array in PARAMS order and the persona ids of the slots."""
    n = spec.n_peds
    if slots is None:
        return np.tile([DEFAULT_PROFILE[p] for p in PARAMS], (n, 1)), ["default"] * n
    if isinstance(slots, SlotProfiles):
        if len(slots.persona_ids) != n or slots.values.shape != (n, len(PARAMS)):
            raise InputError(f"slots for {spec.id}: expected {n} profiles (one per pedestrian), "
                             f"got {len(slots.persona_ids)}")
        return slots.values, slots.persona_ids
    missing = [c for c in ("persona_id", *PARAMS) if c not in slots.columns]
    if missing:
        raise InputError(f"slots for {spec.id}: missing column(s) {', '.join(missing)}")
    if len(slots) != n:
        raise InputError(
            f"slots for {spec.id}: expected {n} rows (one per pedestrian), got {len(slots)}"
        )
    # one column at a time (a multi-column selection or a whole-table to_numpy
    # costs ~10x more)
    values = np.column_stack([slots[p].to_numpy(dtype=np.float64) for p in PARAMS])
    ids = [str(x) for x in slots["persona_id"].tolist()]
    if "slot" in slots.columns:
        slot = slots["slot"].to_numpy()
        if not np.array_equal(slot, np.arange(n)):  # usually already in slot order
            if sorted(slot.tolist()) != list(range(n)):
                raise InputError(f"slots for {spec.id}: column 'slot' must hold 0..{n - 1}")
            order = np.argsort(slot, kind="stable")
            values, ids = values[order], [ids[i] for i in order]
    _check_profiles(spec, values)
    return values, ids


def _check_profiles(spec: EpisodeSpec, values: np.ndarray) -> None:
    """InputError naming the first parameter, then slot, outside its range."""
    bad = ~np.isfinite(values) | (values < _PARAM_LO) | (values > _PARAM_HI)
    if bad.any():
        j = int(np.flatnonzero(bad.any(axis=0))[0])  # first parameter, then first slot
        k = int(np.flatnonzero(bad[:, j])[0])
        lo, hi = PARAM_RANGES[PARAMS[j]]
        raise InputError(
            f"slots for {spec.id}: {PARAMS[j]} = {float(values[k, j])} at slot {k} "
            f"is not a number in [{lo}, {hi}]"
        )
