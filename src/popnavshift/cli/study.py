"""Study commands: plan, run, report."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated

import typer
from rich.markup import escape
from rich.table import Table

from ..progress import console
from .app import MAX_WORKERS, app, check_workers, folder, say

StudyArg = Annotated[
    str | None,
    typer.Argument(help="A built-in study (paper, quick) or a study YAML file. Default: paper."),
]


@app.command()
def plan(
    study: StudyArg = None,
    json_out: Annotated[bool, typer.Option("--json", help="Print the counts as JSON.")] = False,
    from_dir: Annotated[
        Path | None,
        typer.Option("--from", help="A finished study folder (a pilot) whose report gives the "
                     "power advice (default: the study's own output folder, if it has one)."),
    ] = None,
) -> None:
    """Print the run counts of a study, per part (nothing is run), and how many episode
    seed sets it needs to separate each headline rate from its null.

    The advice comes from a study that has already run (its report's
    tables/evidence_power.csv): run a pilot, then plan the real study with --from.
    """
    from ..engine.plan import count_runs
    from ..engine.study import load_study
    from ..engine.validate import validate_study
    from ..episodes.specs import all_episodes

    s = load_study(study or "paper")
    validate_study(s, all_episodes(s.seed))
    counts = count_runs(s, all_episodes(s.seed))
    pilot = from_dir or Path("study" if study is None else f"study-{s.name}")
    advice = power_advice(pilot / "report" / "tables" / "evidence_power.csv")
    if json_out:
        typer.echo(json.dumps({"study": s.name, "parts": counts,
                               "power": advice.to_dict("records") if advice is not None
                               else None}, indent=2, default=str))
        return
    t = Table("part", "episodes", "robot runs", "no-robot runs", "total",
              title=f"study {say(s.name)}")
    for name, c in counts.items():
        t.add_row(
            say(name),
            str(c.get("episodes", "")),
            f"{c['robot_runs']:,}",
            f"{c['no_robot_runs']:,}",
            f"{c['total']:,}",
        )
    console.print(t)
    console.print("'distinct' is what a run executes: parts share identical runs.")
    if advice is None:
        console.print(f"power: no estimate yet ({escape(str(pilot))} has no report). Run a "
                      "pilot, e.g. `popnavshift run pilot` (the matched pair and its swap null "
                      "on 2 seed sets), then `popnavshift plan "
                      f"{escape(study or 'paper')} --from study-pilot`.", highlight=False)
        return
    p = Table("comparison", "metric", "rule", "excess", "effect to detect", "seed sets used",
              "seed sets needed", "verdict now", title=f"power (from {pilot})")
    for r in advice.itertuples(index=False):
        need = "–" if r.seed_sets_needed != r.seed_sets_needed else f"{int(r.seed_sets_needed)}"
        p.add_row(r.comparison, r.metric, r.rule, f"{100 * r.excess:+.1f} pp",
                  f"{100 * r.effect:.0f} pp", str(int(r.seed_sets_used)), need, r.verdict)
    console.print(p)
    from ..analysis.replicates import ALPHA_ONE_SIDED, MIN_EFFECT, POWER

    console.print(f"seed sets needed: to detect the effect (the observed excess, or "
                  f"{100 * MIN_EFFECT:g} pp when smaller) with {100 * POWER:g}% power at "
                  f"one-sided {100 * ALPHA_ONE_SIDED:g}%; add them as `seeds:` to the parts "
                  "that run the comparison and its null.", highlight=False)


def power_advice(path: Path):
    """The power table a study's report wrote (None if there is none)."""
    import pandas as pd

    if not path.exists():
        return None
    cols = ["comparison", "metric", "rule", "excess", "effect", "seed_sets_used",
            "seed_sets_needed", "verdict"]
    table = pd.read_csv(path)
    return table[cols] if set(cols) <= set(table.columns) else None


@app.command()
def run(
    study: StudyArg = None,
    out: Annotated[
        Path | None,
        typer.Option(
            "--out",
            "-o",
            help="Study folder (default: ./study-<name>, or ./study for the default).",
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
) -> None:
    """Run every stage of a study that is not already done; resumable.

    Interrupt it at any time (Ctrl-C, kill, power loss) and run the same command
    again: finished work is kept and verified, the rest is done, and the tables come
    out identical to an uninterrupted run.
    """
    from ..engine.lock import study_lock
    from ..engine.runner import run_study
    from ..engine.study import load_study
    from .population import print_sizes

    check_workers(workers, executor)
    s = load_study(study or "paper")
    target = folder(out or Path("study" if study is None else f"study-{s.name}"))
    with study_lock(target):
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
        _write_report(target)
    console.print(f"outputs in {say(target.resolve())}")


@app.command("report")
def report_cmd(
    study_dir: Annotated[Path, typer.Argument(help="A study folder written by `popnavshift run`.")],
    n_boot: Annotated[int, typer.Option(min=1, help="Bootstrap resamples for the CIs.")] = 1000,
) -> None:
    """Write DIR/report/index.html with every table (CSV) and figure (PNG, SVG)."""
    _write_report(study_dir, n_boot=n_boot)


def _write_report(study_dir: Path, n_boot: int = 1000) -> None:
    from ..engine.store import check_study_folder
    from ..report.build import build_report

    check_study_folder(study_dir)
    with console.status("writing the report…"):
        path = build_report(study_dir, n_boot=n_boot)
    console.print(f"report → {say(path)}")
