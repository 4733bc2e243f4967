"""Who the personas are and who answers: a study's ``personas:`` and ``respondent:``, as
the strict models a study file and the stage commands both fill."""

from __future__ import annotations

from typing import Annotated, Any, Literal

from pydantic import Field, field_validator

from ..strict import Count, Strict, Unique


class PersonaSource(Strict):
    """Where the personas come from and how many (a study's ``personas:``)."""

    source: str = "synthetic"
    n: Count = 600
    missing: Literal["require", "fill", "error"] = "require"
    codebook: str | None = None  # release only: codebook file of another layout
    sources: Annotated[tuple[str, ...] | None, Unique] = None  # release only: sources kept
    #: release only: check the shards against manifest.json
    verify_checksums: Annotated[bool, Field(strict=True)] = True


class RespondentSpec(Strict):
    """Who answers the probes (a study's ``respondent:``): a registered respondent, its
    options and the independent samples per persona and variant."""

    name: str = "rule"
    options: dict[str, Any] = Field(default_factory=dict)
    #: independent samples per persona and variant, each sent with its own seed; the
    #: profiles read their per-item median (docs/method.md), the audit their test–retest
    samples: int = Field(1, ge=1, le=100, strict=True)  # `true` is not 1

    @field_validator("options")
    @classmethod
    def _no_replicate(cls, v: dict[str, Any]) -> dict[str, Any]:
        if "replicate" in v:  # it changed only the cache key: a sample that was not one
            raise ValueError("options.replicate was removed (it changed the cache key, not "
                             "the request); ask independent samples with `samples: k`, "
                             "each sent with its own seed")
        return v
