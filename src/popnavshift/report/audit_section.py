"""The respondent audit in the report: a banner under the title, a flag at the top of the
answer when the respondent that built the populations is not usable, and a section with
the audit's tables (:mod:`popnavshift.analysis.audit_verdict`)."""

from __future__ import annotations

from typing import Any

import pandas as pd

from ..analysis.audit import rho_text
from ..analysis.audit_power import POWER
from ..analysis.audit_power import USABLE as USABLE_EFFECTS
from ..analysis.audit_verdict import (
    ALPHA,
    MIN_DISTINCT_SHARE,
    MIN_EXCESS_R2,
    MIN_ICC,
    MIN_URGENCY_SHIFT,
    UNDECIDED,
    USABLE,
)
from .blocks import Block, Cell, Page, SectionSpec, fmt, para, pct, table

ROLE = {"first": "The respondent", "second": "The second respondent"}


def _who(r: Any) -> str:
    return f"{ROLE.get(r.respondent, r.respondent)} ({r.name}, {r.model})"


def _figures(r: Any) -> str:
    shift = "" if pd.isna(r.urgency_shift) else f", deadline urgency shift {r.urgency_shift:+.2f}"
    return (f"{r.sensitive_answers}/{r.answers} answers and {r.sensitive_parameters}/"
            f"{r.parameters} motion parameters persona-sensitive, {r.directions_as_expected}/"
            f"{r.directions} expected directions{shift}")


def audit_banner(tables: dict[str, pd.DataFrame]) -> tuple[str, str] | None:
    """(css class, text) of the banner under the title: every respondent's verdict; a
    warning when one is not usable; None without an audit."""
    v = tables.get("audit_verdict")
    if v is None or v.empty:
        return None
    parts = [f"{_who(r)}: {r.verdict.upper()} — " + (r.reasons if r.reasons else _figures(r))
             for r in v.itertuples()]
    cls = "note" if (v["verdict"] == USABLE).all() else "warn"
    return cls, "Respondent audit. " + " ".join(p.rstrip(".") + "." for p in parts)


def answer_flag(tables: dict[str, pd.DataFrame]) -> dict[str, Any] | None:
    """A warning for the top of the answer section when the first respondent (whose
    answers built the populations every rate compares) is not usable; else None."""
    v = tables.get("audit_verdict")
    first = v[v["respondent"] == "first"] if v is not None and not v.empty else None
    if first is None or first.empty or first["verdict"].iloc[0] == USABLE:
        return None
    r = first.iloc[0]
    if r["verdict"] == UNDECIDED:
        return para(f"Read the rates below with care: the respondent audit could not tell "
                    f"whether the respondent whose answers built these populations "
                    f"({r['name']}, {r['model']}) follows the persona — {r['reasons']}. Every "
                    "population compared below is built from its answers.", "warn")
    return para(f"Read the rates below with care: the respondent whose answers built these "
                f"populations ({r['name']}, {r['model']}) is {r['verdict'].upper()} by the "
                f"respondent audit — {r['reasons']}. Every population compared below is built "
                "from its answers, so a reversal rate measures that respondent, not "
                "persona-driven behaviour.", "warn")


METHOD = (f"Computed from the study's own answer tables, nothing asked again. An answer or "
          f"motion parameter is persona-sensitive when its R² on the persona fields "
          f"beats the same R² with the persona rows shuffled at p ≤ {ALPHA:g} (Bonferroni "
          f"within answers and within parameters) and exceeds the shuffles' mean by at least "
          f"{MIN_EXCESS_R2:g}. Not persona-sensitive: no answer is. Weak: a stuck answer (an "
          f"item on ≤ 2 of 5 levels, a probe on one action), a block item, the action score or a "
          f"motion parameter that is not persona-sensitive (a single probe's action is shown, "
          f"not required: the mappings read the actions through their score), fewer distinct "
          f"answer rows than {MIN_DISTINCT_SHARE:.0%} of the distinct persona records, an "
          f"expected direction whose 95% interval does not "
          f"exclude 0 on its side, or a deadline shift of urgency below "
          f"{MIN_URGENCY_SHIFT:+.3f} (half a level) or a declared item moved against its "
          f"direction; with two or more samples per persona, also a block item, the action "
          f"score or a motion parameter whose test–retest ICC is below {MIN_ICC:g}, or a "
          f"server at temperature 0 whose samples differ (not reproducible). With one sample "
          f"per persona, test–retest is not measured (--samples 2 measures it). Each check "
          f"states the smallest effect it detects with {POWER:.0%} power at this number of "
          f"personas and samples; a check that fails without the power to see a usable "
          f"respondent's effect (R² {USABLE_EFFECTS['sensitivity']:.2f}, ρ "
          f"{USABLE_EFFECTS['direction']:.1f}, an urgency shift of one level, ICC "
          f"{USABLE_EFFECTS['retest']:.2f}) makes the verdict '{UNDECIDED}', with the size "
          f"it needs, never 'weak' (docs/analysis.md §11).")


def _audit(p: Page, v: pd.DataFrame) -> list[Block]:
    """Verdicts, then per respondent its answers' spread and sensitivity, the expected
    directions and the matched intervention, then the two respondents' agreement."""
    tables = p.a.tables
    s: list[Block] = [para(METHOD, "note")]
    s.append(table(
        ["Respondent", "Model", "Personas", "Distinct answer rows", "Distinct persona records",
         "Figures", "Verdict", "What fails"],
        [[r.respondent, r.model, r.personas, r.answer_rows, r.persona_records, _figures(r),
          Cell(r.verdict, "ok" if r.verdict == USABLE else "bad"), r.reasons or "–"]
         for r in v.itertuples()],
        caption="Verdict per respondent", csv="audit_verdict"))
    sens, spread = tables["audit_sensitivity"], tables["audit_spread"]
    for r in v.itertuples():
        sp = spread[spread["respondent"] == r.respondent].set_index("column")
        se = sens[sens["respondent"] == r.respondent]
        rows = []
        for x in se.itertuples():
            spr = sp.loc[x.target] if x.target in sp.index else None
            rows.append([x.target, x.kind,
                         "" if spr is None else f"{spr['used']}/{spr['levels']}"
                         + (" stuck" if spr["stuck"] else ""),
                         "" if spr is None else fmt(spr["entropy_bits"]),
                         "" if spr is None else f"{spr['modal']} ({pct(spr['modal_share'])})",
                         fmt(x.r2), fmt(x.null_mean), fmt(x.excess, "{:+.3f}"),
                         fmt(x.p_value, "{:.3f}"), fmt(getattr(x, "mde", None)),
                         Cell("yes" if x.sensitive else "no", "ok" if x.sensitive else "bad")])
        s.append(table(["Answer / parameter", "Kind", "Levels used", "Entropy (bits)",
                        "Modal (share)", "R²", "Null R²", "Excess", "p",
                        "Smallest detectable R²", "Sensitive"],
                       rows, caption=f"{_who(r)}: spread and persona sensitivity",
                       csv="audit_sensitivity", collapsed=True))
    _directions(s, tables.get("audit_directions"))
    _manipulation(s, tables.get("audit_manipulation"))
    _retest(s, v, tables.get("audit_retest"))
    _agreement(s, tables.get("audit_agreement"))
    return s


AUDIT = SectionSpec("audit", "Respondent audit: do the answers follow the persona?", _audit,
                    needs=("audit_verdict",), otherwise="the study folder has no responses table")


def _retest(s: list[Block], v: pd.DataFrame, g: pd.DataFrame | None) -> None:
    """Test–retest per respondent: its table, or a line saying it was not measured."""
    for r in v.itertuples():
        rows = g[g["respondent"] == r.respondent] if g is not None and not g.empty else None
        if rows is None or rows.empty:
            s.append(para(f"{_who(r)}: test–retest {r.retest}.", "note"))
            continue
        cells = [[x.target, x.kind, pct(x.agree),
                  f"κ {fmt(x.kappa)}" if x.kind == "action" else
                  Cell(f"ICC {fmt(x.icc)}", "bad" if x.icc < MIN_ICC else "ok"),
                  fmt(getattr(x, "within_var", None), "{:.4f}"),
                  fmt(getattr(x, "between_var", None), "{:.4f}")] for x in rows.itertuples()]
        s.append(table(["Answer / parameter", "Kind", "All samples agree",
                        "κ / ICC", "Within-persona variance",
                        "Between-persona variance"], cells,
                       caption=f"{_who(r)}: test–retest, {r.retest}",
                       csv="audit_retest", collapsed=True))


def _directions(s: list[Block], d: pd.DataFrame | None) -> None:
    if d is None or d.empty:
        return
    rows = [[r.respondent, f"{r.field} → {r.target}", r.expected, r.why,
             rho_text(r.rho, r.ci_low, r.ci_high),
             Cell(r.outcome, "ok" if r.outcome == "as expected" else "bad")]
            for r in d.itertuples()]
    s.append(table(["Respondent", "Persona field → answer", "Expected", "Why",
                    "Spearman ρ [95%]", "Outcome"], rows,
                   caption="Expected directions", csv="audit_directions"))


def _manipulation(s: list[Block], m: pd.DataFrame | None) -> None:
    if m is None or m.empty:
        return
    rows = []
    for r in m.itertuples():
        if r.target == "actions":
            rows.append([r.respondent, "probe actions", "", "", "", pct(r.changed), ""])
            continue
        rows.append([r.respondent, r.target, r.expected,
                     f"{r.shift:+.3f} [{r.ci_low:+.3f}, {r.ci_high:+.3f}]",
                     f"{pct(r.up)} / {pct(r.down)}", pct(r.changed),
                     Cell(r.outcome, "bad" if r.outcome in ("flat", "reversed") else "")])
    s.append(table(["Respondent", "Answer", "Expected", "Deadline − baseline [95%]",
                    "Up / down", "Changed", "Outcome"], rows,
                   caption="Matched intervention: the same personas with time pressure "
                   "set to Deadline (paired)", csv="audit_manipulation"))


def _agreement(s: list[Block], g: pd.DataFrame | None) -> None:
    if g is None or g.empty:
        return
    stat = {"action": "κ", "item": "ρ", "parameter": "r"}
    rows = [[r.target, r.kind, r.n, pct(getattr(r, "agree", None)),
             pct(getattr(r, "within_one", None)),
             f"{stat[r.kind]} {fmt(getattr(r, stat[r.kind], None))}"] for r in g.itertuples()]
    s.append(table(["Answer / parameter", "Kind", "Records", "Agree", "Within one level",
                    "κ / Spearman ρ / Pearson r"], rows,
                   caption="Agreement of the two respondents (same persona and variant)",
                   csv="audit_agreement"))
