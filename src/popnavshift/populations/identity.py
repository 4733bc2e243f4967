"""What a population is, as a typed value: :class:`PopulationSpec`; and every kind of null
design, declared once with its behaviour: :data:`NULL_KINDS`.

A study runs four kinds of population: the conditions it compares (``observed``), the
replicates of its null designs (``swap_null``: an arm of a swap permutation of the
matched pair; ``sized_null``: a size-matched random subset of ``mixed`` standing in for
one condition) and the split halves of the noise floor (``half``). Their names
(``matched_swap7_a``, ``high_caution_sized3``, ``mixed_half_b``) are written in one place
(:attr:`PopulationSpec.name`) and never read back: a spec comes from what declares it —
a condition or a split half from the registry (:data:`popnavshift.populations.build.KNOWN`),
a null replicate from its study part's null design (:data:`NULL_KINDS`) — and a study's
populations are looked up by name in its index (``Study.population_specs``). The runs and
pedestrians tables carry the role and the replicate as columns (:meth:`PopulationSpec.columns`),
so a reader of a table selects by them. A null population stands in for one population or
for a pair of them: its ``base`` holds the one name or the pair, never a name to split.

A null design kind (:class:`NullKind`) is one :data:`NULL_KINDS` entry: the role of its
populations, their names, the populations of its replicate k, how their members are drawn
from the study's records (:class:`Records`), which of them stand in for an observed pair
of a headline comparison, and its labels. The study file's kinds, the population stage,
the headline's nulls, the calibration and the report iterate it.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from typing import Literal, NamedTuple

import numpy as np
import pandas as pd

from ..hashing import stable_seed
from .nulls import sized_subset, swap_variants

#: the matched time-pressure pair: the same personas, base then deadline profile
MATCHED_PAIR: tuple[str, str] = ("matched_base", "matched_deadline")
#: the two arms of a swap permutation and the two halves of a split
ARMS: tuple[str, str] = ("a", "b")
#: the population every size-matched subset is drawn from (and its own null)
SIZED_SOURCE = "mixed"

Role = Literal["observed", "swap_null", "sized_null", "half"]
#: members of a population: (persona_id, variant) pairs, sorted by persona id
Members = list[tuple[str, str]]


@dataclass(frozen=True)
class PopulationSpec:
    """A population: the condition it is, halves or stands in for (``base``: one name, or
    the pair a null of a pair stands in for), its ``role``, its null replicate k ≥ 1 (0
    unless a null) and its arm (``a``/``b`` of a permutation or a split; empty otherwise)."""

    base: str | tuple[str, ...]
    role: Role = "observed"
    replicate: int = 0
    arm: str = ""

    @classmethod
    def swap(cls, replicate: int, arm: str) -> PopulationSpec:
        """Arm ``a`` or ``b`` of swap permutation ``replicate`` of the matched pair."""
        return cls(MATCHED_PAIR, "swap_null", int(replicate), arm)

    @classmethod
    def sized(cls, of: str, replicate: int) -> PopulationSpec:
        """Replicate ``replicate`` of the size-matched subset of mixed standing in for ``of``."""
        return cls(of, "sized_null", int(replicate))

    @classmethod
    def half(cls, of: str, arm: str) -> PopulationSpec:
        """Half ``a`` or ``b`` of a seeded random split of ``of``."""
        return cls(of, "half", 0, arm)

    @property
    def bases(self) -> tuple[str, ...]:
        """The populations it is, halves or stands in for: ``base`` as a tuple."""
        return (self.base,) if isinstance(self.base, str) else tuple(self.base)

    @property
    def name(self) -> str:
        """The population's name in a study file and in the tables."""
        if self.is_null:
            return null_kind(self).name(self)
        if self.role == "half":
            return f"{self.base}_half_{self.arm}"
        return str(self.base)

    @property
    def is_null(self) -> bool:
        """Whether it is a population of a null design (:data:`NULL_KINDS`)."""
        return any(kind.role == self.role for kind in NULL_KINDS.values())

    def columns(self) -> dict[str, object]:
        """:data:`popnavshift.tables.POPULATION_COLUMNS` of this population."""
        return {"population_role": self.role, "null_replicate": self.replicate}


class Records(NamedTuple):
    """What a null population's members are drawn from: ``members(spec)``, the members of
    any population of the study (``PopulationSpec(name)`` for a condition), and the study
    ``seed``."""

    members: Callable[[PopulationSpec], Members]
    seed: int

    def rng(self, *key: object) -> np.random.Generator:
        """A generator seeded by ``key`` and the study seed (the same draw in every process)."""
        return np.random.default_rng(stable_seed(key[0], self.seed, *key[1:]))

    def ids(self, population: str) -> list[str]:
        """The persona ids of the condition ``population``, sorted."""
        return [pid for pid, _ in self.members(PopulationSpec(population))]


Pair = tuple[PopulationSpec, PopulationSpec]


@dataclass(frozen=True)
class NullKind:
    """A kind of null design (a study part's ``null_design.kind``).

    ``role``: the role of its populations; ``name(spec)``: the name of one of them;
    ``replicate(k, populations)``: the populations of its replicate k standing in for a
    part's ``populations`` (a ValueError saying why when it cannot stand in for them);
    ``members(spec, records)``: how one of them is drawn from the study's records;
    ``pair(observed, k)``: its two populations standing in for the observed pair in
    replicate k of a headline comparison (None when it stands in for no such pair);
    ``same_personas``: whether the two populations of a replicate hold the very personas
    of the pair, differing by chance alone (a crossover between them is then a false
    positive, and it can be the null of the matched pair on its own); ``stands_for``: the
    populations it always stands in for (a part's are those; empty: the part's own).
    Labels: ``words``, its replicates in words ("against 9 swap permutations of their
    profiles"); ``crossover``, the calibration's claim for a crossover between its
    populations; ``listed``, how the populations section lists them (default: ``words``).
    """

    role: Role
    name: Callable[[PopulationSpec], str]
    replicate: Callable[[int, tuple[str, ...]], tuple[PopulationSpec, ...]]
    members: Callable[[PopulationSpec, Records], Members]
    pair: Callable[[tuple[str, str], int], Pair | None]
    words: str
    crossover: str
    listed: str = ""
    same_personas: bool = False
    stands_for: tuple[str, ...] = ()


def _swap_members(spec: PopulationSpec, records: Records) -> Members:
    ids = records.ids(MATCHED_PAIR[0])
    coins = records.rng("swap", spec.replicate)  # one draw for both arms
    return list(zip(ids, swap_variants(ids, spec.arm, coins), strict=True))


def _sized_members(spec: PopulationSpec, records: Records) -> Members:
    size = len(records.members(PopulationSpec(spec.base)))
    rng = records.rng("sized", str(spec.base), spec.replicate)
    return [(pid, "baseline") for pid in sized_subset(records.ids(SIZED_SOURCE), size, rng)]


def _sized_replicate(k: int, populations: tuple[str, ...]) -> tuple[PopulationSpec, ...]:
    out = tuple(PopulationSpec.sized(p, k) for p in populations if p != SIZED_SOURCE)
    if not out:
        raise ValueError(f"a sized null stands in for populations other than "
                         f"{SIZED_SOURCE!r} (its own size-matched subset), got {list(populations)}")
    return out


def _sized_pair(pair: tuple[str, str], k: int) -> Pair:
    def sub(p: str) -> PopulationSpec:
        return PopulationSpec(p) if p == SIZED_SOURCE else PopulationSpec.sized(p, k)

    return sub(pair[0]), sub(pair[1])


def _swap_pair(pair: tuple[str, str], k: int) -> Pair | None:
    if set(pair) != set(MATCHED_PAIR):
        return None
    return PopulationSpec.swap(k, ARMS[0]), PopulationSpec.swap(k, ARMS[1])


#: Every null design kind, by its name in a study file; where several stand in for an
#: observed pair, the headline takes the first the study ran (the most specific first).
NULL_KINDS: dict[str, NullKind] = {
    "swap": NullKind(
        "swap_null", lambda s: f"matched_swap{s.replicate}_{s.arm}",
        lambda k, _: tuple(PopulationSpec.swap(k, arm) for arm in ARMS),
        _swap_members, _swap_pair, "swap permutations of their profiles",
        "a crossover between swap arms",
        listed="swap permutations of the matched pair (2 arms each)",
        same_personas=True, stands_for=MATCHED_PAIR),
    "sized": NullKind(
        "sized_null", lambda s: f"{s.base}_sized{s.replicate}", _sized_replicate,
        _sized_members, _sized_pair,
        "size-matched random subsets of mixed (matched in size, not in dispersion)",
        "a crossover among sized subsets",
        listed="size-matched random subsets of mixed (one per cohort)"),
}


def null_kind(spec: PopulationSpec) -> NullKind:
    """The null design kind the null population ``spec`` belongs to."""
    return next(kind for kind in NULL_KINDS.values() if kind.role == spec.role)


def null_populations(kind: str, replicates: int,
                     populations: tuple[str, ...]) -> tuple[PopulationSpec, ...]:
    """The populations of a null design: replicates 1 … ``replicates`` of its kind
    (:data:`NULL_KINDS`) standing in for ``populations``."""
    return tuple(spec for k in range(1, replicates + 1)
                 for spec in NULL_KINDS[kind].replicate(k, populations))


def index_of(specs: Iterable[PopulationSpec]) -> dict[str, PopulationSpec]:
    """Specs by name; a name two different specs would share is an error (a condition
    registered under a name a null replicate also writes)."""
    out: dict[str, PopulationSpec] = {}
    for spec in specs:
        if out.setdefault(spec.name, spec) != spec:
            raise ValueError(f"population name {spec.name!r} is both {out[spec.name]} and "
                             f"{spec}: rename the condition")
    return out


def spec_of(specs: Mapping[str, PopulationSpec], name: str) -> PopulationSpec:
    """The spec of population ``name`` in a study's index; a name it does not hold (a
    condition of a table read without its study) is an observed condition."""
    return specs.get(name) or PopulationSpec(name)


def with_population_columns(table: pd.DataFrame,
                            specs: Mapping[str, PopulationSpec]) -> pd.DataFrame:
    """``table`` with the population columns (:meth:`PopulationSpec.columns`) filled where
    they are absent, from the study's index ``specs`` (rows stored before the columns
    existed are carried, not re-run)."""
    if "population" not in table.columns or (
            "population_role" in table.columns and table["population_role"].notna().all()):
        return table
    cols = {p: spec_of(specs, str(p)).columns() for p in table["population"].unique()}
    out = table.copy()
    for column in ("population_role", "null_replicate"):
        derived = out["population"].map({p: c[column] for p, c in cols.items()})
        out[column] = out[column].fillna(derived) if column in out else derived
    out["null_replicate"] = out["null_replicate"].astype("int64")
    return out
