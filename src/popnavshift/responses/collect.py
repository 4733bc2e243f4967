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
from ..tables import IDENTITY_COLUMNS, RESPONSES, check_table
from .probes import PROBE_SET_HASH
from .respondent import ProbeRequest, Progress, Respondent
from .schema import answer_to_row


def probe_requests(personas: pd.DataFrame, matched: Sequence[str],
                   samples: int = 1) -> list[ProbeRequest]:
    """Baseline requests for every persona, then deadline requests for ``matched`` ids;
    each ``samples`` times (sample 0 of every record first, then sample 1, …)."""
    records = {str(r["persona_id"]): r for r in personas.to_dict("records")}
    asked = [(pid, "baseline", apply_variant(r, "baseline")) for pid, r in records.items()]
    asked += [(pid, "deadline", apply_variant(records[pid], "deadline")) for pid in matched]
    return [ProbeRequest(pid, v, p, s) for s in range(samples) for pid, v, p in asked]


def collect_responses(
    personas: pd.DataFrame,
    respondent: Respondent,
    matched: Sequence[str] = (),
    progress: Progress | None = None,
    samples: int = 1,
) -> tuple[pd.DataFrame, pd.DataFrame, dict[str, Any]]:
    """Answers for all personas (baseline) and the matched ids (deadline), ``samples``
    independent samples of each (:func:`probe_requests`).

    Returns ``(responses, invalid, stats)``: ``responses`` follows the
    ``responses`` table spec (one row per persona id, variant and sample); ``invalid``
    lists persona_id, variant, sample, error, raw for records that stayed invalid;
    ``stats`` sums calls (and the seconds they took), cache hits and tokens and lists the
    models that answered
    (``served_models``: what the server reports, e.g. a dated version of ``model``).
    """
    requests = probe_requests(personas, matched, samples)
    answers = respondent.answer_all(requests, progress=progress)
    rows, bad = [], []
    stats: dict[str, Any] = {"records": len(answers), "samples": samples, "calls": 0,
                             "cached": 0, "tokens": {}, "call_seconds": 0.0}
    details = served_details(respondent)
    for req, ans in zip(requests, answers, strict=True):
        stats["calls"] += ans.calls
        stats["call_seconds"] += ans.seconds
        stats["cached"] += int(ans.cached)
        for k, v in ans.tokens.items():
            stats["tokens"][k] = stats["tokens"].get(k, 0) + v
        if ans.answer is None:
            bad.append(
                {
                    "persona_id": ans.persona_id,
                    "variant": ans.variant,
                    "sample": req.sample,
                    "error": ans.error or "no answer",
                    "raw": ans.raw,
                }
            )
            continue
        rows.append(
            {
                "persona_id": ans.persona_id,
                "variant": ans.variant,
                "sample": req.sample,
                "respondent": respondent.name,
                "model": respondent.model,
                "served_model": ans.served_model,
                "system_fingerprint": ans.fingerprint,
                **details,
                "probe_set": PROBE_SET_HASH,
                **answer_to_row(ans.answer),
            }
        )
    responses = pd.DataFrame(rows, columns=RESPONSES.names).astype(
        {"persona_id": str, "sample": "int64", "model_size": float, "model_params": float})
    stats["invalid"] = len(bad)
    stats["served_models"] = sorted({a.served_model for a in answers if a.served_model})
    stats["system_fingerprints"] = sorted({a.fingerprint for a in answers if a.fingerprint})
    stats["served"] = {k: v for k, v in details.items() if v is not None}
    invalid = pd.DataFrame(bad, columns=["persona_id", "variant", "sample", "error", "raw"])
    return check_table(responses, "responses"), invalid, stats


def served_details(respondent: Respondent) -> dict[str, Any]:
    """The identity columns of the responses table (model file, size, parameters, server
    build) as the respondent last learned them from its server; None each when it did not
    (the rule respondent, a server that does not say)."""
    told = getattr(respondent, "served_details", None) or {}
    return {k: told.get(k) for k in IDENTITY_COLUMNS}
