"""Batches: the planned runs of one episode under one backend and profile set, the unit a
worker simulates (it builds the episode spec once) and the store keeps as one shard.

A batch's id hashes its runs' keys and the digest of each one's own inputs
(:mod:`.run_inputs`), so a shard is reused exactly when every run in it would be
simulated from the same inputs.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass

from ..design.plan import Run
from ..hashing import digest


@dataclass(frozen=True)
class Batch:
    episode: str
    backend: str
    mapping: str
    runs: tuple[Run, ...]
    #: each run's digest of its own inputs (:func:`.run_inputs.run_inputs`), in run order
    inputs: tuple[str, ...] = ()

    @property
    def id(self) -> str:
        """Stable id of the batch's runs and their inputs (its shard file name): a shard
        made from other slot profiles, episode draws or code never matches."""
        return digest([[list(r.key), i] for r, i in zip(self.runs, self.inputs or
                                                         ("",) * len(self.runs), strict=True)])[:20]


def batches(runs: Iterable[Run], inputs: Mapping[tuple, str] | None = None) -> list[Batch]:
    """Group runs by (episode, backend, mapping), keeping plan order; ``inputs`` gives each
    run's digest of its own inputs (:func:`.run_inputs.run_inputs`: its slot profiles,
    episode draw and code), so a batch's id changes when any of its runs' inputs does."""
    groups: dict[tuple[str, str, str], list[Run]] = {}
    for r in runs:
        groups.setdefault((r.episode, r.backend, r.mapping), []).append(r)
    return [Batch(e, b, m, tuple(rs), tuple(inputs[r.key] for r in rs) if inputs else ())
            for (e, b, m), rs in groups.items()]
