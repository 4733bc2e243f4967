"""Stage 2 function: ask a respondent about every persona (and matched variant).

``collect_responses`` is pure with respect to files: caching lives inside the
network respondents, progress is a callback. Invalid records are returned in a
separate table with the reason — never dropped silently, never replaced.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import pandas as pd

from ..personas.variants import apply_variant
from ..tables import RESPONSES, check_table
from .probes import PROBE_SET_HASH
from .respondent import ProbeRequest, Progress, Respondent
from .schema import answer_to_row


def probe_requests(personas: pd.DataFrame, matched: Sequence[str]) -> list[ProbeRequest]:
    """Baseline requests for every persona, then deadline requests for ``matched`` ids."""
    records = {str(r["persona_id"]): r for r in personas.to_dict("records")}
    reqs = [
        ProbeRequest(pid, "baseline", apply_variant(r, "baseline")) for pid, r in records.items()
    ]
    reqs += [
        ProbeRequest(pid, "deadline", apply_variant(records[pid], "deadline")) for pid in matched
    ]
    return reqs


def collect_responses(
    personas: pd.DataFrame,
    respondent: Respondent,
    matched: Sequence[str] = (),
    progress: Progress | None = None,
) -> tuple[pd.DataFrame, pd.DataFrame, dict[str, Any]]:
    """Answers for all personas (baseline) and the matched ids (deadline).

    Returns ``(responses, invalid, stats)``: ``responses`` follows the
    ``responses`` table spec (one row per persona id and variant); ``invalid``
    lists persona_id, variant, error, raw for records that stayed invalid;
    ``stats`` sums calls, cache hits and tokens and lists the models that answered
    (``served_models``: what the server reports, e.g. a dated version of ``model``).
    """
    answers = respondent.answer_all(probe_requests(personas, matched), progress=progress)
    rows, bad = [], []
    stats: dict[str, Any] = {"records": len(answers), "calls": 0, "cached": 0, "tokens": {}}
    for ans in answers:
        stats["calls"] += ans.calls
        stats["cached"] += int(ans.cached)
        for k, v in ans.tokens.items():
            stats["tokens"][k] = stats["tokens"].get(k, 0) + v
        if ans.answer is None:
            bad.append(
                {
                    "persona_id": ans.persona_id,
                    "variant": ans.variant,
                    "error": ans.error or "no answer",
                    "raw": ans.raw,
                }
            )
            continue
        rows.append(
            {
                "persona_id": ans.persona_id,
                "variant": ans.variant,
                "respondent": respondent.name,
                "model": respondent.model,
                "served_model": ans.served_model,
                "probe_set": PROBE_SET_HASH,
                **answer_to_row(ans.answer),
            }
        )
    responses = pd.DataFrame(rows, columns=_response_columns())
    stats["invalid"] = len(bad)
    stats["served_models"] = sorted({a.served_model for a in answers if a.served_model})
    invalid = pd.DataFrame(bad, columns=["persona_id", "variant", "error", "raw"])
    return check_table(responses.astype({"persona_id": str}), "responses"), invalid, stats


def _response_columns() -> list[str]:

    return RESPONSES.names
