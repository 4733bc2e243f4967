"""Rebuild one stored run from its key: the episode drawn again, the population's
members placed in its slots, the controller and backend made by name.

A study worker (:mod:`.worker`) builds every run this way, with each
population's members cached as arrays; the report's replays, ``popnavshift
evaluate``'s card and ``popnavshift simulate``/``replay`` rebuild one run with
:func:`rebuild_run`. Both go through :func:`member_arrays` and
:func:`popnavshift.sim.slots.profiles_of_members`, so a rebuilt run is the
stored one, bit for bit.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
import pandas as pd

from ..episodes.specs import get_episode
from ..errors import InputError
from ..sim.run import SimResult, simulate
from ..sim.slots import profiles_of_members
from ..tables import PARAMS


def population_members(populations: pd.DataFrame, mapping: str, population: str) -> pd.DataFrame:
    """The rows of one population under one profile set, sorted by persona_id (the
    order slots pick members in); InputError when the table has none."""
    members = populations[(populations["mapping"] == mapping)
                          & (populations["population"] == population)]
    if members.empty:
        raise InputError(f"the populations table has no {population!r} for profile set "
                         f"{mapping!r}")
    return members.sort_values("persona_id", kind="stable")


def member_arrays(members: pd.DataFrame) -> tuple[np.ndarray, list[str]]:
    """Members sorted by persona id as the (m, 7) profile array in PARAMS order and
    their persona ids (one column at a time: a multi-column ``to_numpy`` costs more)."""
    values = np.column_stack([members[p].to_numpy(dtype=np.float64) for p in PARAMS])
    return values, [str(x) for x in members["persona_id"].tolist()]


def rebuild_run(key: Mapping[str, str], populations: pd.DataFrame, seed: int, *,
                record: bool = False) -> SimResult:
    """Simulate the run ``key`` (episode, population, controller, backend, mapping) of
    a study with seed ``seed`` again; ``record`` adds the trajectory for a replay.
    Raises what :func:`popnavshift.sim.run.simulate` raises (a ControllerError for a
    run stored as ``controller_error``)."""
    spec = get_episode(key["episode"], seed=seed)
    members = population_members(populations, key["mapping"], key["population"])
    slots = profiles_of_members(spec, *member_arrays(members))
    return simulate(spec, slots, key["controller"], key["backend"], record=record)
