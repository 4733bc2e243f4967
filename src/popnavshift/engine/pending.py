"""What ``run`` would simulate on a study folder, counted without simulating or writing.

:func:`pending_runs` plans the study as :func:`.runner.run_study` does (the same run
digests, :mod:`.run_inputs`; the same carried runs and finished shards,
:func:`.batch_plan.plan_batches`) and returns how many runs ``run`` would execute. When
only the populations stage would run again (a part's null design, populations or
seeds changed) the populations table is built in memory, as the stage would build it;
when a stage before it would run again (other personas, answers or profiles), what the
runs are simulated from is not known until it has run, and the count says so.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from ..design.plan import plan_study
from ..design.study import Study
from ..episodes.specs import all_episodes
from ..pipeline import build_populations, read_table
from ..read.checks import read_stamps, readable_parquet
from .batch_plan import plan_batches
from .runner import population_settings, stored_inputs
from .stages import STAGES, stage_stamps
from .store import RunStore


@dataclass(frozen=True)
class Pending:
    """``planned`` distinct runs; ``execute``: how many ``run`` would execute (None when a
    stage before the populations would run again: ``stale`` names it); ``kept``: runs the
    folder already holds with the same inputs (stored or in finished shards)."""

    planned: int
    execute: int | None
    kept: int
    stale: str | None = None


def pending_runs(study: Study, folder: Path) -> Pending:
    """What ``run`` of ``study`` would simulate in ``folder`` (see the module doc)."""
    folder = Path(folder)
    runs = plan_study(study, all_episodes(seed=study.seed))
    settings = population_settings(study)
    done, want = read_stamps(folder), stage_stamps(settings)
    for stage in STAGES:
        if stage.name == "populations":
            continue
        if done.get(stage.name) != want[stage.name] or not readable_parquet(folder / stage.table):
            return Pending(len(runs), None, 0, stage.name)
    if done.get("populations") == want["populations"] and readable_parquet(
            folder / "populations.parquet"):
        populations = read_table(folder / "populations.parquet", "populations")
    else:
        populations = build_populations(folder, settings)
    built = set(zip(populations["mapping"], populations["population"], strict=True))
    runs = [r for r in runs if (r.mapping, r.population) in built]  # run refuses the rest
    plan = plan_batches(runs, RunStore(folder), populations, study.seed,
                        stored=stored_inputs(folder, study.seed), check_only=True)
    return Pending(len(runs), plan.to_execute, plan.reused)


def has_study_tables(folder: Path) -> bool:
    """Whether ``folder`` holds a study's stage tables (something to count against)."""
    return Path(folder, "stages.json").is_file() and any(
        Path(folder, stage.table).is_file() for stage in STAGES)


__all__ = ["Pending", "has_study_tables", "pending_runs"]
