"""Profile sets for the robustness studies (paper §IV-C, §V-D/E).

Every set gets a label in the ``mapping`` column of the populations table, so the
engine and the analysis treat it like a mapping: a run's identity includes it and
controllers are only compared within one set. :class:`ProfileSet` is a label read
once into data; the runs and pedestrians tables carry it as columns. Labels:

* ``A``–``D``: the four mappings (:mod:`popnavshift.profiles.mappings`);
* ``A~reassign``: whole Mapping A profile vectors reassigned among persona ids by a
  seeded permutation before the populations are rebuilt (membership unchanged);
* ``A~shuffle``: within each population, each parameter column permuted
  independently (marginals kept exactly, associations broken);
* ``A~block-<name>``: profiles mapped from responses in which only one response block
  varies across personas and every other answer is set to its population-wide typical
  value (median level; most common action per probe);
* ``A~<respondent>-2``: the matched pair re-profiled from a second respondent.

The structure perturbations (reassign, shuffle, block) are declared once in
:data:`STRUCTURE`: their arguments and how their sets are built. The labels, the study
check and the population pipeline iterate it, so a new kind is one entry and its builder.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
import pandas as pd

from ..errors import ConfigError
from ..hashing import stable_seed
from ..profiles.mappings import build_profiles
from ..tables import (
    ACTION_COLUMNS,
    PARAMS,
    PROFILE_SET_COLUMNS,
    Q_COLUMNS,
    Z_COLUMNS,
    check_table,
)

#: Response blocks for the single-block runs: item columns (and whether actions vary).
BLOCKS: dict[str, tuple[tuple[str, ...], bool]] = {
    "time_pressure": (("q_urgency", "q_waiting"), False),
    "caution": (("q_clearance", "q_yielding", "q_gap", "q_detour"), True),
    "trust": (("q_trust",), False),
}

NO_ARGUMENT: tuple[str, ...] = ("",)


class Sources(NamedTuple):
    """What a structure set built at the profiles stage is made from: Mapping A's
    profiles, the responses (one per persona and variant), the personas, the seed."""

    profiles: pd.DataFrame
    responses: pd.DataFrame
    personas: pd.DataFrame
    seed: int


class Structure(NamedTuple):
    """How the profile sets of one structure perturbation of Mapping A are built: one
    set per argument in ``args`` (:data:`NO_ARGUMENT`: one set, no argument), either at
    the profiles stage (``profiles(sources, arg)``: the set's ``profiles`` rows) or at
    the populations stage (``populations(populations_a, arg, seed)``: the set's
    ``populations`` rows from Mapping A's). Each returns rows labelled with the set's
    label (:func:`label`). ``words``: how a page names one of its sets (``{arg}``: its
    argument, ``_`` as ``-``; default: the set's label, :attr:`ProfileSet.words`)."""

    args: tuple[str, ...] = NO_ARGUMENT
    profiles: Callable[[Sources, str], pd.DataFrame] | None = None
    populations: Callable[[pd.DataFrame, str, int], pd.DataFrame] | None = None
    words: str = ""


@dataclass(frozen=True)
class ProfileSet:
    """A profile set as data: the mapping its profiles come from, how they were
    perturbed, and the perturbation's argument (a block name, the second respondent's
    name; empty otherwise).

    The study file names a set by its label (``A``, ``A~block-caution``, ``A~rule-2``);
    :meth:`parse` reads a label once and :attr:`label` writes it back, so nothing
    downstream splits strings: the runs and pedestrians tables carry :meth:`columns`.
    """

    base: str
    perturbation: str = "none"
    arg: str = ""

    def __post_init__(self) -> None:
        if self.perturbation not in PERTURBATIONS:
            raise ConfigError(f"profile set perturbation {self.perturbation!r}: one of "
                              f"{', '.join(PERTURBATIONS)}")
        if bool(self.arg) != _takes_argument(self.perturbation):
            takes = [k for k in PERTURBATIONS if _takes_argument(k)]
            raise ConfigError(f"profile set {self.perturbation!r}: argument {self.arg!r} "
                              f"({' and '.join(takes)} take one, nothing else does)")

    @classmethod
    def parse(cls, label: str) -> ProfileSet:
        """The set a label names: ``<base>``, ``<base>~<kind>`` or ``<base>~<kind>-<arg>``
        for a kind of :data:`STRUCTURE` (``A~shuffle``, ``A~block-caution``), or
        ``<base>~<respondent>-2``."""
        base, sep, rest = label.partition("~")
        if not sep:
            return cls(base)
        if rest in STRUCTURE and STRUCTURE[rest].args == NO_ARGUMENT:
            return cls(base, rest)
        kind, _, arg = rest.partition("-")
        if kind in STRUCTURE and arg in STRUCTURE[kind].args:
            return cls(base, kind, arg)
        respondent, _, two = rest.rpartition("-")
        if respondent and two == "2":
            return cls(base, "second_respondent", respondent)
        kinds = [f"~{k}" if s.args == NO_ARGUMENT else f"~{k}-<{'|'.join(s.args)}>"
                 for k, s in STRUCTURE.items()]
        raise ConfigError(f"profile set {label!r}: not <mapping>{', '.join(kinds)} "
                          "or ~<respondent>-2")

    @property
    def label(self) -> str:
        """The study file's name of the set (the ``mapping`` column)."""
        if self.perturbation == "none":
            return self.base
        if self.perturbation == "second_respondent":
            return f"{self.base}~{self.arg}-2"
        return f"{self.base}~{self.profile_set}"

    @property
    def profile_set(self) -> str:
        """The ``profile_set`` column: ``original``, ``<kind>`` or ``<kind>-<arg>`` for a
        structure kind (``reassign``, ``shuffle``, ``block-<block>``), or
        ``second_respondent``."""
        if self.perturbation == "none":
            return "original"
        if self.arg and self.perturbation != "second_respondent":
            return f"{self.perturbation}-{self.arg}"
        return self.perturbation

    @property
    def is_structure(self) -> bool:
        return self.perturbation in STRUCTURE

    @property
    def words(self) -> str:
        """How a page names the set: unperturbed, its structure kind's ``words``, else its
        label."""
        if self.perturbation == "none":
            return f"unperturbed (Mapping {self.base})"
        kind = STRUCTURE.get(self.perturbation)
        if kind is None or not kind.words:
            return self.label
        return kind.words.format(arg=self.arg.replace("_", "-"))

    def columns(self) -> dict[str, str]:
        """The set's columns of the runs and pedestrians tables (:data:`PROFILE_SET_COLUMNS`)."""
        values = (self.profile_set, self.base, self.perturbation, self.arg)
        return dict(zip(PROFILE_SET_COLUMNS, values, strict=True))


def label(kind: str, detail: str | None = None, base: str = "A") -> str:
    """The label of ``base`` perturbed by ``kind`` (``detail``: its argument)."""
    return ProfileSet(base, kind, detail or "").label


def reassign_profiles(profiles: pd.DataFrame, seed: int) -> pd.DataFrame:
    """Baseline profile vectors moved to other persona ids by one seeded permutation.

    The multiset of profile vectors is unchanged; which persona carries which vector
    is not. Deadline rows are left as they are (the structure study does not use the
    matched pair).
    """
    out = profiles.copy()
    base = np.flatnonzero((out["variant"] == "baseline").to_numpy())
    ids = out["persona_id"].to_numpy()[base]
    order = np.argsort(ids, kind="stable")  # permutation defined on sorted ids
    rng = np.random.default_rng(stable_seed("reassign", seed))
    perm = rng.permutation(len(base))
    cols = [*PARAMS, *(Z_COLUMNS[p] for p in PARAMS), "caution"]
    values = out[cols].to_numpy(copy=True)
    src = base[order][perm]
    values[base[order]] = out[cols].to_numpy()[src]
    out[cols] = values
    out["mapping"] = label("reassign")
    return check_table(out, "profiles")


def shuffle_columns(populations: pd.DataFrame, seed: int) -> pd.DataFrame:
    """Each parameter column permuted independently within each population."""
    out = populations.copy()
    for name, idx in out.groupby("population", sort=True).indices.items():
        for p in PARAMS:
            rng = np.random.default_rng(stable_seed("shuffle", seed, name, p))
            col = out.columns.get_loc(p)
            out.iloc[idx, col] = out.iloc[idx, col].to_numpy()[rng.permutation(len(idx))]
    out["mapping"] = label("shuffle")
    return check_table(out, "populations")


def single_block_responses(responses: pd.DataFrame, block: str) -> pd.DataFrame:
    """Responses in which only ``block`` varies; all else is set to its typical value."""
    items, actions_vary = BLOCKS[block]
    out = responses.copy()
    base = responses[responses["variant"] == "baseline"]
    for q in Q_COLUMNS:
        if q not in items:
            levels = np.sort(base[q].to_numpy())
            out[q] = float(levels[(len(levels) - 1) // 2])  # a median that is a real level
    if not actions_vary:
        for a in ACTION_COLUMNS:
            out[a] = str(base[a].value_counts().sort_index().idxmax())
    return out


def block_profiles(sources: Sources, block: str) -> pd.DataFrame:
    """Mapping A's profiles of responses in which only ``block`` varies."""
    one = build_profiles(single_block_responses(sources.responses, block), sources.personas, "A")
    return one.assign(mapping=label("block", block))


def with_profile_set_columns(table: pd.DataFrame) -> pd.DataFrame:
    """``table`` with :data:`PROFILE_SET_COLUMNS` filled from its ``mapping`` labels where
    they are absent: rows stored before a column existed are carried, not re-run."""
    present = [c for c in PROFILE_SET_COLUMNS if c in table.columns]
    complete = len(present) == len(PROFILE_SET_COLUMNS)
    if "mapping" not in table.columns or complete and not table[present].isna().any(axis=None):
        return table
    sets = {m: ProfileSet.parse(str(m)).columns() for m in table["mapping"].unique()}
    out = table.copy()
    for column in PROFILE_SET_COLUMNS:
        derived = out["mapping"].map({m: c[column] for m, c in sets.items()})
        out[column] = out[column].fillna(derived) if column in out else derived
    return out


#: The structure perturbations of Mapping A (paper §V-D), in the order their sets are
#: built: what :class:`ProfileSet` parses, :func:`popnavshift.engine.validate.known_mappings`
#: accepts and the population pipeline builds (every set of every kind, when a study part
#: names any). A new kind is one entry and its builder.
STRUCTURE: dict[str, Structure] = {
    "reassign": Structure(profiles=lambda s, _: reassign_profiles(s.profiles, s.seed),
                          words="whole profiles reassigned"),
    "shuffle": Structure(populations=lambda pops, _, seed: shuffle_columns(pops, seed),
                         words="columns shuffled"),
    "block": Structure(tuple(BLOCKS), profiles=block_profiles, words="{arg} block only"),
}
#: the ``perturbation`` of a profile set: how it departs from its base mapping
PERTURBATIONS: tuple[str, ...] = ("none", *STRUCTURE, "second_respondent")


def _takes_argument(perturbation: str) -> bool:
    """Whether a set of ``perturbation`` names an argument (a block, a respondent)."""
    return (perturbation == "second_respondent"
            or STRUCTURE.get(perturbation, Structure()).args != NO_ARGUMENT)
