"""The respondent audit command: is the respondent persona-sensitive, and usable?"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer
from rich.table import Table

from ..errors import ConfigError
from ..progress import console
from .app import app, say

if TYPE_CHECKING:  # the analysis stack is imported by the command, not by --help
    import pandas as pd

VERDICT_STYLE = {"usable": "green", "weak": "yellow", "not persona-sensitive": "red"}


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
    seed: Annotated[int, typer.Option(help="Seed of the shuffles and resamples.")] = 0,
    strict: Annotated[bool, typer.Option(
        "--strict", help="Exit with code 1 when a respondent is not usable (for scripts, CI).")
                      ] = False,
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

    Example: popnavshift audit study --strict
    """
    from ..analysis.audit import ANSWER_TARGETS
    from ..analysis.audit_verdict import MIN_PERMUTATIONS, audit_tables
    from ..read.checks import check_study_folder
    from ..read.respondent_tables import read_respondent_tables

    if permutations < MIN_PERMUTATIONS:
        raise ConfigError(f"--permutations {permutations}: expected at least "
                          f"{MIN_PERMUTATIONS}, the fewest whose smallest p reaches the "
                          f"Bonferroni level of the {ANSWER_TARGETS} answers tested")
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
        console.print(f"{r.respondent} respondent {say(r.name)} ({say(r.model)}): "
                      f"[bold {style}]{r.verdict}[/]" + (f" — {say(r.reasons)}" if r.reasons
                                                        else ""), highlight=False)
    if strict and (t["audit_verdict"]["verdict"] != "usable").any():
        raise typer.Exit(1)


def _rows(t: dict[str, pd.DataFrame], name: str, role: str) -> pd.DataFrame:
    import pandas as pd

    df = t.get(f"audit_{name}", pd.DataFrame())
    return df[df["respondent"] == role] if not df.empty else df


def _print_respondent(t: dict[str, pd.DataFrame], r) -> None:
    from ..analysis.audit import rho_text

    console.rule(f"{r.respondent} respondent: {say(r.name)} ({say(r.model)})")
    console.print(f"{r.personas} personas; {r.answer_rows} distinct answer rows for "
                  f"{r.persona_records} distinct persona records", highlight=False)
    sens = _rows(t, "sensitivity", r.respondent).set_index("target")
    spread = _rows(t, "spread", r.respondent).set_index("column")
    a = Table("answer", "levels", "bits", "modal", "R²", "null", "p", "sensitive",
              title="answers: levels used, entropy, modal answer; R² on the persona fields "
              "against the shuffled null's mean")
    for name, x in sens[sens["kind"] != "parameter"].iterrows():
        used = entropy = modal = ""
        if name in spread.index:
            s = spread.loc[name]
            used = f"{s.used}/{s.levels}" + (" [red]stuck[/]" if s.stuck else "")
            entropy, modal = _num(s.entropy_bits), f"{say(s.modal)} {s.modal_share:.0%}"
        sensitive = "yes" if x.sensitive else "no" if x.kind == "action" else "[red]no[/]"
        a.add_row(str(name), used, entropy, modal, _num(x.r2), _num(x.null_mean),
                  _num(x.p_value, "{:.3f}"), sensitive)
    console.print(a)
    params = sens[sens["kind"] == "parameter"]
    if not params.empty:
        p = Table("motion parameter", "R²", "null", "p", "sensitive",
                  title="motion parameters of its profiles")
        for name, x in params.iterrows():
            p.add_row(str(name), _num(x.r2), _num(x.null_mean), _num(x.p_value, "{:.3f}"),
                      "yes" if x.sensitive else "[red]no[/]")
        console.print(p)
    d = Table("persona field → answer", "expected", "Spearman ρ [95%]", "outcome",
              title="expected directions")
    for x in _rows(t, "directions", r.respondent).itertuples(index=False):
        d.add_row(f"{x.field} → {x.target}", x.expected,
                  rho_text(x.rho, x.ci_low, x.ci_high), _outcome(x.outcome))
    console.print(d)
    _print_retest(_rows(t, "retest", r.respondent), r.retest)
    m = _rows(t, "manipulation", r.respondent)
    if m.empty:
        console.print("matched intervention: no persona was asked both variants.")
        return
    mt = Table("item", "expected", "shift [95%]", "up / down", "outcome",
               title=f"matched intervention: deadline − baseline ({int(m['n'].iloc[0])} personas)")
    for x in m[m["target"] != "actions"].itertuples(index=False):
        mt.add_row(x.target, x.expected, f"{x.shift:+.3f} [{x.ci_low:+.3f}, {x.ci_high:+.3f}]",
                   f"{x.up:.0%} / {x.down:.0%}", _outcome(x.outcome))
    console.print(mt)
    changed = m.loc[m["target"] == "actions", "changed"].iloc[0]
    console.print(f"probe actions changed by the deadline: {changed:.0%}", highlight=False)


def _print_retest(g: pd.DataFrame, summary: str) -> None:
    """The test–retest table, or the line saying it was not measured and how to."""
    if g.empty:
        console.print(f"test–retest: {say(summary)}", highlight=False)
        return
    from ..analysis.audit_verdict import MIN_ICC

    t = Table("answer / parameter", "all samples agree", "κ / ICC", "within var",
              "between var", title=f"test–retest: {say(summary)}")
    for x in g.itertuples(index=False):
        stat = f"κ {_num(x.kappa)}" if x.kind == "action" else (
            f"ICC {_num(x.icc)}" if not x.icc < MIN_ICC else f"[red]ICC {_num(x.icc)}[/]")
        t.add_row(x.target, _num(x.agree, "{:.0%}"), stat,
                  _num(getattr(x, "within_var", None), "{:.4f}"),
                  _num(getattr(x, "between_var", None), "{:.4f}"))
    console.print(t)


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
    console.print(t)
