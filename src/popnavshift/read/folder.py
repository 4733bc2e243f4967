"""A study folder on disk: its tables and manifest, and the runs of each study part.

``open_study`` opens what ``popnavshift run`` wrote, the stored study configuration
parsed once into its :class:`~popnavshift.design.study.Study`, the tables read on first use;
``main_grid`` selects the study's main part (the paper's design, the part whose role is
``main``, :meth:`StudyFolder.main_part`), and ``part_runs``
the runs of any part on one of its seed sets. Pure selection: the analysis of these runs
lives in :mod:`popnavshift.analysis`, which finds parts by role, never by name.
"""

from __future__ import annotations

import functools
import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

from ..design.part import Part
from ..design.plan import select_episodes
from ..design.study import Study, study_from_dict
from ..episodes.specs import seed_set_id
from ..errors import InputError
from ..populations.build import HALVES, population_order
from ..populations.identity import PopulationSpec
from ..tables import NO_ROBOT


class StudyFolder:
    """A finished study folder, opened once (:func:`open_study`): its manifest and the
    study configuration it stored, parsed into a :class:`Study` (``study``; None when it
    names no part); its tables are read on first use, pedestrians with
    :data:`ANALYSIS_PEDESTRIAN_COLUMNS` only (:func:`stored_pedestrians` reads one run's
    full rows). Every reader of a folder — the analysis, the report, ``evaluate``, the
    audit, ``popnavshift.load`` — goes through it, so the stored study is parsed in one
    place and its main part is the one :meth:`Study.main_part` names."""

    def __init__(self, folder: Path, manifest: dict[str, Any] | None = None,
                 tables: Mapping[str, pd.DataFrame | None] | None = None) -> None:
        self.folder = Path(folder)
        self.manifest = (_read_json(self.folder / "manifest.json") if manifest is None
                         else manifest)
        #: the manifest's study configuration, parsed (None when it names no part)
        self.study: Study | None = stored_study(self.manifest)
        self._tables: dict[str, pd.DataFrame | None] = dict(tables or {})

    def require_run_tables(self) -> None:
        """InputError when ``runs.parquet`` or ``pedestrians.parquet`` is absent, without
        reading either (a command checks this before it starts its progress lines)."""
        for name in ("runs", "pedestrians"):
            if name not in self._tables and not (self.folder / f"{name}.parquet").exists():
                raise InputError(f"study folder {self.folder}: {name}.parquet not found",
                                 hint="run the study first (popnavshift run)")

    def _table(self, name: str) -> pd.DataFrame | None:
        if name not in self._tables:
            path = self.folder / f"{name}.parquet"
            if name in ("runs", "pedestrians"):
                self.require_run_tables()
            if not path.exists():
                self._tables[name] = None
            elif name == "pedestrians":
                self._tables[name] = read_categorical(path, list(ANALYSIS_PEDESTRIAN_COLUMNS))
            else:
                self._tables[name] = pd.read_parquet(path)
        return self._tables[name]

    @property
    def runs(self) -> pd.DataFrame:
        """``runs.parquet`` (InputError when absent)."""
        runs = self._table("runs")
        assert runs is not None
        return runs

    @property
    def pedestrians(self) -> pd.DataFrame:
        """``pedestrians.parquet``, :data:`ANALYSIS_PEDESTRIAN_COLUMNS` only (InputError
        when absent)."""
        peds = self._table("pedestrians")
        assert peds is not None
        return peds

    @property
    def populations(self) -> pd.DataFrame | None:
        return self._table("populations")

    @property
    def episodes(self) -> pd.DataFrame | None:
        return self._table("episodes")

    @functools.cached_property
    def metadata(self) -> dict[str, dict[str, Any]]:
        """``personas.json`` and ``responses.json``, by name."""
        return {n: _read_json(self.folder / f"{n}.json") for n in ("personas", "responses")}

    @property
    def population_specs(self) -> dict[str, PopulationSpec]:
        """The study's populations by name (``Study.population_specs``; empty without a
        study configuration)."""
        return self.study.population_specs() if self.study is not None else {}

    @property
    def seed(self) -> int | None:
        """The study seed, None when the manifest does not say."""
        return self.study.seed if self.study is not None else self.manifest.get(
            "seeds", {}).get("study")

    def main_part(self) -> tuple[str, Part] | None:
        """The (name, part) of the study's main part (:meth:`Study.main_part`: declared or
        named ``main``), None without one."""
        return None if self.study is None else self.study.main_part()


def open_study(folder: Path) -> StudyFolder:
    """The study folder ``folder``, opened: its manifest read and its study parsed now,
    its tables on first use. InputError when the folder does not exist or a JSON file
    the run wrote is damaged."""
    folder = Path(folder)
    if not folder.is_dir():
        raise InputError(f"study folder {folder} not found",
                         hint="give a folder written by `popnavshift run`")
    return StudyFolder(folder)


def stored_study(manifest: Mapping[str, Any]) -> Study | None:
    """The study the manifest stored, its parts in the study file's order (``part_order``;
    the stored JSON's keys are sorted): the one parse of a stored study configuration."""
    cfg = manifest.get("study_config")
    if not (isinstance(cfg, dict) and cfg.get("parts")):
        return None
    order = [n for n in manifest.get("part_order", ()) if n in cfg["parts"]]
    parts = {n: cfg["parts"][n] for n in [*order, *sorted(set(cfg["parts"]) - set(order))]}
    return study_from_dict({**cfg, "parts": parts}, "manifest study_config")


def _read_json(path: Path) -> dict[str, Any]:
    """A JSON object the run wrote ({} when absent); InputError when it is damaged."""
    if not path.exists():
        return {}
    try:
        data = json.loads(path.read_text("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError):
        data = None
    if not isinstance(data, dict):
        raise InputError(f"{path} is damaged (not a JSON object)",
                         hint="run the study again on this folder to rewrite it")
    return data


#: The pedestrian columns the analysis reads (paired delays, no-robot checks, selections).
#: The others (profiles, stop time, detour, clearance, ids) stay on disk: a powered study
#: holds millions of pedestrian rows, and every analysis copy would carry them.
ANALYSIS_PEDESTRIAN_COLUMNS: tuple[str, ...] = (
    "part", "episode", "seed_set", "population", "controller", "backend", "mapping", "slot",
    "persona_id", "arrived", "travel_time", "walk_distance")


def read_categorical(path: Path, columns: list[str]) -> pd.DataFrame:
    """``columns`` of a Parquet table, its string columns as categoricals with sorted
    categories (same order, same groups as ``astype("category")``).

    A powered study's pedestrian table repeats a few hundred ids over millions of rows:
    as categoricals it takes a quarter of the memory, and every analysis copy with it.
    The strings are read as Parquet's dictionaries, never as one string per row
    (which took 170 MB more at the peak for 2 million rows, and 2 s)."""
    schema = pq.read_schema(path)
    text = [c for c in columns
            if pa.types.is_string(schema.field(c).type) or pa.types.is_large_string(
                schema.field(c).type)]
    table = pq.read_table(path, columns=columns, read_dictionary=text)
    frame = {c: _sorted_categorical(table.column(c)) if c in text else table.column(c).to_pandas()
             for c in columns}
    del table
    pa.default_memory_pool().release_unused()  # the decoded pages: give them back now
    return pd.DataFrame(frame)


def _sorted_categorical(column: pa.ChunkedArray) -> pd.Categorical:
    """A dictionary column as a categorical whose categories are sorted (Parquet's
    dictionary is in order of appearance, and differs between row groups)."""
    column = column.unify_dictionaries().combine_chunks()
    values = column.dictionary.to_numpy(zero_copy_only=False).astype(object)
    order = np.argsort(values, kind="stable")
    rank = np.empty(len(order), np.int64)
    rank[order] = np.arange(len(order))
    index = column.indices.fill_null(-1).to_numpy(zero_copy_only=False)
    codes = np.where(index < 0, -1, rank[np.maximum(index, 0)]) if len(rank) else index
    return pd.Categorical.from_codes(codes, categories=pd.Index(values[order], dtype="str"))


def stored_pedestrians(study: StudyFolder, key: dict[str, str]) -> pd.DataFrame:
    """Every column of the stored pedestrian rows of one run (``key``: its RUN_KEY values),
    read from the Parquet file with a filter."""
    filters = [(k, "==", v) for k, v in key.items()]
    return pd.read_parquet(study.folder / "pedestrians.parquet", filters=filters)


def _isin(df: pd.DataFrame, column: str, values) -> pd.Series:
    return df[column].isin(list(values))


def split_halves(populations) -> list[tuple[str, str, str]]:
    """(population, half a, half b) for every pair of split halves (:data:`HALVES`) among
    ``populations``."""
    have = set(map(str, populations))
    pairs = {(str(h.base), h.name, PopulationSpec.half(str(h.base), "b").name)
             for h in HALVES if h.arm == "a"}
    return sorted(p for p in pairs if {p[1], p[2]} <= have)


def is_half(population: pd.Series) -> pd.Series:
    """Whether each population of ``population`` is a split half (:data:`HALVES`)."""
    return population.isin([h.name for h in HALVES])


def main_grid(study: StudyFolder) -> tuple[pd.DataFrame, pd.DataFrame, str]:
    """Runs and pedestrians of the study's main part (:meth:`Study.role`), and a description.

    The part is read from the study configuration: its episodes,
    populations, controllers (plus the no-robot baseline), backends and mapping.
    Split-half populations (for the noise floor) are kept on the same episodes, so the
    floor is at Table I's design (their other seed sets feed the seed-spread section).
    Without a configuration every run is kept.
    """
    runs, peds = study.runs, study.pedestrians
    main = study.main_part()
    if main is None or study.episodes is None:
        return runs, peds, "every run in the folder (the manifest names no study part)"
    name, part = main
    ids = {e.id for e in select_episodes(part.episodes, study.episodes.itertuples(index=False))}
    mappings = part.mappings

    def keep(df: pd.DataFrame) -> pd.DataFrame:
        grid = (_isin(df, "controller", (NO_ROBOT, *part.controllers))
                & _isin(df, "backend", part.backends) & _isin(df, "mapping", mappings))
        on_grid = _isin(df, "episode", ids)  # the paper's design: one seed set
        main = _isin(df, "population", part.populations) | is_half(df["population"])
        return df[grid & on_grid & main]

    runs, peds = keep(runs), keep(peds)
    text = (f"part {name!r}: {runs['episode'].nunique()} episodes, populations "
            f"{', '.join(population_order(runs['population'].unique()))}; controllers "
            f"{', '.join(part.controllers)} and no robot; backend {', '.join(part.backends)}; "
            f"mapping {', '.join(mappings)}")
    return runs, peds, text


def part_runs(study: StudyFolder, name: str, seed: int | None = None
              ) -> tuple[pd.DataFrame, pd.DataFrame] | None:
    """Runs and pedestrians of the study part ``name`` (None when the study has no such
    part, or it has no runs); ``seed`` selects one of the part's extra seed sets
    (default: the study's own). The parts whose role is mapping or structure keep
    Mapping A beside their profile sets, the respondent part the first respondent's pair."""
    spec = study.study
    if spec is None or name not in spec.parts or study.episodes is None:
        return None
    part = spec.parts[name]
    ids = {e.id for e in select_episodes(part.episodes, study.episodes.itertuples(index=False))}
    if seed is not None and seed != spec.seed:
        ids = {seed_set_id(i, seed) for i in ids}
    mappings = set(part.mappings) | (
        {"A"} if spec.role(name) in ("mapping", "structure", "respondent") else set()
    )

    def keep(df: pd.DataFrame) -> pd.DataFrame:
        return df[
            df["episode"].isin(ids)
            & df["population"].isin(part.populations)
            & df["controller"].isin([NO_ROBOT, *part.controllers])
            & df["backend"].isin(part.backends)
            & df["mapping"].isin(mappings)
        ]

    runs = keep(study.runs)
    return None if runs.empty else (runs, keep(study.pedestrians))
