"""Study commands: calibrate, run, report (``plan`` is :mod:`.plan`)."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Annotated

import typer
from rich.table import Table

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
    stdout,
)


@app.command()
def calibrate(
    study_dir: Annotated[Path, typer.Argument(help="A study folder written by `popnavshift run`.")
                         ] = Path("study"),
    by_comparison: Annotated[bool, typer.Option(
        "--by-comparison", help="One block per comparison (matched, all pairs) besides the "
        "pooled rows.")] = False,
    fresh: Annotated[bool, typer.Option(
        help="Recompute from the study's tables even when its report has the calibration.")
                     ] = False,
) -> None:
    """Print every verdict rule's false-positive rate on placebos drawn from the study's own
    nulls, with a Clopper–Pearson 95% interval.

    A placebo takes one null replicate as if it were the observed populations and the other
    replicates as its null: no population effect, so every claim is false. First the
    headline table as the report decides it (all its rates together), then each test.

    Status: 'within' (the interval reaches down to the nominal level and rules out twice
    it), 'above nominal', or 'too few placebos to tell'. Then, for every card in
    STUDY_DIR/evaluate (`popnavshift evaluate`, `leaderboard`), the same for its robustness
    verdict on that controller's own placebos. Exit 1 if the study ran no null. The
    tables go to stdout (`popnavshift calibrate study > calibration.txt`).

    Example: `popnavshift calibrate study`.
    """
    from ..analysis.calibrate import TESTS
    from ..read.checks import check_study_folder

    check_study_folder(study_dir)
    cal = _calibration(study_dir, fresh)
    if cal is None or cal.empty:
        console.print(f"{say(study_dir)} ran no null replicates: nothing to calibrate (a study "
                      "needs a `null_design` part, as the paper study has).", highlight=False,
                      soft_wrap=True)
        raise typer.Exit(1)
    per_comp = sorted(set(cal["comparison"]) - {"all", "table"}) if by_comparison else []
    scopes = [x for x in ("table", *per_comp, "all") if (cal["comparison"] == x).any()]
    for scope in scopes:
        title = {"all": "each test, pooled over comparisons and metrics",
                 "table": "the headline table as the report decides it"}.get(scope, scope)
        t = Table("test (rule)", "claim", "claims / placebos", "rate [95% CI]", "nominal: status",
                  title=f"placebos: {title}")
        for r in cal[cal["comparison"] == scope].itertuples(index=False):
            t.add_row(f"{say(r.test)} ({say(r.rule)})", say(r.claim), f"{r.claims}/{r.placebos}",
                      _rate(r), _status(r))
        stdout.print(t)
    fp = cal[cal["comparison"].isin(["all", "table"]) & (cal["kind"] == "false positive")]
    bad = fp[fp["status"] == "above nominal"]
    checked = fp[fp["placebos"] > 0]
    unsure = checked[checked["status"] == "too few placebos to tell"]
    if bad.empty:
        stdout.print(f"[green]no verdict rule claims more than its nominal level[/] on this "
                     f"study's placebos ({len(checked)} rules checked; every Clopper–Pearson "
                     "interval reaches down to its nominal level).", highlight=False)
    else:
        stdout.print("[red]above its nominal level[/]: "
                     + "; ".join(f"{say(r.test)}: {say(r.claim)}" for r in bad.itertuples()),
                     highlight=False)
    if not unsure.empty:
        stdout.print("too few placebos to rule out twice the nominal rate for: "
                     + "; ".join(f"{say(r.test)}: {say(r.claim)}" for r in unsure.itertuples())
                     + " (more null replicates would tell; the test suite checks the rules on "
                     "thousands of synthetic designs).", highlight=False)
    unchecked = sorted(set(TESTS) - set(checked["test"]))
    if unchecked:
        stdout.print("no placebo could make a claim for: "
                     + "; ".join(f"{n} (it needs {TESTS[n].min_nulls + 1} null replicates)"
                                 for n in unchecked) + ".", highlight=False)
    _card_calibrations(study_dir)


def _card_calibrations(study_dir: Path) -> None:
    """Each card's verdict as a whole (its table of rates decided together, the raw rule)
    on that controller's placebos: one row per card and claim; a damaged card is named."""
    from ..io import read_csv
    from ..read.access import EVALUATE_DIR, card_intact

    t = Table("controller", "claim", "claims / placebos", "rate [95% CI]", "nominal: status",
              title="placebos: each card's robustness verdict, on its controller's own nulls")
    for card in sorted(p for p in (study_dir / EVALUATE_DIR).glob("*") if p.is_dir()):
        doc, why = card_intact(card)
        if why:
            t.add_row(say(card.name), f"[yellow]not read: {say(why)}[/]", "", "", "")
            continue
        path = card / "robustness_calibration.csv"
        cal = read_csv(path) if path.is_file() else None
        rows = [] if cal is None or cal.empty else list(cal[
            (cal["comparison"] == "table") & (cal["kind"] == "false positive")].itertuples())
        if not rows:
            t.add_row(say(doc.get("controller", card.name)), "no placebos: the study ran no "
                      "null its comparisons could use", "", "", "")
        for r in rows:
            t.add_row(say(doc.get("controller", card.name)), say(r.claim),
                      f"{r.claims}/{r.placebos}", _rate(r), _status(r))
    if t.row_count:
        stdout.print(t)


def _rate(r) -> str:
    """``2.5% [0.1, 13.2]``: a placebo claim rate with its Clopper–Pearson interval."""
    if r.placebos == 0:
        return "–"
    return f"{100 * r.rate:.1f}% [{100 * r.cp_low:.1f}, {100 * r.cp_high:.1f}]"


def _status(r) -> str:
    """``5.0%: within`` coloured by the status (a diagnostic or power row: its kind)."""
    if r.kind != "false positive":
        return str(r.kind)
    colour = {"within": "green", "above nominal": "red"}.get(r.status, "yellow")
    return f"{100 * r.nominal:.1f}%: [{colour}]{r.status}[/]"


def _calibration(study_dir: Path, fresh: bool):
    """The report's calibration table when the report is intact (every file as its build
    wrote it) and newer than the runs, else computed from the study's tables (the same code
    the report runs), with one line saying why the report's could not be used."""
    from ..analysis.calibrate import COLUMNS
    from ..io import read_csv
    from ..read.access import report_intact

    csv = study_dir / "report" / "tables" / "evidence_calibration.csv"
    runs = study_dir / "runs.parquet"
    if not fresh and csv.is_file() and runs.is_file() and (
            csv.stat().st_mtime >= runs.stat().st_mtime):
        why = report_intact(study_dir)
        table = read_csv(csv) if not why else None
        if table is not None and set(COLUMNS) <= set(table.columns):
            _check_numbers(table, csv)
            return table
        why = why or "the report's calibration table is of an older version"
        console.print(f"computing the calibration again: {say(why)}", highlight=False,
                      soft_wrap=True)
    from ..analysis.study_evidence import evidence_tables
    from ..read.folder import open_study

    with console.status("running the placebos on the study's nulls…"):
        tables, _ = evidence_tables(open_study(study_dir))
    return tables.get("evidence_calibration")


def _check_numbers(table, path: Path) -> None:
    """InputError unless the calibration's counts and rates are numbers."""
    import pandas as pd

    numbers = ("nominal", "placebos", "claims", "rate", "cp_low", "cp_high")
    if not all(pd.api.types.is_numeric_dtype(table[c]) for c in numbers):
        raise InputError(f"{path} is damaged (a count or rate that is not a number)",
                         hint="write the report again: popnavshift report FOLDER")


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
    from ..report.build import build_report

    check_study_folder(study_dir)
    started = time.perf_counter()
    with console.status("writing the report…") as status:
        def step(name: str) -> None:
            status.update(f"writing the report: {name}…")
            if not console.is_terminal:  # a pipe or a CI log: one plain line per step
                console.print(f"report: {name} ({time.perf_counter() - started:.0f} s)",
                              highlight=False)

        path = build_report(study_dir, n_boot=n_boot, progress=step)
    console.print(f"report → {say(path)} ({time.perf_counter() - started:.0f} s)")
