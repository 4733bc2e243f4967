"""The respondent audit command: is the respondent persona-sensitive, and usable?"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer
from rich.table import Table

from ..errors import ConfigError
from ..progress import console
from .app import app, say, stdout

if TYPE_CHECKING:  # the analysis stack is imported by the command, not by --help
    import pandas as pd

VERDICT_STYLE = {"usable": "green", "weak": "yellow", "not persona-sensitive": "red",
                 "not enough personas to tell": "yellow"}


def _num(x: Any, pattern: str = "{:.2f}") -> str:
    import pandas as pd

    return "–" if pd.isna(x) else pattern.format(x)


@app.command()
def audit(
    study_dir: Annotated[Path, typer.Argument(help="A study folder with personas.parquet and "
                                              "responses.parquet (after `popnavshift probe` "
                                              "or `popnavshift run`).")] = Path("study"),
    permutations: Annotated[int, typer.Option(
        max=100_000, help="Persona shuffles of the sensitivity null; at least 319, the fewest "
        "whose smallest p reaches 0.05 / 16 (16 answers tested).")] = 999,
    boot: Annotated[int, typer.Option(min=100, max=100_000,
                                      help="Bootstrap resamples of the intervals.")] = 1000,
    seed: Annotated[int, typer.Option(min=0, help="Seed of the shuffles and resamples.")] = 0,
    strict: Annotated[bool, typer.Option(
        "--strict", help="Exit with code 1 when a respondent is not usable (for scripts, CI).")
                      ] = False,
    pilot: Annotated[int | None, typer.Option(
        min=2, max=10_000, rich_help_panel="Pilot",
        help="Before a study: ask this many of its personas (STUDY_DIR is then a study, "
        "built-in name or YAML), audit them, time the calls and project the full study's "
        "calls, tokens and time.")] = None,
    samples: Annotated[int | None, typer.Option(
        min=1, max=100, rich_help_panel="Pilot",
        help="Samples per persona in the pilot (default: the study's).")] = None,
    out: Annotated[Path | None, typer.Option(
        "--out", "-o", rich_help_panel="Pilot",
        help="The pilot's folder (default: ./pilot-<study name>).")] = None,
) -> None:
    """Audit the probe answers of every respondent: do they follow the persona?

    From the study's own tables (responses, responses_alt for a second
    respondent, personas, profiles); nothing is asked again.

    \b
    - spread: per probe and item, levels used, entropy (bits), modal
      share; an item on at most 2 of its 5 levels, or a probe answered
      with one action throughout, is stuck;
    - persona sensitivity: R² of each answer and motion parameter on the
      persona fields against the same R² with the personas shuffled;
    - expected directions: e.g. trust_level vs the trust answer,
      time_pressure vs urgency (Spearman, 95% bootstrap interval);
    - the matched intervention: deadline − baseline shift per item
      (paired, 95% interval);
    - test–retest, with 2 or more samples per persona (--samples k at
      the probe stage): κ per probe, ICC per item and motion parameter
      (within- against between-persona variance); at temperature 0,
      samples that differ read "server not reproducible";
    - the two respondents' agreement, when there are two.

    Each respondent gets a verdict: usable; weak (what fails is listed);
    or not persona-sensitive: its answers carry no more of the persona
    than a shuffle, and the populations built from them are artifacts.
    Thresholds and reasons: docs/analysis.md §11.
    Each check states the smallest effect it could detect at this number
    of personas; when only checks without the power to see a usable
    respondent fail, the verdict is "not enough personas to tell"
    (needs ≈ N).

    With --pilot N, STUDY_DIR names a study (paper, quick, a YAML file):
    its first N personas are asked with its respondent, audited, and the
    full study's probe stage projected from the measured pace.

    Example: popnavshift audit study --strict

    Example: popnavshift audit my-study.yaml --pilot 30 --samples 2
    """
    from ..analysis.audit import ANSWER_TARGETS
    from ..analysis.audit_verdict import MIN_PERMUTATIONS, audit_tables
    from ..read.checks import check_study_folder
    from ..read.respondent_tables import read_respondent_tables

    if permutations < MIN_PERMUTATIONS:
        raise ConfigError(f"--permutations {permutations}: expected at least "
                          f"{MIN_PERMUTATIONS}, the fewest whose smallest p reaches the "
                          f"Bonferroni level of the {ANSWER_TARGETS} answers tested")
    measured = None
    if pilot is not None:
        study_dir, measured = _run_pilot(str(study_dir), pilot, samples, out)
    elif samples is not None or out is not None:
        raise ConfigError("--samples and --out belong to --pilot",
                          hint="popnavshift audit STUDY --pilot 30 --samples 2")
    check_study_folder(study_dir)
    personas, respondents = read_respondent_tables(study_dir)
    with console.status("shuffling personas…"):
        t = audit_tables(personas, respondents, rng_seed=seed, n_perm=permutations, n_boot=boot)
    for r in t["audit_verdict"].itertuples(index=False):
        _print_respondent(t, r)
    if "audit_agreement" in t:
        _print_agreement(t["audit_agreement"])
    for r in t["audit_verdict"].itertuples(index=False):
        style = VERDICT_STYLE[r.verdict]
        stdout.print(f"{r.respondent} respondent {say(r.name)} ({say(r.model)}): "
                      f"[bold {style}]{r.verdict}[/]" + (f" — {say(r.reasons)}" if r.reasons
                                                        else ""), highlight=False)
    if measured is not None:
        _print_projection(*measured)
    if strict and (t["audit_verdict"]["verdict"] != "usable").any():
        raise typer.Exit(1)


def _run_pilot(study_name: str, n: int, samples: int | None, out: Path | None):
    """Run the pilot of ``--pilot``: (its folder, (pilot, study, samples))."""
    from ..design.study import load_study
    from ..engine.lock import study_lock
    from ..engine.pilot import run_pilot
    from .app import folder

    study = load_study(study_name)
    target = folder(out or Path(f"pilot-{study.name}"))
    with study_lock(target):
        measured = run_pilot(study, n, target, samples)
    return target, (measured, study, samples)


def _print_projection(pilot, study, samples: int | None) -> None:
    """The pilot's pace, and the full study's probe stage at that pace."""
    from ..engine.pilot import projection

    p = projection(pilot, study, samples)
    asked = pilot.records - pilot.cached
    stdout.rule(f"pilot of study {say(study.name)}")
    per = p["seconds_per_call"]
    stdout.print(f"pilot: {pilot.personas} personas, {pilot.matched} matched, "
                 f"{pilot.samples} sample(s): {pilot.records} records ({pilot.cached} from the "
                 f"cache), {pilot.calls} calls in {pilot.wall_seconds:.0f} s"
                 + (f", {per:.1f} s per call" if per is not None else "")
                 + f" ({pilot.concurrency} at a time)", highlight=False)
    if "seconds" not in p:
        stdout.print(f"full study: {p['records']:,} records; nothing was asked of a server "
                     f"in the pilot ({asked} records asked, {pilot.calls} calls), so there "
                     "is no pace to project", highlight=False)
    else:
        stdout.print(f"full study: {p['records']:,} records ({p['samples']} sample(s)) → "
                     f"≈ {p['calls']:,} calls, ≈ {p['tokens']:,} tokens, ≈ "
                     f"{_duration(p['seconds'])} at the pilot's pace", highlight=False)
    if "second" in p:
        stdout.print(f"second respondent {say(p['second']['name'])}: "
                     f"{p['second']['records']:,} more records, not piloted", highlight=False)
    if pilot.calls:
        stdout.print(f"the pilot's answers are cached in {say(pilot.folder / 'cache')}",
                     highlight=False)


def _duration(seconds: float) -> str:
    hours, rest = divmod(round(seconds), 3600)
    return f"{hours} h {rest // 60:02d} min" if hours else f"{rest // 60} min {rest % 60:02d} s"


def _rows(t: dict[str, pd.DataFrame], name: str, role: str) -> pd.DataFrame:
    import pandas as pd

    df = t.get(f"audit_{name}", pd.DataFrame())
    return df[df["respondent"] == role] if not df.empty else df


def _print_respondent(t: dict[str, pd.DataFrame], r) -> None:
    from ..analysis.audit import rho_text

    stdout.rule(f"{r.respondent} respondent: {say(r.name)} ({say(r.model)})")
    stdout.print(f"{r.personas} personas; {r.answer_rows} distinct answer rows for "
                  f"{r.persona_records} distinct persona records", highlight=False)
    sens = _rows(t, "sensitivity", r.respondent).set_index("target")
    spread = _rows(t, "spread", r.respondent).set_index("column")
    a = Table("answer", "levels", "bits", "modal", "R²", "null", "p",
              "smallest detectable", "sensitive",
              title="answers: levels used, entropy, modal answer; R² on the persona fields "
              "against the shuffled null's mean; the smallest R² the test detects (80% power)")
    for name, x in sens[sens["kind"] != "parameter"].iterrows():
        used = entropy = modal = ""
        if name in spread.index:
            s = spread.loc[name]
            used = f"{s.used}/{s.levels}" + (" [red]stuck[/]" if s.stuck else "")
            entropy, modal = _num(s.entropy_bits), f"{say(s.modal)} {s.modal_share:.0%}"
        sensitive = "yes" if x.sensitive else "no" if x.kind == "action" else "[red]no[/]"
        a.add_row(str(name), used, entropy, modal, _num(x.r2), _num(x.null_mean),
                  _num(x.p_value, "{:.3f}"), _num(x.mde) if x.kind != "action" else "",
                  sensitive)
    stdout.print(a)
    params = sens[sens["kind"] == "parameter"]
    if not params.empty:
        p = Table("motion parameter", "R²", "null", "p", "smallest detectable", "sensitive",
                  title="motion parameters of its profiles")
        for name, x in params.iterrows():
            p.add_row(str(name), _num(x.r2), _num(x.null_mean), _num(x.p_value, "{:.3f}"),
                      _num(x.mde), "yes" if x.sensitive else "[red]no[/]")
        stdout.print(p)
    d = Table("persona field → answer", "expected", "Spearman ρ [95%]", "smallest detectable",
              "outcome", title="expected directions")
    for x in _rows(t, "directions", r.respondent).itertuples(index=False):
        d.add_row(f"{x.field} → {x.target}", x.expected,
                  rho_text(x.rho, x.ci_low, x.ci_high), _num(x.mde, "|ρ| {:.2f}"),
                  _outcome(x.outcome))
    stdout.print(d)
    _print_retest(_rows(t, "retest", r.respondent), r.retest)
    m = _rows(t, "manipulation", r.respondent)
    if m.empty:
        stdout.print("matched intervention: no persona was asked both variants.")
        return
    mt = Table("item", "expected", "shift [95%]", "up / down", "smallest detectable", "outcome",
               title=f"matched intervention: deadline − baseline ({int(m['n'].iloc[0])} personas)")
    for x in m[m["target"] != "actions"].itertuples(index=False):
        mt.add_row(x.target, x.expected, f"{x.shift:+.3f} [{x.ci_low:+.3f}, {x.ci_high:+.3f}]",
                   f"{x.up:.0%} / {x.down:.0%}", _num(x.mde, "{:+.3f}"), _outcome(x.outcome))
    stdout.print(mt)
    changed = m.loc[m["target"] == "actions", "changed"].iloc[0]
    stdout.print(f"probe actions changed by the deadline: {changed:.0%}", highlight=False)


def _print_retest(g: pd.DataFrame, summary: str) -> None:
    """The test–retest table, or the line saying it was not measured and how to."""
    if g.empty:
        stdout.print(f"test–retest: {say(summary)}", highlight=False)
        return
    from ..analysis.audit_verdict import MIN_ICC

    smallest = g["mde"].iloc[0] if "mde" in g else float("nan")
    t = Table("answer / parameter", "all samples agree", "κ / ICC", "within var",
              "between var", title=f"test–retest: {say(summary)}; the smallest true ICC "
              f"it passes (80% power): {_num(smallest)}")
    for x in g.itertuples(index=False):
        stat = f"κ {_num(x.kappa)}" if x.kind == "action" else (
            f"ICC {_num(x.icc)}" if not x.icc < MIN_ICC else f"[red]ICC {_num(x.icc)}[/]")
        t.add_row(x.target, _num(x.agree, "{:.0%}"), stat,
                  _num(getattr(x, "within_var", None), "{:.4f}"),
                  _num(getattr(x, "between_var", None), "{:.4f}"))
    stdout.print(t)


def _outcome(text: str) -> str:
    return text if text in ("as expected", "") else f"[red]{text}[/]"


def _print_agreement(g: pd.DataFrame) -> None:
    t = Table("answer / parameter", "records", "agree", "within one level", "κ / ρ / r",
              title="agreement of the two respondents (same persona, same variant)")
    for x in g.itertuples(index=False):
        stat = {"action": f"κ {_num(x.kappa)}", "item": f"ρ {_num(getattr(x, 'rho', None))}",
                "parameter": f"r {_num(getattr(x, 'r', None))}"}[x.kind]
        t.add_row(x.target, str(x.n), _num(getattr(x, "agree", None), "{:.0%}"),
                  _num(getattr(x, "within_one", None), "{:.0%}"), stat)
    stdout.print(t)
