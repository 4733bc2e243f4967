"""The stages of a study, declared once.

A study folder is built stage by stage: each :class:`Stage` writes one table and
records its *stamp* in ``stages.json``, a hash of the settings that produced it,
chained through the stamp of the stage it reads (``after``). A stage whose stamp
or output is out of date is run again, and so is every stage after it in the
chain (:func:`popnavshift.engine.runner.run_stages`). The runs come last
(:mod:`.plan`, :mod:`.executors`): each run is identified by its own inputs
(:mod:`.run_inputs`: its episode draw, slot profiles and code), never by a stage's
stamp, so a changed stage reruns only the runs whose inputs it changed.

The runner, ``popnavshift evaluate``, the CLI and the benchmarks read this
declaration; the stage functions themselves live in :mod:`popnavshift.pipeline`.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..episodes.specs import all_episodes, episodes_table
from ..hashing import content_digest, digest
from ..io import write_parquet
from ..pipeline import (
    PopulationSettings,
    run_personas,
    run_populations,
    run_profiles,
    run_responses,
)
from ..responses.probes import PROBE_SET_HASH


@dataclass(frozen=True)
class Stage:
    """One stage: its ``name`` (the key in ``stages.json``), the ``table`` it writes in
    the study folder, the stage it reads (``after``, None for a source), what of the
    settings enters its stamp (``settings``) and how it runs (``run``)."""

    name: str
    table: str
    after: str | None
    settings: Callable[[PopulationSettings], list[Any]]
    run: Callable[[Path, PopulationSettings, bool], object]

    def stamp(self, s: PopulationSettings, stamps: Mapping[str, str]) -> str:
        """``digest([name, upstream stamp, *settings])``: the formula every study folder's
        ``stages.json`` was written with (changing it reruns every stage of old folders)."""
        upstream = [stamps[self.after]] if self.after is not None else []
        return digest([self.name, *upstream, *self.settings(s)])


def _persona_settings(s: PopulationSettings) -> list[Any]:
    p = s.personas
    source: list[Any] = [p.source, p.n, s.seed, p.missing]
    if p.source != "synthetic" and Path(p.source).exists():
        source.append(content_digest(p.source))  # an edited file reruns its stage
    release = [p.codebook, p.sources, p.verify_checksums]
    if release != [None, None, True]:  # release options only when set: old stamps stay valid
        source.append(release)
    return source


def _population_settings(s: PopulationSettings) -> list[Any]:
    nulls = [[spec.name for spec in s.nulls], list(s.null_mappings)] if s.nulls else []
    return [s.matched_n, *nulls]


def _response_settings(s: PopulationSettings) -> list[Any]:
    first, second = s.respondent, s.respondent2
    asked = [first.name, first.options, s.matched_n, PROBE_SET_HASH,
             None if second is None else second.name, {} if second is None else second.options]
    samples = (first.samples, 1 if second is None else second.samples)
    # samples only when set: the stamps of one-sample folders stay valid
    return asked if samples == (1, 1) else [*asked, *samples]


def _write_episodes(folder: Path, s: PopulationSettings, _progress: bool) -> None:
    write_parquet(episodes_table(all_episodes(seed=s.seed)), folder / "episodes.parquet")


STAGES: tuple[Stage, ...] = (
    Stage("personas", "personas.parquet", None, _persona_settings,
          lambda folder, s, _progress: run_personas(folder, s)),
    Stage("responses", "responses.parquet", "personas", _response_settings, run_responses),
    Stage("profiles", "profiles.parquet", "responses",
          lambda s: [list(s.mappings), s.structure],
          lambda folder, s, _progress: run_profiles(folder, s)),
    Stage("populations", "populations.parquet", "profiles", _population_settings,
          lambda folder, s, _progress: run_populations(folder, s)),
    Stage("episodes", "episodes.parquet", None, lambda s: [s.seed], _write_episodes),
)


def stage_stamps(s: PopulationSettings) -> dict[str, str]:
    """The stamp every stage of :data:`STAGES` should have under settings ``s``."""
    stamps: dict[str, str] = {}
    for stage in STAGES:
        stamps[stage.name] = stage.stamp(s, stamps)
    return stamps


def legacy_batch_inputs(stamps: Mapping[str, str]) -> str:
    """The stamp of the populations and episode draws that the run tables of a folder
    compacted before runs carried their own inputs were made from (their record's
    ``inputs``), from the folder's stage stamps: such a folder's runs are migrated
    (:meth:`.store.RunStore.legacy_inputs`) only when it matches."""
    return digest([stamps["populations"], stamps["episodes"]])
