"""The strict response schema and its validator.

A valid answer is a JSON object::

    {"actions": {"P1": "slow", ..., "P8": "continue"},
     "block": {"clearance": "high", "waiting": "low", ..., "urgency": "medium"}}

with every probe id and every block item present, nothing else, and values from
the enums below. Five levels encode to 0, .25, .5, .75, 1 (SPEC §3).
"""

from __future__ import annotations

import json
import re
from typing import Any

from ..errors import RespondentError
from ..tables import ACTIONS, BLOCK_ITEMS
from .probes import PROBE_IDS

LEVELS: tuple[str, ...] = ("very_low", "low", "medium", "high", "very_high")
LEVEL_VALUE: dict[str, float] = {lv: i / 4 for i, lv in enumerate(LEVELS)}

#: Meaning of each block item's levels, shown to the respondent.
BLOCK_QUESTIONS: dict[str, str] = {
    "clearance": "How much space do you want to keep between yourself and a robot? "
    "(very_low = I pass very close, very_high = I keep a very wide berth)",
    "waiting": "How willing are you to wait for a robot to pass? "
    "(very_low = never wait, very_high = happy to wait)",
    "yielding": "How readily do you give way to a robot? (very_low = never, very_high = always)",
    "gap": "How willing are you to squeeze through a small gap next to a robot? "
    "(very_low = never, very_high = always)",
    "detour": "How willing are you to step off your line to go around a robot? "
    "(very_low = never, very_high = readily)",
    "trust": "How much do you trust a robot to move safely around you? "
    "(very_low = not at all, very_high = completely)",
    "urgency": "How urgently do you need to get where you are going? "
    "(very_low = no hurry at all, very_high = extremely urgent)",
}
assert tuple(BLOCK_QUESTIONS) == BLOCK_ITEMS


def response_json_schema() -> dict[str, Any]:
    """The JSON Schema sent as ``response_format`` (OpenAI) / ``response_schema`` (Gemini)."""
    actions = {
        "type": "object",
        "properties": {pid: {"type": "string", "enum": list(ACTIONS)} for pid in PROBE_IDS},
        "required": list(PROBE_IDS),
        "additionalProperties": False,
    }
    block = {
        "type": "object",
        "properties": {k: {"type": "string", "enum": list(LEVELS)} for k in BLOCK_ITEMS},
        "required": list(BLOCK_ITEMS),
        "additionalProperties": False,
    }
    return {
        "type": "object",
        "properties": {"actions": actions, "block": block},
        "required": ["actions", "block"],
        "additionalProperties": False,
    }


_FENCE = re.compile(r"^\s*```(?:json|JSON)?\s*\n(.*?)\n?\s*```\s*$", re.DOTALL)


def parse_answer(text: str) -> dict[str, Any]:
    """Validate raw respondent text; return ``{"actions": {...}, "block": {...}}``.

    A single surrounding Markdown code fence is tolerated (common with chat
    models); anything else that is not exactly the schema raises
    :class:`RespondentError` with the first problem found.
    """
    if text is None or not str(text).strip():
        raise RespondentError("empty response")
    m = _FENCE.match(text)
    body = m.group(1) if m else text
    try:
        obj = json.loads(body)
    except json.JSONDecodeError as exc:
        # "Unterminated string starting at" ends with "at" already: no "at at char"
        where = exc.msg.removesuffix(" at")
        raise RespondentError(f"response is not valid JSON ({where} at char {exc.pos})") from None
    if not isinstance(obj, dict):
        raise RespondentError("response is not a JSON object")
    _exact_keys(obj, ("actions", "block"), "response")
    actions, block = obj["actions"], obj["block"]
    if not isinstance(actions, dict) or not isinstance(block, dict):
        raise RespondentError("'actions' and 'block' must be objects")
    _exact_keys(actions, PROBE_IDS, "actions")
    _exact_keys(block, BLOCK_ITEMS, "block")
    for pid in PROBE_IDS:
        if actions[pid] not in ACTIONS:
            raise RespondentError(f"actions.{pid}: {actions[pid]!r} is not one of {list(ACTIONS)}")
    for k in BLOCK_ITEMS:
        if block[k] not in LEVELS:
            raise RespondentError(f"block.{k}: {block[k]!r} is not one of {list(LEVELS)}")
    return {
        "actions": {p: actions[p] for p in PROBE_IDS},
        "block": {k: block[k] for k in BLOCK_ITEMS},
    }


def _exact_keys(obj: dict, expected: tuple[str, ...], where: str) -> None:
    missing = [k for k in expected if k not in obj]
    extra = [k for k in obj if k not in expected]
    if missing:
        raise RespondentError(f"{where}: missing key(s) {', '.join(missing)}")
    if extra:
        raise RespondentError(f"{where}: unexpected key(s) {', '.join(map(str, extra))}")


def answer_to_row(answer: dict[str, Any]) -> dict[str, Any]:
    """Flatten a parsed answer into response-table columns (action_1.., q_<item>)."""
    row: dict[str, Any] = {
        f"action_{i}": answer["actions"][pid] for i, pid in enumerate(PROBE_IDS, start=1)
    }
    row.update({f"q_{k}": LEVEL_VALUE[answer["block"][k]] for k in BLOCK_ITEMS})
    return row
