"""What a run is simulated from, as one digest per run: the run's own inputs.

A run of episode e, population p, controller c, backend b and profile set m is
simulated from the episode's spec (its id and the study seed it is drawn with), the
(n, 7) profiles and persona ids of the pedestrians in its slots, the code the run
executes (:func:`.stamps.run_code_stamp`: the simulator, navground and the controller)
and the backend. :func:`run_inputs` hashes exactly that, for every planned run, and
nothing else: not the populations table as a whole, not the other runs, not the
study's parts. So adding or removing populations, null replicates, seed sets or
controllers leaves every other run's digest as it was, and ``run`` simulates exactly
the runs whose digest the study tables do not hold yet (``runs.parquet``'s
``run_inputs`` column; :meth:`.store.RunStore.carried`).

A population's slot profiles are those the worker simulates
(:func:`popnavshift.sim.slots.profiles_of_members`: its members sorted by persona id,
slot k takes member ⌊u_k · n⌋), so two runs with bit-equal slots and the same code
share a digest, as the worker's :class:`.worker.RunMemo` shares their simulation.
"""

from __future__ import annotations

import hashlib
from collections.abc import Iterable, Mapping

import numpy as np
import pandas as pd

from ..design.plan import Run
from ..episodes.specs import EpisodeSpec, get_episode, slot_members
from .rebuild import member_arrays

#: (episode, population, controller, backend, mapping): a run's key (``Run.key``)
Key = tuple[str, str, str, str, str]
#: length of a run's digest in hex digits (64 bits: no two of a study's runs collide)
DIGEST_HEX = 16


class SlotIndex:
    """The slot profiles of (episode, profile set, population) as digests, from a
    populations table, computed once each."""

    def __init__(self, populations: pd.DataFrame, episode_seed: int) -> None:
        self.episode_seed = int(episode_seed)
        groups = populations.groupby(["mapping", "population"], sort=False)
        self._members = {k: g for k, g in groups}
        self._arrays: dict[tuple[str, str], tuple[np.ndarray, list[str]]] = {}
        self._specs: dict[str, EpisodeSpec] = {}
        self._digests: dict[tuple[str, str, str], str | None] = {}

    def _member_arrays(self, mapping: str, population: str):
        key = (mapping, population)
        if key not in self._arrays:
            members = self._members.get(key)
            if members is None:
                return None
            self._arrays[key] = member_arrays(members.sort_values("persona_id", kind="stable"))
        return self._arrays[key]

    def digest(self, episode: str, mapping: str, population: str) -> str | None:
        """Hex sha256 of the slots' profile bytes (PARAMS order) and persona ids; None
        when the table holds no such population under that profile set."""
        key = (episode, mapping, population)
        if key not in self._digests:
            arrays = self._member_arrays(mapping, population)
            if arrays is None or not len(arrays[1]):
                self._digests[key] = None
            else:
                values, ids = arrays
                if episode not in self._specs:
                    self._specs[episode] = get_episode(episode, seed=self.episode_seed)
                pick = slot_members(self._specs[episode], len(ids))
                h = hashlib.sha256(np.ascontiguousarray(values[pick]).tobytes())
                h.update("\0".join(ids[i] for i in pick).encode("utf-8"))
                self._digests[key] = h.hexdigest()
        return self._digests[key]


def run_digest(episode_seed: int, key: Key, slots: str, code: str) -> str:
    """The digest of one run: its key's episode, backend and profile set, the study seed
    its episode is drawn with, its slots' digest and its code stamp."""
    episode, _population, _controller, backend, mapping = key
    text = "\0".join((str(int(episode_seed)), episode, backend, mapping, slots, code))
    return hashlib.sha256(text.encode("utf-8")).hexdigest()[:DIGEST_HEX]


def run_inputs(runs: Iterable[Run | Key], populations: pd.DataFrame, episode_seed: int,
               code: Mapping[str, str]) -> dict[Key, str]:
    """``{run key: digest of its own inputs}`` for every run of ``runs`` (plans or keys)
    whose population ``populations`` holds under its profile set; ``code`` is the code
    stamp of each controller id (:func:`.stamps.code_stamps`). A run whose population or
    controller stamp is absent gets no digest (it is never carried)."""
    index = SlotIndex(populations, episode_seed)
    out: dict[Key, str] = {}
    for run in runs:
        key: Key = run.key if isinstance(run, Run) else run
        episode, population, controller, _backend, mapping = key
        slots = index.digest(episode, mapping, population)
        stamp = code.get(controller)
        if slots is not None and stamp is not None:
            out[key] = run_digest(episode_seed, key, slots, stamp)
    return out


__all__ = ["DIGEST_HEX", "Key", "SlotIndex", "run_digest", "run_inputs"]
