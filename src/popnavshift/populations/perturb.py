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
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from ..errors import ConfigError
from ..hashing import stable_seed
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


#: the ``perturbation`` of a profile set: how it departs from its base mapping
PERTURBATIONS: tuple[str, ...] = ("none", "reassign", "shuffle", "block", "second_respondent")
#: perturbations of the structure study (built only when a study asks for one)
STRUCTURE_PERTURBATIONS: tuple[str, ...] = ("reassign", "shuffle", "block")


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
        if bool(self.arg) != (self.perturbation in ("block", "second_respondent")):
            raise ConfigError(f"profile set {self.perturbation!r}: argument {self.arg!r} "
                              "(blocks and second respondents take one, nothing else does)")

    @classmethod
    def parse(cls, label: str) -> ProfileSet:
        """The set a label names: ``<base>``, ``<base>~reassign``, ``<base>~shuffle``,
        ``<base>~block-<block>`` or ``<base>~<respondent>-2``."""
        base, sep, rest = label.partition("~")
        if not sep:
            return cls(base)
        if rest in ("reassign", "shuffle"):
            return cls(base, rest)
        kind, _, block = rest.partition("-")
        if kind == "block" and block in BLOCKS:
            return cls(base, "block", block)
        respondent, _, two = rest.rpartition("-")
        if respondent and two == "2":
            return cls(base, "second_respondent", respondent)
        raise ConfigError(f"profile set {label!r}: not <mapping>~reassign, ~shuffle, "
                          f"~block-<{'|'.join(BLOCKS)}> or ~<respondent>-2")

    @property
    def label(self) -> str:
        """The study file's name of the set (the ``mapping`` column)."""
        if self.perturbation == "none":
            return self.base
        if self.perturbation == "block":
            return f"{self.base}~block-{self.arg}"
        if self.perturbation == "second_respondent":
            return f"{self.base}~{self.arg}-2"
        return f"{self.base}~{self.perturbation}"

    @property
    def profile_set(self) -> str:
        """The ``profile_set`` column: ``original``, ``reassign``, ``shuffle``,
        ``block-<block>`` or ``second_respondent``."""
        if self.perturbation == "none":
            return "original"
        return f"block-{self.arg}" if self.perturbation == "block" else self.perturbation

    @property
    def is_structure(self) -> bool:
        return self.perturbation in STRUCTURE_PERTURBATIONS

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
