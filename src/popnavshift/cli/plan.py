"""``popnavshift plan``: a study's run counts per part, what `run` would simulate in its
folder, and from a pilot's report what would decide each undecided headline rate."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated

import typer
from rich.table import Table

from ..errors import InputError
from .app import (
    WIDE,
    Replicates,
    SeedSets,
    StudyArg,
    app,
    default_folder,
    extended,
    indented,
    prose,
    say,
    stdout,
)


@app.command()
def plan(
    study: StudyArg = None,
    json_out: Annotated[bool, typer.Option("--json", help="Print the counts as JSON.")] = False,
    from_dir: Annotated[
        Path | None,
        typer.Option("--from", help="A finished study folder (a pilot) whose report gives the "
                     "power advice (default: the study's own output folder, if it has one)."),
    ] = None,
    report: Annotated[bool, typer.Option(
        help="Check that the report can be written too, as `run` does by default.")] = True,
    out: Annotated[Path | None, typer.Option(
        "--out", "-o", help="The study folder `run` would write (default: the study's own "
        "folder): how many runs it would simulate there.")] = None,
    replicates: Replicates = None,
    seed_sets: SeedSets = None,
) -> None:
    """Print the run counts of a study, per part (nothing is run), and what would decide
    each undecided headline rate (more seed sets, more null replicates, or nothing).

    The advice gives the runs and minutes it costs.

    The advice comes from a study that has already run (its report's
    tables/evidence_power.csv, measured on its own replicate curve and nulls): run a pilot,
    then plan the real study with --from, e.g. `popnavshift plan paper --from study-pilot`.
    """
    from ..design.plan import count_runs
    from ..design.study import load_study
    from ..engine.validate import validate_study
    from ..episodes.specs import all_episodes

    s = extended(load_study(study or "paper"), replicates, seed_sets)
    validate_study(s, all_episodes(s.seed), report=report)
    counts = count_runs(s, all_episodes(s.seed))
    if from_dir is not None:
        check_pilot(from_dir)
    target = out or default_folder(s.name)
    pilot = from_dir or target
    advice = power_advice(pilot / "report" / "tables" / "evidence_power.csv")
    pending = _pending(s, target)
    if advice is not None and pending is not None and pilot == target:
        advice = exact_runs(advice, s, target)
    if json_out:
        typer.echo(json.dumps({"study": s.name, "parts": counts, "folder": str(target),
                               "pending": None if pending is None else vars(pending),
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
    stdout.print(t)
    prose("'distinct' is what a run executes: parts share identical runs.")
    prose(_pending_text(target, pending))
    if advice is None:
        prose(f"power: no estimate yet ({say(no_power_why(pilot))}). Run a "
              "pilot, e.g. `popnavshift run pilot` (the matched pair and its swap null "
              "on 2 seed sets), then `popnavshift plan "
              f"{say(study or 'paper')} --from study-pilot`.")
        return
    print_advice(advice, f"power (from {say(pilot)})")
    for line in holdout_lines(advice):
        prose(line)
    prose("what would decide it: the fewest seed sets and null replicates that decide the "
          "verdict with 80% power, the excess and the null's spread each following the "
          "curve fitted on the pilot's own seed sets (t: predicted, with its 10–90% "
          "interval from the model's hold-out error); run them with `popnavshift run STUDY "
          "--seed-sets S --replicates R` (only the new runs are simulated; `plan STUDY "
          "--seed-sets S --replicates R` counts them first).")


def print_advice(advice, title: str) -> None:
    """The power table: a grid on a wide terminal; on a narrower one, a line per row
    (comparison · metric · rule: excess, verdict) and, for an undecided one, what would
    decide it below, indented."""
    if stdout.width >= WIDE:
        p = Table("comparison", "metric", "rule", "excess", "verdict now",
                  "what would decide it", title=title)
        for r in advice.itertuples(index=False):
            p.add_row(say(r.comparison), say(r.metric), say(r.rule),
                      _pp(r.excess), say(r.verdict), say(advice_text(r)))
        stdout.print(p)
        return
    prose(f"[bold]{title}[/]")
    for r in advice.itertuples(index=False):
        head = (f"{say(r.comparison)} · {say(r.metric)} · {say(r.rule)}: "
                f"{_pp(r.excess)}, {say(r.verdict)}")
        decide = advice_text(r)
        if decide == "decided":
            prose(f"{head} (decided)")
        else:
            prose(head)
            indented(decide)


def _pp(excess: float) -> str:
    """An excess in percentage points; "no estimate" where the rule gave none (not 'nan')."""
    return "no estimate" if excess != excess else f"{100 * excess:+.1f} pp"


def _pending(study, folder: Path):
    """What `run` would simulate in ``folder`` (None: no study tables there yet)."""
    from ..engine.pending import has_study_tables, pending_runs

    return pending_runs(study, folder) if has_study_tables(folder) else None


#: an advised design is counted exactly (planned as `run` would) up to this many runs;
#: planning millions takes minutes, and so large a design is itself the message
MAX_EXACT = 600_000


def exact_runs(advice, study, folder: Path):
    """``advice`` with ``runs_exact``: what `run STUDY --seed-sets S --replicates R` would
    simulate in ``folder`` for each advised design (:func:`.engine.pending.pending_runs`,
    counted as `run` plans them), NaN where the advice cannot be run that way — more seed
    sets for a comparison on a part without ``seeds`` (the main grid: add ``seeds`` to its
    parts, as the built-in paper-large does), or a stage before the populations would run
    again; and for the significant rule's rows (descriptive) or designs above
    :data:`MAX_EXACT` runs."""
    import numpy as np

    from ..design.study import Study
    from ..engine.pending import pending_runs

    assert isinstance(study, Study)
    extendable = {part.null_design.kind if part.null_design else None
                  for part in study.parts.values() if part.seeds}
    cache: dict[tuple[int, int], float] = {}
    exact = []
    for r in advice.itertuples(index=False):
        s1, p1 = getattr(r, "seed_sets_needed", np.nan), getattr(r, "nulls_needed", np.nan)
        if not (np.isfinite(s1) and np.isfinite(p1)):
            exact.append(np.nan)
            continue
        if r.rule != "raw" or not r.runs_needed <= MAX_EXACT:
            exact.append(np.nan)  # too large to plan in a moment: its upper bound stands
            continue
        s1, p1 = int(s1), int(p1)
        s0 = getattr(r, "seed_sets", np.nan)
        if not np.isfinite(s0):  # a power table without the study's own design: unknown
            exact.append(np.nan)
            continue
        more_sets = s1 > int(s0)
        null_kind = getattr(r, "null", None)
        if more_sets and null_kind not in extendable:
            exact.append(np.nan)
            continue
        key = (s1 if more_sets else 0, p1)
        if key not in cache:
            bigger = study.extended(seed_sets=s1 if more_sets else None,
                                    replicates=max(p1, _replicates_of(study)))
            n = pending_runs(bigger, folder).execute
            cache[key] = np.nan if n is None else float(n)
        exact.append(cache[key])
    return advice.assign(runs_exact=exact)


def _replicates_of(study) -> int:
    """The most null replicates a part of ``study`` declares (extended() refuses fewer)."""
    return max((p.null_design.replicates for p in study.parts.values() if p.null_design),
               default=1)


def _pending_text(folder: Path, pending) -> str:
    """The pending count in words."""
    if pending is None:
        return f"{say(folder)} holds no study yet: `run` simulates every distinct run."
    if pending.execute is None:
        return (f"in {say(folder)}: the {pending.stale} stage would run again first, so which "
                f"of the {pending.planned:,} runs change is known only after it (at most all).")
    return (f"in {say(folder)}: `run` would simulate {pending.execute:,} new runs and keep "
            f"{pending.kept:,} it already holds with the same inputs.")


def advice_text(r) -> str:
    """One power row's advice in words (runs are an upper bound: identical runs repeat)."""
    if r.limit == "decided" or r.runs_needed != r.runs_needed:
        return str(r.limit)
    minutes = f", ~{r.minutes_needed:.0f} min" if r.minutes_needed == r.minutes_needed else ""
    sets = int(r.seed_sets_needed)
    exact = getattr(r, "runs_exact", float("nan"))
    if exact == exact and r.minutes_needed == r.minutes_needed and r.runs_needed > 0:
        minutes = f", ~{r.minutes_needed * exact / r.runs_needed:.0f} min"
    runs = (f"`run` would simulate {int(exact):,} new runs here{minutes}" if exact == exact
            else f"about +{int(r.runs_needed):,} runs{minutes}")
    text = (f"{r.limit}: {sets} seed set{'s' if sets != 1 else ''}, {int(r.nulls_needed)} "
            f"null replicates ({runs})")
    t, low, high = (getattr(r, k, float("nan")) for k in ("t_predicted", "t_low", "t_high"))
    if t == t:
        chance = getattr(r, "chance", float("nan"))
        text += (f"; t {t:.1f} [{low:.1f}, {high:.1f}]"
                 + (f", decided with chance {chance:.0%}" if chance == chance else ""))
    return text


def holdout_lines(advice) -> list[str]:
    """Per comparison with ≥ 3 seed sets: how far the t predicted at its seed sets from
    its first 2 was from the t it measured (the model's own hold-out on this study)."""
    if "holdout_error" not in advice:
        return []
    out = []
    rows = advice[advice["holdout_error"].notna()]
    for comparison, g in rows.groupby("comparison", sort=False):
        s0 = int(g["holdout_at"].iloc[0])
        parts = ", ".join(f"{say(r.metric)} {r.holdout_error:+.1f} (predicted "
                          f"{r.holdout_predicted:.1f}, measured {r.holdout_t:.1f})"
                          for r in g.itertuples())
        out.append(f"hold-out, {say(comparison)}: the t at {s0} seed sets predicted from "
                   f"seed sets 1–2 was off by {parts} on this study (measured − predicted).")
    return out


def no_power_why(pilot: Path) -> str:
    """Why ``pilot`` gives no power advice, in words."""
    power = pilot / "report" / "tables" / "evidence_power.csv"
    if not (pilot / "report" / "index.html").is_file():
        return f"{pilot} has no report"
    if not power.is_file():
        return (f"the report of {pilot} has no power table ({power.relative_to(pilot)}): "
                "its study ran no null design to measure power against")
    return (f"the power table of {pilot} is of an older version: write its report again "
            f"(popnavshift report {pilot})")


#: the power table's columns a report before the curve model lacks
OPTIONAL = ("t_predicted", "t_low", "t_high", "chance", "holdout_at", "holdout_predicted",
            "holdout_t", "holdout_error", "seed_sets", "n_null")
#: text columns of the power table `plan` keeps when present (the comparison's null kind:
#: whether `--seed-sets` can grow it, :func:`exact_runs`)
OPTIONAL_TEXT = ("null",)


def power_advice(path: Path):
    """The power table a study's report wrote (None if there is none or it predates the
    current columns)."""
    import pandas as pd

    from ..io import read_csv

    if not path.is_file():
        return None
    cols = ["comparison", "metric", "rule", "excess", "verdict", "limit", "seed_sets_needed",
            "nulls_needed", "runs_needed", "minutes_needed"]
    table = read_csv(path)
    if not set(cols) <= set(table.columns):
        return None
    cols += [c for c in OPTIONAL if c in table.columns]  # a report of this version has them
    numbers = cols[3:4] + cols[6:]
    table = table[cols + [c for c in OPTIONAL_TEXT if c in table.columns]]
    if not all(pd.api.types.is_numeric_dtype(table[c]) for c in numbers):
        raise InputError(f"{path} is damaged (a count or rate that is not a number)",
                         hint="write the report again: popnavshift report FOLDER")
    return table


def check_pilot(path: Path) -> None:
    """``plan --from``: a folder that a study ran in, or one clear line."""
    from ..engine.ownership import folder_owner

    if not path.exists():
        raise InputError(f"--from {path}: no such folder", hint="give the --out of a pilot run")
    if not path.is_dir():
        raise InputError(f"--from {path} is a file, not a study folder",
                         hint="give the --out of a pilot run")
    if folder_owner(path) is None:
        raise InputError(f"--from {path} holds no PopNavShift study",
                         hint="give the --out of a pilot run, e.g. study-pilot")
