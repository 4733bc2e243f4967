"""A pilot before the bill: ask a few personas of a study, time the calls, project the rest.

A real model is slow or paid: SmolLM2-135M on one CPU thread takes seconds a call, a
hosted API bills every token. :func:`run_pilot` asks the first ``n`` personas of the
study's own persona draw (and a matched sample scaled to them) with the study's
respondent and samples, in a folder of its own, and builds their Mapping A profiles, so
that ``popnavshift audit --pilot`` can audit them; :func:`projection` turns what the
pilot measured (records asked, calls, their seconds, wall time, tokens) into the calls,
tokens and time of the full study's probe stage at the same pace.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from ..design.study import Study
from ..errors import ConfigError
from ..io import write_parquet
from ..personas.fields import LOW_TIME_PRESSURE
from ..pipeline import PopulationSettings, run_personas, run_profiles, run_responses
from ..responses.respondent import RESPONDENTS
from .runner import population_settings


@dataclass(frozen=True)
class Pilot:
    """What a pilot asked and measured: ``records`` asked (samples included), ``calls``
    made (re-asks and retries included; 0 for records from the cache), ``call_seconds``
    their summed time, ``wall_seconds`` the probe stage's, ``tokens`` summed."""

    folder: Path
    personas: int
    matched: int
    samples: int
    records: int
    cached: int
    calls: int
    call_seconds: float
    wall_seconds: float
    tokens: int
    concurrency: int


def pilot_settings(study: Study, n: int, samples: int | None, full: int) -> PopulationSettings:
    """The study's population settings for a pilot of ``n`` of its ``full`` personas:
    its matched sample scaled to them, mapping A only, no second respondent."""
    s = population_settings(study)
    if n >= full:
        raise ConfigError(f"--pilot {n}: the study asks only {full} personas; a pilot asks "
                          "fewer (say 20 to 50)")
    respondent = (s.respondent if samples is None
                  else s.respondent.model_copy(update={"samples": samples}))
    matched = max(1, round(s.matched_n * n / full))
    return replace(s, respondent=respondent, matched_n=matched, mappings=("A",),
                   respondent2=None, structure=False, nulls=(), null_mappings=())


def run_pilot(study: Study, n: int, folder: Path, samples: int | None = None,
              show_progress: bool = True) -> Pilot:
    """Ask ``n`` personas of ``study`` into ``folder`` (personas — the first ``n`` of the
    study's draw, kept in ``study_personas.parquet`` —, responses, Mapping A profiles, its
    own response cache) and measure the probe stage."""
    full = population_settings(study)
    settings = pilot_settings(study, n, samples, full.personas.n)
    # the study's own draw (kept beside), so the pilot asks its first personas
    everyone = run_personas(folder, full, folder / "study_personas.parquet")
    first = everyone.head(n)
    eligible = int(first["time_pressure"].isin(LOW_TIME_PRESSURE).sum())
    settings = replace(settings, matched_n=max(1, min(settings.matched_n, eligible)))
    write_parquet(first, folder / "personas.parquet")
    started = time.perf_counter()
    run_responses(folder, settings, show_progress)
    wall = time.perf_counter() - started
    run_profiles(folder, settings)
    stats = json.loads((folder / "responses.json").read_text("utf-8"))
    return Pilot(folder, n, settings.matched_n, settings.respondent.samples, stats["records"],
                 stats["cached"], stats["calls"], float(stats.get("call_seconds", 0.0)), wall,
                 int(stats.get("tokens", {}).get("total", 0)),
                 int(settings.respondent.options.get("max_concurrency", 4)))


def projection(pilot: Pilot, study: Study, samples: int | None = None) -> dict[str, Any]:
    """The full study's probe stage at the pilot's pace: ``records`` (personas and matched,
    × samples; a second respondent that is a network model apart, ``second``), ``calls``,
    ``tokens``,
    ``seconds`` (wall, at the same concurrency) and the pilot's ``seconds_per_call``.
    Rates come from the records the pilot actually asked (not its cache hits); None when
    it asked none."""
    s = population_settings(study)
    k = samples if samples is not None else s.respondent.samples
    records = (s.personas.n + s.matched_n) * k
    asked = pilot.records - pilot.cached
    per_call = pilot.call_seconds / pilot.calls if pilot.calls else None
    out: dict[str, Any] = {"records": records, "samples": k, "asked": asked,
                           "seconds_per_call": per_call}
    if asked > 0 and pilot.calls > 0:
        out["calls"] = round(pilot.calls / asked * records)
        out["tokens"] = round(pilot.tokens / asked * records)
        out["seconds"] = pilot.wall_seconds / asked * records
    if s.respondent2 is not None and RESPONDENTS.resolve(s.respondent2.name).uses_cache:
        out["second"] = {"name": s.respondent2.name,  # a network model: its own bill
                         "records": 2 * s.matched_n * s.respondent2.samples}
    return out
