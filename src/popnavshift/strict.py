"""Strict typed settings: the pydantic base and field types every user setting uses.

A study file (:mod:`popnavshift.design.study`) and the stage commands' options
(:class:`popnavshift.pipeline.PopulationSettings`) are validated by the same models, so a
value refused in one is refused in the other. Unknown keys are errors and models are
frozen.
"""

from __future__ import annotations

from typing import Annotated

from pydantic import AfterValidator, BaseModel, ConfigDict, Field

#: seeds feed numpy's SeedSequence and int64 table columns: non-negative, 32 bits
SEED_MAX = 2**32 - 1
#: more personas than this is a typo (the MATRAIX release holds about 100 000)
PERSONAS_MAX = 10_000_000


def no_duplicates(values: tuple | None) -> tuple | None:
    """A listed value twice is a typo or a copy-paste slip, never a design: refuse it
    instead of silently running it once (or twice)."""
    for i, value in enumerate(values or ()):
        if value in values[:i]:  # type: ignore[index]
            raise ValueError(f"{value!r} is listed twice")
    return values


#: strict: YAML's ``true`` is not the seed 1, nor ``1.0`` the seed 1 (silently rounded)
Seed = Annotated[int, Field(strict=True, ge=0, le=SEED_MAX)]
Count = Annotated[int, Field(strict=True, ge=1, le=PERSONAS_MAX)]
Number = Annotated[float, Field(strict=True, allow_inf_nan=False)]
Unique = AfterValidator(no_duplicates)
#: a non-empty list of distinct names
Names = Annotated[tuple[str, ...], Field(min_length=1), Unique]


class Strict(BaseModel):
    """A frozen model that refuses unknown keys: a typo is an error, never a default."""

    model_config = ConfigDict(extra="forbid", frozen=True)
