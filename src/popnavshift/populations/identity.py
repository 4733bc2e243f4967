"""What a population is, as a typed value: :class:`PopulationSpec`.

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
so a reader of a table selects by them.
Each null design kind is declared once, in :data:`NULL_KINDS`: the role of its populations,
the populations of its replicate k and what a null population of it stands in for.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from typing import Literal

#: the matched time-pressure pair: the same personas, base then deadline profile
MATCHED_PAIR: tuple[str, str] = ("matched_base", "matched_deadline")
#: what a swap null stands in for (its ``base``): the matched pair as a whole
SWAP_BASE = "matched"
#: the two arms of a swap permutation and the two halves of a split
ARMS: tuple[str, str] = ("a", "b")
#: the population every size-matched subset is drawn from (and its own null)
SIZED_SOURCE = "mixed"

Role = Literal["observed", "swap_null", "sized_null", "half"]


@dataclass(frozen=True)
class PopulationSpec:
    """A population: the condition it is, stands in for or halves (``base``; ``matched``
    for a swap null), its ``role``, its null replicate k ≥ 1 (0 unless a null) and its arm
    (``a``/``b`` of a swap permutation or a split; empty otherwise)."""

    base: str
    role: Role = "observed"
    replicate: int = 0
    arm: str = ""

    @classmethod
    def swap(cls, replicate: int, arm: str) -> PopulationSpec:
        """Arm ``a`` or ``b`` of swap permutation ``replicate`` of the matched pair."""
        return cls(SWAP_BASE, "swap_null", int(replicate), arm)

    @classmethod
    def sized(cls, of: str, replicate: int) -> PopulationSpec:
        """Replicate ``replicate`` of the size-matched subset of mixed standing in for ``of``."""
        return cls(of, "sized_null", int(replicate))

    @classmethod
    def half(cls, of: str, arm: str) -> PopulationSpec:
        """Half ``a`` or ``b`` of a seeded random split of ``of``."""
        return cls(of, "half", 0, arm)

    @property
    def name(self) -> str:
        """The population's name in a study file and in the tables."""
        if self.role == "swap_null":
            return f"matched_swap{self.replicate}_{self.arm}"
        if self.role == "sized_null":
            return f"{self.base}_sized{self.replicate}"
        if self.role == "half":
            return f"{self.base}_half_{self.arm}"
        return self.base

    @property
    def is_null(self) -> bool:
        """Whether it is a population of a null design (:data:`NULL_KINDS`)."""
        return any(kind.role == self.role for kind in NULL_KINDS.values())

    def columns(self) -> dict[str, object]:
        """:data:`popnavshift.tables.POPULATION_COLUMNS` of this population."""
        return {"population_role": self.role, "null_replicate": self.replicate}


@dataclass(frozen=True)
class NullKind:
    """A kind of null design (a study part's ``null_design.kind``): the ``role`` of its
    populations; ``replicate(k, populations)``, the populations of its replicate k standing
    in for a part's ``populations`` (none, or a ValueError, when it cannot stand in for
    them); ``stands_for(spec)``, the observed populations one of them stands in for; and
    its replicates in words (``words``: "against 9 swap permutations of their profiles")."""

    role: Role
    replicate: Callable[[int, tuple[str, ...]], tuple[PopulationSpec, ...]]
    stands_for: Callable[[PopulationSpec], tuple[str, ...]]
    words: str


#: Every null design kind, by its name in a study file.
NULL_KINDS: dict[str, NullKind] = {
    "swap": NullKind("swap_null",
                     lambda k, _: tuple(PopulationSpec.swap(k, arm) for arm in ARMS),
                     lambda _: MATCHED_PAIR, "swap permutations of their profiles"),
    "sized": NullKind("sized_null",
                      lambda k, pops: tuple(PopulationSpec.sized(p, k) for p in pops
                                            if p != SIZED_SOURCE),
                      lambda spec: (spec.base,), "size-matched random subsets of mixed"),
}


def null_kind(spec: PopulationSpec) -> str:
    """The name of the null design kind the null population ``spec`` belongs to."""
    return next(name for name, kind in NULL_KINDS.items() if kind.role == spec.role)


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
