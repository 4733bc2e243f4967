"""Run a study: every stage not already done, then the runs, then compaction.

Stages (:data:`.stages.STAGES`) are skipped when their output exists and its
*stamp* (a hash of the settings that produced it, chained through upstream
stamps) matches, so a changed setting reruns exactly the stages downstream of
it. Runs are resumed per batch (see :mod:`.store`) and run by the batch executor
(:func:`.executors.execute`).
"""

from __future__ import annotations

import json
import platform
import time
from dataclasses import dataclass, field
from importlib.metadata import version
from pathlib import Path
from typing import Any

import pandas as pd

from ..design.plan import count_runs, plan_study
from ..design.study import Study
from ..episodes.specs import all_episodes
from ..errors import ConfigError, InputError
from ..io import write_json
from ..pipeline import PopulationSettings, read_table
from ..populations.build import check_members
from ..populations.perturb import ProfileSet
from ..progress import console
from ..read.checks import read_manifest, read_stamps, readable_parquet
from ..responses.probes import PROBE_SET_HASH
from ..tables import RUN_KEY
from ..version import __version__
from .batch_plan import plan_batches, run_plan
from .stages import STAGES, Stage, legacy_batch_inputs, stage_stamps
from .store import RunStore
from .validate import profile_mappings, validate_study
from .worker import Context


@dataclass
class RunReport:
    folder: Path
    planned: int = 0
    reused: int = 0
    executed: int = 0
    simulated: int = 0  # of the executed runs; the others repeated an identical run
    seconds: float = 0.0
    stages_run: list[str] = field(default_factory=list)
    compacted: bool = False  # the study tables were (re)written

    @property
    def nothing_to_do(self) -> bool:
        return not self.stages_run and self.executed == 0 and not self.compacted


def population_settings(study: Study) -> PopulationSettings:
    used = {m for part in study.parts.values() for m in part.mappings}
    null_parts = [part for part in study.parts.values() if part.null_design is not None]
    nulls = tuple(dict.fromkeys(p for part in null_parts for p in part.planned_specs))
    return PopulationSettings(
        personas=study.personas,
        seed=study.seed,
        respondent=study.respondent,
        respondent2=study.respondent2,
        matched_n=study.matched_n,
        mappings=profile_mappings(study),
        structure=any(ProfileSet.parse(m).is_structure for m in used),
        nulls=nulls,
        null_mappings=tuple(sorted({m for part in null_parts for m in part.mappings})),
        required=required_populations(study),
    )


def required_populations(study: Study) -> tuple[str, ...]:
    """Every population some part of ``study`` runs, in the order the parts name them."""
    return tuple(dict.fromkeys(p for part in study.parts.values()
                               for p in part.planned_populations))


def run_stages(folder: Path, s: PopulationSettings, show_progress: bool) -> list[str]:
    """Run the stages of :data:`.stages.STAGES` whose stamp changed or whose table is
    damaged, and every stage after one that ran; return the names of those run."""
    done = read_stamps(folder)
    want = stage_stamps(s)
    ran: list[str] = []
    for stage in STAGES:
        intact = readable_parquet(folder / stage.table)  # a damaged output is redone
        if done.get(stage.name) == want[stage.name] and intact and stage.after not in ran:
            continue
        with console.status(f"stage {stage.name}…"):
            _run_stamped(folder, stage, s, show_progress, done, want[stage.name])
        ran.append(stage.name)
    return ran


def run_stage(folder: Path, name: str, s: PopulationSettings, show_progress: bool = True,
              stamp: bool = True) -> Any:
    """Run the one stage ``name`` of :data:`.stages.STAGES` (a stage command such as
    ``popnavshift probe``) and return its table; record the stamp ``run`` would give it
    under ``s``, so that ``run`` with the same settings redoes nothing and with other
    settings redoes it. Without its upstream stamp (a table from before stamps) or with
    ``stamp`` False (settings the stamp cannot vouch for), the stage is left unstamped:
    ``run`` redoes it rather than trust it."""
    stage = next(st for st in STAGES if st.name == name)
    done = read_stamps(folder)
    known = stamp and (stage.after is None or stage.after in done)
    return _run_stamped(folder, stage, s, show_progress, done,
                        stage.stamp(s, done) if known else None)


def _run_stamped(folder: Path, stage: Stage, s: PopulationSettings, show_progress: bool,
                 done: dict[str, Any], stamp: str | None) -> Any:
    """Run ``stage`` and record ``stamp`` (None: no stamp) in ``stages.json``. The old
    stamp is dropped first: a stage that fails half-way (a table written, the next not)
    must not pass for done."""
    if done.pop(stage.name, None) is not None:
        write_json(done, folder / "stages.json")
    table = stage.run(folder, s, show_progress)
    if stamp is not None:
        done[stage.name] = stamp
        write_json(done, folder / "stages.json")
    return table


def run_study(
    study: Study,
    folder: Path,
    workers: int = 2,
    executor_name: str = "local",
    address: str | None = None,
    show_progress: bool = True,
) -> RunReport:
    episodes = all_episodes(seed=study.seed)
    validate_study(study, episodes)  # before any stage runs
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    report = RunReport(folder)
    started = time.perf_counter()
    settings = population_settings(study)
    stored = stored_inputs(folder, study.seed)  # before the stages replace their tables
    report.stages_run = run_stages(folder, settings, show_progress)
    populations = read_table(folder / "populations.parquet", "populations")
    check_members(populations["population"].unique(), settings.required or (),
                  study.population_specs())
    runs = plan_study(study, episodes)
    built = set(populations["mapping"])
    missing = sorted({r.mapping for r in runs} - built)
    if missing:
        raise ConfigError(
            f"study {study.name}: profile set(s) {', '.join(missing)} were not "
            f"built; available: {', '.join(sorted(built))}",
            hint="robustness labels need `respondent2` or a structure part",
        )
    store = RunStore(folder)
    plan = plan_batches(runs, store, populations, study.seed, stored=stored)
    report.planned = len(runs)
    report.reused = plan.reused
    # a folder compacted before runs carried their inputs is compacted once more, with them
    complete = _manifest_describes(folder, study) and not plan.batches and stored is None
    if not plan.todo and not report.stages_run and complete and _holds_exactly(folder, runs):
        report.seconds = time.perf_counter() - started
        return report

    context = Context(populations, study.seed, study.population_specs())
    done = run_plan(plan, store, context, workers,
                    executor_name=executor_name, address=address, show_progress=show_progress)
    report.executed, report.simulated = done.executed, done.simulated
    report.compacted = True
    report.seconds = time.perf_counter() - started
    write_manifest(
        folder,
        study,
        settings,
        report,
        done.seconds,
        workers,
        executor_name,
        done.n_runs,
        done.n_peds,
        count_runs(study, episodes),
    )
    return report


def stored_inputs(folder: Path, episode_seed: int) -> dict[tuple, str] | None:
    """The digests of the stored runs of a folder compacted before runs carried their own
    inputs (:meth:`.store.RunStore.legacy_inputs`), from its populations as they are before
    any stage runs again; None for a folder with nothing to migrate."""
    stamps = read_stamps(folder)
    store = RunStore(folder)
    record = stamps.get(store.RECORD)
    path = folder / "populations.parquet"
    if (not isinstance(record, dict) or "inputs" not in record or "populations" not in stamps
            or "episodes" not in stamps or not readable_parquet(path)):
        return None
    return store.legacy_inputs(read_table(path, "populations"), episode_seed,
                               legacy_batch_inputs(stamps))


def _manifest_describes(folder: Path, study: Study) -> bool:
    """Whether the manifest reads back and describes ``study`` as it is now. A damaged one
    is written again (not reported as 'nothing to do' while `report` refuses it), and so is
    one of an earlier version of the study whose runs are all still valid (a part renamed,
    a role declared): the analysis reads the study from it, and the runs' ``part`` column
    is compacted again."""
    try:
        manifest = read_manifest(folder)
    except InputError:
        return False
    return manifest is not None and manifest.get("config_hash") == study.config_hash()


def _holds_exactly(folder: Path, runs: list) -> bool:
    """Whether ``runs.parquet`` holds exactly the planned runs (a study that dropped a
    controller or a population must be compacted again; a damaged table is rebuilt)."""
    if not RunStore(folder).tables_intact():
        return False
    have = pd.read_parquet(folder / "runs.parquet", columns=list(RUN_KEY))
    return len(have) == len(runs)


#: what the manifest keeps of responses.json: who answered, where (``endpoint``: the URL
#: requests went to), with which settings, how many samples and how they were aggregated,
#: and what the server said of its model (file name, size, parameters, build, fingerprints)
MANIFEST_RESPONDENT = ("respondent", "model", "served_models", "seed", "scale", "endpoint",
                       "temperature", "max_tokens", "extra_body", "samples", "aggregation",
                       "system_fingerprints", "served")


def write_manifest(
    folder: Path,
    study: Study,
    s: PopulationSettings,
    report: RunReport,
    sim_seconds: float,
    workers: int,
    executor_name: str,
    n_runs: int,
    n_peds: int,
    counts: dict[str, Any],
) -> None:
    responses_meta = json.loads((folder / "responses.json").read_text())
    write_json(
        {
            "study": study.name,
            "config_hash": study.config_hash(),
            "study_config": study.model_dump(mode="json"),
            # the JSON's keys are sorted; the parts' order decides the main part of a
            # study that names none (Study.role)
            "part_order": list(study.parts),
            "versions": {
                "popnavshift": __version__,
                "navground": _navground_version(),
                "python": platform.python_version(),
                "pandas": pd.__version__,
            },
            "seeds": {"study": study.seed},
            "probe_set": PROBE_SET_HASH,
            "respondent": {k: v for k, v in responses_meta.items() if k in MANIFEST_RESPONDENT},
            "counts": counts,
            "tables": {"runs": n_runs, "pedestrians": n_peds},
            "timings": {
                "total_s": round(report.seconds, 2),
                "simulation_s": round(sim_seconds, 2),
                "runs_executed": report.executed,
                "runs_simulated": report.simulated,
                "runs_reused": report.reused,
                "workers": workers,
                "executor": executor_name,
            },
        },
        folder / "manifest.json",
    )


def _navground_version() -> str:
    try:
        return version("navground")
    except Exception:
        return "unknown"
