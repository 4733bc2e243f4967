"""Study commands: run, report (``plan`` is :mod:`.plan`, ``calibrate`` :mod:`.calibrate`)."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Annotated

import typer

from ..errors import InputError
from ..progress import console
from .app import (
    MAX_WORKERS,
    Replicates,
    SeedSets,
    StudyArg,
    app,
    check_workers,
    default_folder,
    extended,
    folder,
    say,
)


@app.command()
def run(
    study: StudyArg = None,
    out: Annotated[
        Path | None,
        typer.Option(
            "--out",
            "-o",
            help="Study folder (default: ./study for the paper study, as `make run`; else "
            "./study-<name>).",
        ),
    ] = None,
    workers: Annotated[
        int,
        typer.Option(
            "--workers",
            "-w",
            min=1,
            max=MAX_WORKERS,
            help="Worker processes (or Ray CPUs for a local Ray instance).",
        ),
    ] = 2,
    executor: Annotated[str, typer.Option(help="local (worker processes) or ray.")] = "local",
    address: Annotated[
        str | None,
        typer.Option(
            help="Ray cluster address (with --executor ray); default: start a local instance."
        ),
    ] = None,
    report: Annotated[bool, typer.Option(help="Write the analysis report at the end.")] = True,
    samples: Annotated[
        int | None,
        typer.Option(min=1, max=100, help="Independent samples per persona, each with its "
                     "own seed, in place of the study's `respondent: {samples: k}` (the "
                     "respondent audit's test–retest needs 2 or more)."),
    ] = None,
    force: Annotated[bool, typer.Option(
        "--force", help="Write into --out even when it holds another study or other files.")
                     ] = False,
    replicates: Replicates = None,
    seed_sets: SeedSets = None,
) -> None:
    """Run every stage of a study that is not already done; resumable.

    Interrupt it at any time (Ctrl-C, kill, power loss) and run the same command
    again: finished work is kept and verified, the rest is done, and the tables come
    out identical to an uninterrupted run.
    """
    from ..design.study import load_study
    from ..engine.lock import study_lock
    from ..engine.ownership import claim_folder
    from ..engine.validate import validate_study
    from ..episodes.specs import all_episodes

    check_workers(workers, executor)
    s = extended(load_study(study or "paper"), replicates, seed_sets)
    if samples is not None:  # part of the study as run: its config hash and manifest say so
        s = s.model_copy(update={"respondent": s.respondent.model_copy(
            update={"samples": samples})})
    validate_study(s, all_episodes(s.seed), report=report)  # the one validation, as plan's
    target = folder(out or default_folder(s.name))
    with study_lock(target):  # held until the report is written: one writer per folder
        claim_folder(target, s, force)
        _run(s, target, workers, executor, address, report)
    console.print(f"outputs in {say(target.resolve())}")


def _run(s, target: Path, workers: int, executor: str, address: str | None,
         report: bool) -> None:
    """The body of ``run``, holding the folder's lock."""
    from ..engine.runner import run_study
    from .population import print_sizes

    report_ = run_study(s, target, workers=workers, executor_name=executor, address=address)
    if report_.nothing_to_do:
        console.print(
            f"[green]nothing to do[/]: {say(target)} is complete ({report_.planned:,} runs)"
        )
    else:
        import pandas as pd

        print_sizes(pd.read_parquet(target / "populations.parquet"))
        repeats = report_.executed - report_.simulated
        same = f" ({repeats:,} repeated an identical run)" if repeats else ""
        console.print(
            f"[bold green]done[/]: {report_.executed:,} runs executed{same}, "
            f"{report_.reused:,} reused, {report_.seconds:.1f} s"
        )
    if report:
        from ..report.build import report_is_current

        why = report_is_current(target, {"rng_seed": 0, "n_boot": 1000, "replays": 2})
        if report_.nothing_to_do and not why:
            console.print(f"report is up to date: {say(target / 'report' / 'index.html')}")
        else:
            if report_.nothing_to_do:
                console.print(f"rebuilding the report: {say(why)}", highlight=False,
                              soft_wrap=True)
            _write_report(target)


@app.command("report")
def report_cmd(
    study_dir: Annotated[Path, typer.Argument(help="A study folder written by `popnavshift run`.")],
    n_boot: Annotated[int, typer.Option(min=1, max=100_000,
                                        help="Bootstrap resamples for the CIs.")] = 1000,
) -> None:
    """Write DIR/report/index.html with every table (CSV) and figure (PNG, SVG)."""
    from ..engine.lock import study_lock

    if not study_dir.is_dir():
        raise InputError(f"study folder {study_dir} not found", hint="give the --out of a run")
    with study_lock(study_dir):  # one writer: a run or another report waits its turn
        _write_report(study_dir, n_boot=n_boot)


def _write_report(study_dir: Path, n_boot: int = 1000) -> None:
    from ..read.checks import check_study_folder
    from ..read.folder import open_study
    from ..report.build import build_report

    check_study_folder(study_dir)
    # what would stop the build at its first step, said before any progress line: a user
    # error is one line
    open_study(study_dir).require_run_tables()
    started = time.perf_counter()
    with console.status("writing the report…") as status:
        def step(name: str) -> None:
            status.update(f"writing the report: {name}…")
            if not console.is_terminal:  # a pipe or a CI log: one plain line per step
                console.print(f"report: {name} ({time.perf_counter() - started:.0f} s)",
                              highlight=False)

        path = build_report(study_dir, n_boot=n_boot, progress=step)
    console.print(f"report → {say(path)} ({time.perf_counter() - started:.0f} s)")
