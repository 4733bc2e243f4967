"""Planned runs → batches → execution → compacted tables: the one sequence ``run`` and
``evaluate`` share.

:func:`plan_batches` groups planned runs into the batches of :func:`.plan.batches`
under the folder's inputs stamp and the code stamps of their controllers (so both
commands give a batch the same id and reuse each other's shards), and knows which
batches have no finished shards yet; :func:`run_plan` executes those
(:func:`.executors.execute`) and compacts every batch into the store's two tables.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import NamedTuple

import pandas as pd

from ..design.plan import Run
from .batches import Batch, batches
from .executors import execute
from .run_inputs import Key, run_inputs
from .stamps import code_stamps
from .store import RunStore
from .worker import Context


@dataclass(frozen=True)
class BatchPlan:
    """Planned ``runs`` with the digest of each one's own inputs (``inputs``), the runs
    the store's compacted tables already hold with that digest (``carried``: not run
    again), the batches of the others (``batches``) and those without finished shards
    (``todo``). ``carry``: whether the compacted tables are the study's, to be carried by
    the next plan (``run``; ``evaluate`` compacts its runs apart and carries none)."""

    runs: list[Run]
    inputs: dict[Key, str]
    carried: set[tuple]
    batches: list[Batch]
    todo: list[Batch]
    carry: bool

    @property
    def reused(self) -> int:
        """Planned runs not executed: carried, or in a batch whose shards are done."""
        return len(self.runs) - self.to_execute

    @property
    def to_execute(self) -> int:
        """Planned runs ``run_plan`` executes: those of the batches without shards."""
        return sum(len(b.runs) for b in self.todo)


def plan_batches(runs: list[Run], store: RunStore, populations: pd.DataFrame,
                 episode_seed: int, *, carry: bool = True,
                 stored: dict[Key, str] | None = None, check_only: bool = False) -> BatchPlan:
    """``runs`` with the digests of their own inputs, from the ``populations`` table and
    the study's ``episode_seed``: a changed slot profile or episode draw, an edited
    controller (which keeps its name) or simulator gives a run a new digest, and its batch
    a new id. ``stored``: the digests of the stored runs when the tables predate the
    ``run_inputs`` column (:meth:`.store.RunStore.legacy_inputs`). ``check_only``: leave
    invalid shards in place (``plan`` only counts)."""
    code = code_stamps(r.controller for r in runs)
    inputs = run_inputs(runs, populations, episode_seed, code)
    missing = [r for r in runs if r.key not in inputs]
    if missing:  # the runner checks the populations first: a bug if reached
        raise ValueError(f"no slot profiles for run {missing[0].key} in the populations table")
    carried = store.carried(inputs, stored) if carry else set()
    all_batches = batches([r for r in runs if r.key not in carried], inputs)
    todo = [b for b in all_batches if not store.is_done(b, clean=not check_only)]
    return BatchPlan(runs, inputs, carried, all_batches, todo, carry)


class PlanResult(NamedTuple):
    """What :func:`run_plan` did: runs executed and simulated (the others repeated an
    identical run), the seconds the execution took, the compacted tables' row counts."""

    executed: int
    simulated: int
    seconds: float
    n_runs: int
    n_peds: int


def run_plan(plan: BatchPlan, store: RunStore, context: Context, workers: int, *,
             executor_name: str = "local", address: str | None = None,
             show_progress: bool = True) -> PlanResult:
    """Execute the plan's ``todo`` batches into ``store`` (no executor is started when
    there are none), then compact every batch, with the carried runs, into its tables."""
    started = time.perf_counter()
    executed = simulated = 0
    if plan.todo:
        executed, simulated = execute(plan.todo, store, context, workers,
                                      executor_name=executor_name, address=address,
                                      show_progress=show_progress)
    seconds = time.perf_counter() - started
    n_runs, n_peds = store.compact_files(plan.batches, plan.runs, plan.carried, plan.inputs,
                                         context.specs, record=plan.carry)
    return PlanResult(executed, simulated, seconds, n_runs, n_peds)
