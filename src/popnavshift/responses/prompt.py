"""Render a persona and the probes into a prompt (never demographics).

The prompt is part of the request, so it enters the cache key: changing a word
here is a new request. Persona values are rendered through the schema's phrase
templates; they are data and are never interpreted.
"""

from __future__ import annotations

from collections.abc import Mapping

from ..personas.fields import PERSONA_FIELDS, field_catalog, is_demographic
from ..personas.variants import apply_variant
from .probes import PROBES
from .schema import BLOCK_QUESTIONS, LEVELS

SYSTEM_PROMPT = (
    "You role-play a pedestrian described by a persona and answer how you would act "
    "when meeting a mobile robot. Answer only with a JSON object matching the schema."
)


def persona_lines(persona: Mapping[str, object]) -> list[str]:
    """One line per behavioural persona field present (demographics never appear)."""
    catalog = field_catalog()
    lines = []
    for field in PERSONA_FIELDS:
        value = persona.get(field)
        if value is None or (isinstance(value, float) and value != value) or is_demographic(field):
            continue
        spec = catalog[field]
        shown = "none" if value == "None" else value  # the vocabulary's word for no need
        lines.append(f"- {spec['label']}: {spec['phrase'].format(value=shown)}")
    return lines


def build_prompt(persona: Mapping[str, object]) -> str:
    """The user message for one persona: persona, probes, block questions, format."""
    probes = "\n".join(f"{p.id}. {p.text}" for p in PROBES)
    block = "\n".join(f"- {k}: {q}" for k, q in BLOCK_QUESTIONS.items())
    return (
        "Persona:\n" + "\n".join(persona_lines(persona)) + "\n\n"
        "For each encounter, choose the one action you would most likely take: "
        "continue, slow, stop, yield, pass, or detour.\n\n"
        f"Encounters:\n{probes}\n\n"
        f"Then rate yourself on each item with one of {', '.join(LEVELS)}:\n{block}\n\n"
        'Reply with JSON: {"actions": {"P1": ..., "P8": ...}, "block": {"clearance": ..., '
        '"urgency": ...}}.'
    )


def respondent_messages(persona: Mapping[str, object], variant: str) -> tuple[str, str]:
    """(system, user) messages an LLM respondent is sent first for ``persona`` under ``variant``.

    Re-asks after an invalid answer append the model's reply and a correction to
    this conversation; they are not part of it.
    """
    return SYSTEM_PROMPT, build_prompt(apply_variant(persona, variant))
