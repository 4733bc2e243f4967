"""Evaluate one controller against the baselines of a study, reusing every cached run.

``evaluate(controller, study, base_folder)``:

1. builds the controller (``CONTROLLERS.make``, :mod:`popnavshift.sim.controllers`:
   a clear :class:`ConfigError` for a class that does not import or is not a
   navground Behavior) and runs the contract checker on it;
2. runs the baseline study in ``base_folder`` (``popnavshift run``'s folder),
   which reuses every finished baseline and no-robot run;
3. plans the controller's runs on the study's evaluation parts (:mod:`.runs`: the main
   part, and the parts of the headline comparisons' nulls) as batches
   of their own, with the batch ids of ``popnavshift run``
   (:func:`popnavshift.engine.batches.batches`): a batch id hashes its run keys, so
   these never change the baseline batches, the stamp of the populations and
   episodes, and the code they run (the controller's module and the simulator,
   :func:`popnavshift.engine.stamps.run_code_stamp`), so edited code is run again.
   The same batch executor runs them (:func:`popnavshift.engine.executors.execute`).
   Their shards live in the baseline folder's store (reused by any later
   evaluation of the same controller and code); the compacted tables go to ``out``;
4. returns the evaluation parts' runs and pedestrians, baselines + controller +
   no-robot, for the card (:mod:`.card`; its robustness verdict, :mod:`.robustness`,
   on every evaluation part, the rest on the main part).

A run in which the controller raises is recorded as ``controller_error`` (see
:mod:`popnavshift.engine.worker`); the evaluation goes on.
"""

from __future__ import annotations

import shlex
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from ..analysis import episode_cells
from ..analysis.replicates import seed_sets
from ..controller_ids import named_controller
from ..design.study import Study, builtin_studies
from ..engine.batch_plan import plan_batches, run_plan
from ..engine.pending import pending_runs
from ..engine.rebuild import rebuild_run
from ..engine.runner import run_study
from ..engine.store import RunStore
from ..engine.worker import Context
from ..errors import ConfigError, InputError
from ..io import write_json
from ..outputs import FileSet
from ..paper import PAPER_CONTROLLERS
from ..pipeline import read_table
from ..read.access import CARD
from ..read.checks import read_manifest
from ..sim.check import ControllerContractError, check_controller
from ..sim.controllers import CONTROLLERS
from ..tables import NO_ROBOT
from ..version import __version__
from ..viz.replay import render_svg, run_outcome
from .advice import Advice, advice_text, advise
from .card import OUTCOME_LABELS, Card, card_tables
from .card_files import (
    card_folder,
    card_identity,
    check_card_settings,
    check_out,
    folder_name,
    runs_digest,
)
from .card_page import write_card
from .export import table_text
from .robustness import robustness_tables
from .runs import card_tables_of, evaluation_parts, main_part_rows, plan_extra
from .safety import SAFETY_THRESHOLD
from .verdict import Verdict

BASELINES: tuple[str, ...] = PAPER_CONTROLLERS  # a card sets a controller beside the paper's
Tables = tuple[pd.DataFrame, pd.DataFrame]  # runs, pedestrians
Log = Callable[[str], None]


@dataclass
class Evaluation:
    """The evaluated part's tables and how they were obtained.

    ``runs`` and ``pedestrians`` hold the no-robot runs, the baselines and the
    controller on the main part only; ``every_runs`` and ``every_pedestrians`` the same
    on every evaluation part (the null designs included); ``reused``/``executed`` count
    runs over both the baseline study and the controller's own batches.
    """

    controller: str
    baselines: tuple[str, ...]
    study: Study
    part: str
    base_folder: Path
    out: Path
    runs: pd.DataFrame
    pedestrians: pd.DataFrame
    description: dict[str, Any]
    check: str
    reused: int = 0
    executed: int = 0
    seconds: float = 0.0
    counts: dict[str, int] = field(default_factory=dict)
    #: the evaluation parts (:func:`.runs.evaluation_parts`) and their runs and
    #: pedestrians (the same controllers): what the robustness verdict is decided on
    parts: tuple[str, ...] = ()
    every_runs: pd.DataFrame | None = None
    every_pedestrians: pd.DataFrame | None = None


class _SharedShards(RunStore):
    """Shards in the baseline folder's store, compacted tables in ``out``."""

    def __init__(self, base_folder: Path, out: Path) -> None:
        super().__init__(out)
        self.runs_dir = Path(base_folder) / "shards" / "runs"
        self.peds_dir = Path(base_folder) / "shards" / "peds"


def check(factory: Any) -> str:
    """Run :func:`check_controller`: a broken contract is a ConfigError; a controller
    that merely raises in the checker's small world is reported and let through,
    since its runs that raise are recorded as controller errors."""
    try:
        check_controller(factory)
    except ControllerContractError as err:
        raise ConfigError(f"{err.message} (contract check)", hint=err.hint or
                          "fix the controller, or skip the check with --no-check") from None
    except Exception as exc:  # the controller's own exception, reported on the card
        return f"raised {type(exc).__name__} in the contract check: {exc}"
    return "passed"


def evaluate(
    controller: str,
    study: Study,
    base_folder: Path,
    out: Path | None = None,
    *,
    baselines: Sequence[str] = BASELINES,
    workers: int = 2,
    run_check: bool = True,
    show_progress: bool = True,
    log: Log | None = None,
) -> Evaluation:
    """Run what is missing and return the evaluated part's tables (see the module doc)."""
    say = log or (lambda _msg: None)
    started = time.perf_counter()
    identity = named_controller(controller)
    if identity == NO_ROBOT:
        raise ConfigError("controller 'none' is the no-robot baseline; name a controller")
    factory = CONTROLLERS.make(identity)
    part_name, _ = study.require_main()
    base_ids = tuple(b for b in dict.fromkeys(baselines) if b != identity)
    if not base_ids:
        raise ConfigError("evaluate needs at least one baseline other than the controller")
    for b in base_ids:  # fail before anything runs or is said
        CONTROLLERS.make(b)
    status = check(factory) if run_check else "skipped"
    say(f"controller {identity}: contract check {status}")
    base_folder = Path(base_folder)
    out = Path(out) if out is not None else card_folder(base_folder, identity)
    check_out(out, base_folder)

    base = run_study(study, base_folder, workers=workers, show_progress=show_progress)
    say(f"baseline study {study.name} ({base_folder}): {base.reused:,} runs reused, "
        f"{base.executed:,} executed")
    parts = evaluation_parts(study)
    compared = (*base_ids, identity)
    own, reused, executed = _run_extra(study, parts, compared, base_folder, out, workers,
                                       show_progress, say)
    sources = [(pd.read_parquet(base_folder / "runs.parquet"),
                pd.read_parquet(base_folder / "pedestrians.parquet")), *own]
    every_runs, every_peds = card_tables_of(study, parts, compared, sources)
    main = main_part_rows(every_runs, study)
    runs = every_runs[main].reset_index(drop=True)
    peds = every_peds[main_part_rows(every_peds, study)].reset_index(drop=True)
    ev = Evaluation(identity, base_ids, study, part_name, base_folder, out, runs, peds,
                    factory.describe(), status, base.reused + reused, base.executed + executed,
                    parts=parts, every_runs=every_runs, every_pedestrians=every_peds)
    ev.seconds = time.perf_counter() - started
    own = runs[runs["controller"] == identity]
    ev.counts = {"runs": len(runs), "controller_runs": len(own),
                 "controller_errors": int((own["outcome"] == "controller_error").sum())}
    say(f"reused {ev.reused:,} runs, executed {ev.executed:,} ({ev.seconds:.1f} s)")
    _write_manifest(ev)
    return ev


def _run_extra(study: Study, parts: tuple[str, ...], controllers: tuple[str, ...],
               base_folder: Path, out: Path, workers: int, show_progress: bool,
               say: Log) -> tuple[list[Tables], int, int]:
    """Plan, run and compact the runs of ``controllers`` on the evaluation ``parts`` that
    the study does not run itself (:func:`.runs.plan_extra`); returns their (runs,
    pedestrians) tables (none when there are none), the runs reused and executed."""
    runs = plan_extra(study, parts, controllers)
    if not runs:
        return [], 0, 0
    store = _SharedShards(base_folder, out)
    populations = read_table(base_folder / "populations.parquet", "populations")
    # the runner's batches and ids: its shards are reused, and it reuses these
    plan = plan_batches(runs, store, populations, study.seed, carry=False)
    n_todo = plan.to_execute
    who = sorted({r.controller for r in runs})
    say(f"{', '.join(who)} on {', '.join(parts)}: {plan.reused:,} runs reused, "
        f"{n_todo:,} to run")
    out.mkdir(parents=True, exist_ok=True)
    context = Context(populations, study.seed, study.population_specs())
    run_plan(plan, store, context, workers, show_progress=show_progress)
    tables = (pd.read_parquet(out / "runs.parquet"), pd.read_parquet(out / "pedestrians.parquet"))
    return [tables], plan.reused, n_todo


def _write_manifest(ev: Evaluation) -> None:
    write_json({
        "controller": ev.controller,
        "description": ev.description,
        "contract_check": ev.check,
        "baselines": list(ev.baselines),
        "study": ev.study.name,
        "config_hash": ev.study.config_hash(),
        "part": ev.part,
        "parts": list(ev.parts),
        "base_folder": folder_name(ev.base_folder),
        "counts": ev.counts,
        "timings": {"total_s": round(ev.seconds, 2), "runs_reused": ev.reused,
                    "runs_executed": ev.executed},
        "popnavshift": __version__,
    }, ev.out / "evaluation.json")


def replay(ev: Evaluation, key: dict[str, Any]) -> tuple[dict, dict]:
    """Simulate one run of the evaluation again, recording it: (trajectory, run row)."""
    populations = read_table(ev.base_folder / "populations.parquet", "populations")
    result = rebuild_run(key, populations, ev.study.seed, record=True)
    assert result.trajectory is not None
    return result.trajectory, result.run


def make_card(ev: Evaluation, *, n_boot: int = 1000, seed: int = 0,
              safety_threshold: float | None = None) -> tuple[Path, Path]:
    """Write ``card.html``, ``card.png``, every table the card shows as ``<name>.csv``
    (:meth:`Card.tables`; the outcomes also as ``outcomes.md`` and ``outcomes.tex``) and,
    last, ``card.json`` (its identity, :func:`.card_files.card_identity`, its verdict and
    every file's sha256) into ``ev.out``, as one set (:class:`popnavshift.outputs.FileSet`:
    an interrupted card is never taken for a finished one); returns the page's and the
    figure's paths. ``seed`` drives the bootstrap (the same seed gives the same
    intervals); ``safety_threshold``, when given, is a share of the controller's runs
    above which a collision kind or controller errors read unsafe whatever the baselines
    do."""
    threshold = SAFETY_THRESHOLD if safety_threshold is None else safety_threshold
    check_card_settings(n_boot, seed, threshold)
    identity = card_identity(ev.controller, ev.baselines, ev.study.config_hash(),
                             runs_digest(ev.base_folder, ev.out), n_boot=n_boot, seed=seed,
                             safety_threshold=threshold)
    n_sets = int(seed_sets(ev.runs).nunique())
    observed = ev.study.require_main()[1].populations
    every = (ev.every_runs if ev.every_runs is not None else ev.runs,
             ev.every_pedestrians if ev.every_pedestrians is not None else ev.pedestrians)
    rob = robustness_tables(*every, ev.controller, ev.baselines, ev.study.population_specs(),
                            observed, rng_seed=seed, n_boot=n_boot)
    card = card_tables(ev.runs, ev.pedestrians, ev.controller, ev.baselines, rob,
                       rng=np.random.default_rng(seed), n_boot=n_boot,
                       safety_threshold=threshold, decide=decide_text(ev, advise(rob.headline)))
    svg, note = _worst_replay(ev, card)
    made = datetime.now(UTC).isoformat(timespec="seconds")
    meta = {"study": ev.study.name, "part": ev.part, "check": ev.check, "reused": ev.reused,
            "executed": ev.executed, "n_runs": ev.counts["controller_runs"],
            "n_errors": ev.counts["controller_errors"],
            "n_cells": episode_cells(ev.runs)["cell"].nunique(),
            "n_populations": ev.runs["population"].nunique(),
            "backends": ", ".join(sorted(ev.runs["backend"].unique())),
            "mappings": ", ".join(sorted(ev.runs["mapping"].unique())),
            "replay_note": note, "n_boot": n_boot, "seed": seed,
            "base_folder": folder_name(ev.base_folder), "seed_sets": n_sets, "n_used": len(ev.runs),
            "safety_threshold": threshold, "parts": ", ".join(ev.parts),
            "n_every": len(every[0]), "version": __version__,
            "config_hash": ev.study.config_hash(), "made": made}
    tables = card.tables()
    main = tables["outcomes"][list(OUTCOME_LABELS)].rename(columns=OUTCOME_LABELS)
    v = card.verdict
    with FileSet(ev.out, CARD) as files:
        for name, table in tables.items():
            files.add_text(f"{name}.csv", table_text(table, "csv"))
        for fmt in ("md", "tex"):  # the main table, for a paper
            files.add_text(f"outcomes.{fmt}", table_text(main, fmt))
        html, png = write_card(card, meta, files, svg)
        files.commit({**identity, "tables": [f"{n}.csv" for n in tables],
                      "verdict": verdict_record(v), "popnavshift": __version__,
                      "made": made})
    return html, png


def verdict_record(v: Verdict) -> dict[str, Any]:
    """The card's two verdicts as ``card.json`` records them."""
    return {"robustness": {"label": v.robustness, "text": v.robustness_text,
                           "decide": v.decide, "row": v.row, "interaction": v.interaction,
                           "interaction_rows": list(v.interaction_rows)},
            "safety": {"label": v.safety.label, "text": v.safety.text,
                       "findings": v.safety.findings, "threshold": v.safety.threshold}}


def decide_text(ev: Evaluation, advice: Advice) -> str:
    """What would decide the card's undecided rates: the evaluate command that extends the
    study as ``advice`` says, the runs it adds (the study's and the controller's own) and
    their minutes at the study's measured pace."""
    if advice.seed_sets is None and advice.replicates is None:
        return advice_text(advice, "", None, None)
    bigger = ev.study.extended(replicates=advice.replicates, seed_sets=advice.seed_sets)
    compared = (*ev.baselines, ev.controller)
    pending = pending_runs(bigger, ev.base_folder)
    runs = None if pending.execute is None else pending.execute + (
        len(plan_extra(bigger, ev.parts, compared)) - len(plan_extra(ev.study, ev.parts,
                                                                     compared)))
    pace = _pace(ev.base_folder)
    minutes = None if runs is None or pace is None else runs / pace / 60
    study = ev.study.name if ev.study.name in builtin_studies() else ev.study.where
    options = "".join(f" --{flag} {value}" for flag, value in
                      (("seed-sets", advice.seed_sets), ("replicates", advice.replicates))
                      if value is not None)
    command = (f"popnavshift evaluate {shlex.quote(ev.controller)} --study "
               f"{shlex.quote(study)} -d {shlex.quote(str(ev.base_folder))}{options}")
    return advice_text(advice, command, runs, minutes)


def _pace(folder: Path) -> float | None:
    """Runs executed per second when the study last ran (its manifest), None unknown."""
    try:
        timings = (read_manifest(folder) or {}).get("timings", {})
    except InputError:
        return None
    done, seconds = timings.get("runs_executed"), timings.get("simulation_s")
    return done / seconds if done and seconds else None


def _worst_replay(ev: Evaluation, card: Card) -> tuple[str | None, str]:
    """The card's worst run simulated again and drawn (SVG), and whether it reproduces
    the stored run; (None, "") without a worst run."""
    if card.worst_run is None:
        return None, ""
    traj, row = replay(ev, card.worst_run)
    same = row["outcome"] == card.worst_run["outcome"] and np.isclose(
        row["robot_time"], card.worst_run["robot_time"], rtol=0, atol=1e-9)
    note = ("The replay reproduces the stored run." if same else
            f"The replay does NOT reproduce the stored run (it ends in {row['outcome']}).")
    title = f"{card.worst_run['episode']} · {card.worst_run['population']} → {row['outcome']}"
    return render_svg(traj, title=title, outcome=run_outcome(row)), note
