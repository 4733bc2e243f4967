"""What a worker does with one batch: build each run from the episode spec and simulate.

A run whose controller raises is recorded with outcome ``controller_error`` and the
message in the ``error`` column (:func:`popnavshift.sim.run.failed_result`); the
batch and the study go on. Any other exception is a bug and stops the study.

A run is simulated from its episode, controller, backend and the (n, 7) slot
profiles alone: two runs of a batch with the same controller and bit-equal slot
profiles are the same simulation (a swap permutation that flipped none of an
episode's few pedestrians, a homogeneous population, a perturbation that leaves a
population unchanged). The batch simulates such a run once and gives the others
its rows with their own keys and persona ids (:class:`RunMemo`); the tables are
those of simulating each run.

Workers receive plain data (a batch of run keys, the populations table, the
episode seed), never navground worlds: worlds do not survive pickling
(navground 0.7.0 drops targets and Python scenarios).
"""

from __future__ import annotations

import os
import signal
import sys
import threading
import time
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
import pandas as pd

from ..episodes.specs import EpisodeSpec, get_episode, seed_set_of
from ..populations.identity import PopulationSpec, spec_of
from ..populations.perturb import ProfileSet
from ..sim.run import ControllerError, SimResult, failed_result, pedestrian_table, simulate
from ..sim.slots import SlotProfiles, profiles_of_members
from ..tables import NO_ROBOT
from .batches import Batch
from .rebuild import member_arrays


@dataclass(frozen=True)
class Context:
    populations: pd.DataFrame  # the populations table (all mappings)
    episode_seed: int
    #: the study's populations by name (``Study.population_specs``): their table columns
    specs: Mapping[str, PopulationSpec]


_CONTEXT: Context | None = None


def init_worker(context: Context, parent_pid: int | None = None) -> None:
    global _CONTEXT
    _CONTEXT = context
    if parent_pid is not None:
        exit_with_parent(parent_pid)


#: how often a worker checks that its parent is alive (s)
PARENT_POLL = 0.5


def exit_with_parent(parent_pid: int) -> None:
    """End this worker process when ``parent_pid`` dies (kill -9 included).

    A killed parent never shuts its pool down, and its workers, blocked on the task
    queue, would linger with a few hundred MB each. On Linux the kernel sends
    SIGTERM at the parent's death (``PR_SET_PDEATHSIG``); everywhere, a daemon
    thread checks the parent pid and exits the process once it has changed."""
    if sys.platform.startswith("linux"):
        try:
            import ctypes

            libc = ctypes.CDLL(None, use_errno=True)
            libc.prctl(1, int(signal.SIGTERM))  # 1 = PR_SET_PDEATHSIG
        except (OSError, AttributeError):
            pass
    if os.getppid() != parent_pid:  # the parent died before the line above
        os._exit(1)

    def watch() -> None:
        while os.getppid() == parent_pid:
            time.sleep(PARENT_POLL)
        os._exit(1)

    threading.Thread(target=watch, name="popnavshift-parent-watch", daemon=True).start()


def _members(ctx: Context, mapping: str, population: str) -> tuple[np.ndarray, list[str]]:
    """One population's members sorted by persona id, as the (m, 7) profile array in
    PARAMS order and their persona ids (:func:`.rebuild.member_arrays`); cached per
    worker and context (the slots of a run are then rows of these arrays, see
    :func:`popnavshift.sim.slots.profiles_of_members`)."""
    global _MEMBERS
    if _MEMBERS is None or _MEMBERS[0] is not ctx:
        groups = ctx.populations.groupby(["mapping", "population"], sort=False)
        _MEMBERS = (ctx, {k: member_arrays(g.sort_values("persona_id", kind="stable"))
                          for k, g in groups})
    return _MEMBERS[1][(mapping, population)]


_MEMBERS: tuple[Context, dict] | None = None


class RunMemo:
    """The results of a batch's simulations by what they depend on: the controller id,
    the backend and the bytes of the slot profiles (the episode is the batch's)."""

    def __init__(self) -> None:
        self.results: dict[tuple[str, str, bytes], tuple[SimResult, str | None]] = {}

    @property
    def simulated(self) -> int:
        """How many runs were simulated: one per distinct key."""
        return len(self.results)

    def run(self, spec: EpisodeSpec, slots: SlotProfiles, controller: str,
            backend: str) -> tuple[SimResult, str | None]:
        """(result, error) of ``controller`` on ``slots``: simulated the first time,
        copied (with ``slots``' persona ids) after."""
        key = (controller, backend, slots.values.tobytes())
        hit = self.results.get(key)
        if hit is None:
            ctrl = None if controller == NO_ROBOT else controller
            try:
                hit = simulate(spec, slots, ctrl, backend), None
            except ControllerError as exc:  # one bad run is an outcome, not the end
                hit = failed_result(spec, controller, backend), str(exc)
            self.results[key] = hit
            return hit
        result, error = hit
        if not error:  # a failed run has no pedestrian rows
            result = SimResult(result.run, {**result.ped_columns, "persona_id": slots.persona_ids})
        return result, error


def run_batch(
    batch: Batch, context: Context | None = None
) -> tuple[str, pd.DataFrame, pd.DataFrame, int]:
    """Simulate every run of ``batch``; returns (batch id, runs, pedestrians, number
    of runs simulated: the others repeated one of them, see :class:`RunMemo`)."""
    ctx = context or _CONTEXT
    assert ctx is not None, "worker used before init_worker"
    memo = RunMemo()
    # one episode and one profile set per batch
    profile_set = ProfileSet.parse(batch.mapping).columns()
    seed_set = seed_set_of(batch.episode, ctx.episode_seed)
    spec = get_episode(batch.episode, seed=ctx.episode_seed)
    slots: dict[str, SlotProfiles] = {}  # per population: the same for every controller
    run_rows, ped_columns = [], []
    ped_keys: dict[str, list] = {}
    digests = batch.inputs or (None,) * len(batch.runs)
    for run, run_inputs in zip(batch.runs, digests, strict=True):
        if run.population not in slots:
            values, ids = _members(ctx, batch.mapping, run.population)
            slots[run.population] = profiles_of_members(spec, values, ids)
        result, error = memo.run(spec, slots[run.population], run.controller, run.backend)
        keys = {
            "part": run.part,
            "episode": run.episode,
            "population": run.population,
            **spec_of(ctx.specs, run.population).columns(),
            "controller": run.controller,
            "backend": run.backend,
            "mapping": run.mapping,
            "run_id": run.id,
            "seed_set": seed_set,
            **profile_set,
        }
        run_rows.append({**result.run, **keys, "run_inputs": run_inputs, "error": error})
        ped_columns.append(result.ped_columns)
        for k, value in keys.items():  # one value per run, repeated per pedestrian
            ped_keys.setdefault(k, []).append(value)
    runs = pd.DataFrame(run_rows)
    if not ped_columns:
        return batch.id, runs, pd.DataFrame(), memo.simulated
    peds = pedestrian_table(ped_columns, ped_keys)
    return batch.id, runs, peds, memo.simulated
