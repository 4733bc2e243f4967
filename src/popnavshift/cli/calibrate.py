"""``popnavshift calibrate``: every verdict rule's false-positive rate on placebos drawn from
the study's own nulls, and, with ``--replicates``, on more placebos run beside the study
(:mod:`popnavshift.engine.side`)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer
from rich.table import Table

from ..errors import InputError
from ..progress import console
from .app import MAX_WORKERS, app, check_workers, say, stdout


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
    replicates: Annotated[int | None, typer.Option(
        "--replicates", min=3, max=999,
        help="Run the study's null designs to N replicates in STUDY_DIR/calibration (only the "
        "new runs; the study, its report and cards are not changed) and judge each of the N "
        "placebos against as many replicates as the study itself does: its rules as deployed, "
        "on N placebos instead of P. With no claim, 39 (390 placebos over the headline's 10 "
        "rows) is about the fewest that shows a rule at 0.05/10 within twice nominal.")
                          ] = None,
    workers: Annotated[int, typer.Option(
        "--workers", "-w", min=1, max=MAX_WORKERS,
        help="Worker processes for --replicates' runs.")] = 2,
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

    With --replicates N the placebos come from N null replicates run beside the study (its
    design otherwise), each judged against the study's own count of replicates (the next
    ones, cyclically): the rules exactly as the study deploys them, on more placebos.
    Run it again to resume; a changed study is linked again.

    Examples: `popnavshift calibrate study`; `popnavshift calibrate study --replicates 39`.
    """
    from ..read.checks import check_study_folder

    check_study_folder(study_dir)
    if replicates is not None:
        check_workers(workers, "local")
        cal = _side_calibration(study_dir, replicates, workers)
    else:
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
    for line in summary_lines(cal):
        stdout.print(line, highlight=False)
    _card_calibrations(study_dir)


def summary_lines(cal) -> list[str]:
    """The verdict under the tables: rules above nominal — pooled, over the headline table
    or in any one comparison (a rule can be within pooled and above in one comparison) —
    else that none is; rules with too few placebos to rule out twice nominal; tests no
    placebo could reach."""
    from ..analysis.calibrate import TESTS

    false_pos = cal[cal["kind"] == "false positive"]
    fp = false_pos[false_pos["comparison"].isin(["all", "table"])]
    bad = false_pos[false_pos["status"] == "above nominal"]
    checked = fp[fp["placebos"] > 0]
    unsure = checked[checked["status"] == "too few placebos to tell"]
    lines = []
    if bad.empty:
        lines.append(f"[green]no verdict rule claims more than its nominal level[/] on this "
                     f"study's placebos, pooled or in any one comparison ({len(checked)} rules "
                     "checked; every Clopper–Pearson interval reaches down to its nominal "
                     "level).")
    else:
        lines.append("[red]above its nominal level[/]: "
                     + "; ".join(f"{say(r.test)}: {say(r.claim)} ({_scope(r.comparison)}: "
                                 f"{r.claims}/{r.placebos}, {_rate(r)})"
                                 for r in bad.itertuples())
                     + " (placebos share null replicates and metrics, so the interval is "
                     "narrower than independent draws would give).")
    if not unsure.empty:
        lines.append("too few placebos to rule out twice the nominal rate for: "
                     + "; ".join(f"{say(r.test)}: {say(r.claim)}" for r in unsure.itertuples())
                     + " (more null replicates would tell; the test suite checks the rules on "
                     "thousands of synthetic designs).")
    unchecked = sorted(set(TESTS) - set(checked["test"]))
    if unchecked:
        lines.append("no placebo could make a claim for: "
                     + "; ".join(f"{n} (it needs {TESTS[n].min_nulls + 1} null replicates)"
                                 for n in unchecked) + ".")
    return lines


def _scope(comparison: str) -> str:
    """``pooled``, ``the headline table`` or the comparison's own name."""
    return {"all": "pooled", "table": "the headline table"}.get(comparison, comparison)


def _card_calibrations(study_dir: Path) -> None:
    """Each card's verdict as a whole (its table of rates decided together, the raw rule)
    on that controller's placebos: one row per card and claim; a damaged card is named."""
    from ..controller_ids import display_name
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
        name = display_name(str(doc.get("controller", card.name)))
        rows = [] if cal is None or cal.empty else list(cal[
            (cal["comparison"] == "table") & (cal["kind"] == "false positive")].itertuples())
        if not rows:
            t.add_row(say(name), "no placebos: the study ran no "
                      "null its comparisons could use", "", "", "")
        for r in rows:
            t.add_row(say(name), say(r.claim),
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


def _side_calibration(study_dir: Path, replicates: int, workers: int):
    """The calibration on ``replicates`` null replicates run in the study's side folder
    (:mod:`popnavshift.engine.side`), each placebo against the study's own count."""
    from ..analysis.study_evidence import evidence_tables
    from ..engine.lock import study_lock
    from ..engine.ownership import claim_folder
    from ..engine.runner import run_study
    from ..engine.side import prepare_side
    from ..read.folder import open_study

    # both locks until the placebos are read: nothing writes the study while it is linked,
    # and another calibrate can neither prune nor remake the side folder under this one
    with study_lock(study_dir):
        side, study, sizes = prepare_side(study_dir, replicates)
        with study_lock(side):
            claim_folder(side, study, force=True)  # the side folder is this command's own
            done = run_study(study, side, workers=workers, executor_name="local")
            _side_placebos(side, replicates, sizes, done)
            with console.status(f"running the placebos on {replicates} replicates…"):
                tables, _ = evidence_tables(open_study(side), null_sizes=sizes)
    return tables.get("evidence_calibration")


def _side_placebos(side: Path, replicates: int, sizes: dict, done) -> None:
    """The side run's one line: its replicates, what it simulated, the study's sizes."""
    console.print(f"{say(side)}: {replicates} replicates of every null design "
                  f"({done.executed:,} runs simulated now, {done.reused:,} reused); each "
                  "placebo judged against "
                  + ", ".join(f"{n} {kind}" for kind, n in sorted(sizes.items()))
                  + " replicates, as the study is", highlight=False, soft_wrap=True)


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
