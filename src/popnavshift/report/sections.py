"""The report's sections of the paper's results: an
:class:`~popnavshift.analysis.study.Analysis` → findings, Table I, the noise floor,
Table II, Fig. 2, Fig. 4, Kendall τ and the trade-off, each declared once
(:class:`.blocks.SectionSpec`) with a function of its content (a list of blocks), with the
paper's figures (:mod:`popnavshift.analysis.paper_reference`) beside ours. The sections
about the study itself are in :mod:`.study_sections`.
"""

from __future__ import annotations

from typing import Any

import pandas as pd

from ..analysis import METRICS
from ..analysis import paper_reference as paper
from ..analysis.reversals import COMPARISONS
from ..analysis.study import CHANGE_METRICS
from ..analysis.summary import controller_order
from ..analysis.surviving import findings_list
from ..analysis.verdicts import ABOVE
from ..paper import CONTROLLERS
from ..populations.build import population_order
from ..populations.identity import MATCHED_PAIR
from ..viz.style import controller_label
from .blocks import Block, Cell, Page, SectionSpec, fmt, para, pct, table
from .figures import METRIC_LABELS, change_rows, pop_label, tau_matrix

OUTCOME_ROWS = (  # Table II rows: column of controller_outcomes, label, number format
    ("success_pct", "Success (%)", "{:.1f}"),
    ("pedestrian_collision_pct", "Pedestrian collision (%)", "{:.1f}"),
    ("world_collision_pct", "World collision (%)", "{:.1f}"),
    ("timeout_pct", "Timeout (%)", "{:.1f}"),
    ("controller_error_pct", "Controller error (%)", "{:.1f}"),  # shown only when present
    ("robot_time", "Robot travel time (s)", "{:.1f}"),
    ("min_clearance", "Minimum clearance (m)", "{:.2f}"),
    ("mean_delay", "Mean added delay (s)", "{:.2f}"),
    ("worst_decile", "Worst-decile delay (s)", "{:.2f}"),
)
WORDS = {"success_pct": "success rate", "timeout_pct": "timeout rate", "mean_delay": "mean delay",
         "worst_decile": "worst-decile delay", "robot_time": "robot travel time",
         **{c.name: c.label for c in CONTROLLERS}}


def words(text: str) -> str:
    """A finding's statement with column names in words and the paper's controllers by
    their names (:data:`popnavshift.paper.CONTROLLERS`)."""
    for k, v in WORDS.items():
        text = text.replace(k, v)
    return text


# --- Sections ----------------------------------------------------------------------------------


def _finding_numbers(statement: str, numbers: dict[str, Any]) -> str:
    rate = "reversal rate" in statement

    def one(v: Any) -> str:
        if isinstance(v, bool):
            return "yes" if v else "no"
        if isinstance(v, (tuple, list)):
            return " → ".join(one(x) for x in v)
        return pct(v) if rate else fmt(v)

    def key(k: Any) -> str:
        return f"{k:g} m" if isinstance(k, float) else words(str(k)).replace("_", " ")

    return "; ".join(f"{key(k)}: {one(v)}" for k, v in numbers.items())


def _summary(p: Page, t: pd.DataFrame) -> list[Block]:
    a = p.a
    held = sum(f.holds for f in a.findings)
    judged = findings_list(t, a.tables.get("evidence_findings"),
                           a.tables.get("evidence_burden")).set_index("statement")
    tested = judged[judged["judged_by"] != "point estimate only"]
    out = [para(f"{held} of the {len(a.findings)} qualitative findings of the paper "
                "(§V) that could be checked hold on this run's point estimates; "
                f"{int((tested['survives'] == True).sum())} of the {len(tested)} that "  # noqa: E712
                "can be judged beyond noise survive it (their 90% paired-bootstrap "
                "interval agrees, or, for the reversal findings, their excess over the "
                "null is above 0). Each line is computed from this study's tables; the "
                "numbers are ours.")]
    if a.cells is not None:
        n_cells, n_pops = a.cells["cell"].nunique(), a.cells["population"].nunique()
        if n_cells < paper.N_CELLS or n_pops < paper.N_POPULATIONS:
            out.append(para(
                f"This run covers {n_cells} cells and {n_pops} population"
                f"{'' if n_pops == 1 else 's'} (the paper: "
                f"{paper.N_CELLS} and {paper.N_POPULATIONS}). With so few cells the intervals are "
                "wide and findings can flip with more data.", "note"))
    if a.missing.get("findings"):
        out.append(para(a.missing["findings"].capitalize() + ".", "note"))
    out.append({"kind": "findings", "entries": [
        {"holds": f.holds, "statement": words(f.statement)[:1].upper() + words(f.statement)[1:],
         "numbers": _finding_numbers(f.statement, f.numbers),
         "beyond": _beyond(judged.loc[f.statement])} for f in a.findings]})
    return out


SUMMARY = SectionSpec("summary", "The paper's findings on this study: which hold, and which "
                      "beyond noise", _summary, needs=("findings",), otherwise="nothing to check")


def _beyond(j: pd.Series) -> str:
    """Whether a finding survives the noise, and on what."""
    if j["judged_by"] == "point estimate only":
        return "Beyond noise: not judged (point estimate only)."
    word = {True: "survives", False: "does not survive"}.get(j["survives"], "undecided")
    return f"Beyond noise, judged by {j['judged_by']}: {word} — {j['evidence']}."


def _rate_row(t: pd.DataFrame, metric: str, scopes: tuple[str, ...]) -> list[Any]:
    row: list[Any] = [METRIC_LABELS[metric]]
    for scope in scopes:
        r = t[(t["cells"] == scope) & (t["metric"] == metric)].iloc[0]
        row += [Cell(pct(r.rate), "num strong"), f"[{pct(r.ci_low)}, {pct(r.ci_high)}]",
                f"{r.reversals}/{r.comparisons}", Cell(pct(r.paper_rate), "paper")]
    return row


def _reversals(p: Page, t: pd.DataFrame) -> list[Block]:
    a = p.a
    out = []
    note = descriptive_note(a.tables.get("evidence_headline"), a.tables.get("evidence_power"))
    if note:
        out.append(para(note, "warn"))
    cols = ["Metric"] + ["Ours", "95% CI", "Reversals / comparable", "Paper"] * 2
    groups = [("", 1), ("All cells", 4), ("Completed cells", 4)]
    pops = a.cells["population"].nunique() if a.cells is not None else 0
    variants = int(a.cells["n_runs"].median()) if a.cells is not None else 0
    design = (f"main grid, {variants} variants per cell (the paper's design; the answer's "
              "rates pool more seed sets where the study ran them)")
    for comp, title in (("all_pairs", f"All {pops * (pops - 1) // 2} population pairs"),
                        ("matched", "Matched time-pressure intervention ("
                         + " vs ".join(MATCHED_PAIR) + ", same personas)")):
        sel = t[t["comparison"] == comp]
        if sel.empty:
            lacks = (f"the study lacks the matched pair ({', '.join(MATCHED_PAIR)})"
                     if comp == "matched" else "not available")
            out.append(para(f"{title}: {lacks}.", "note"))
            continue
        rows = [_rate_row(sel, m, ("all", "completed")) for m in METRICS]
        out.append(table(cols, rows, caption=f"{title} — {design}", csv="reversals",
                         groups=groups))
    return out + p.figure("reversal_rates", "Reversal rates with 95% intervals; black "
                          "diamonds: the paper's values.")


REVERSALS = SectionSpec(
    "table1", "Ranking reversals across populations (paper Table I, §V-A)", _reversals,
    needs=("reversals",),
    intro="Share of comparable controller comparisons (non-tied under both populations) "
          "whose order flips, pooled over cells and controller pairs; 95% cluster-bootstrap "
          "intervals resample cells. Completed cells: every controller succeeded on every "
          "variant under both populations.")


def descriptive_note(head: pd.DataFrame | None, power: pd.DataFrame | None) -> str:
    """Why Table I is descriptive: which of its comparisons no rate of beats its null."""
    if head is None or power is None or head.empty or power.empty:
        return ""
    raw = power[power["rule"] == "raw"]
    within = [c for c, g in raw.groupby("comparison", sort=False)
              if not (g["verdict"] == ABOVE).any()]
    if not within:
        return ""
    which = " and ".join(COMPARISONS[c].noun if c in COMPARISONS else c for c in within)
    return (f"Descriptive: for {which}, no raw rate below is above its null at the same design "
            "(see 'The answer'): these rates reproduce the paper's statistic, and most of "
            "them are what noise alone produces.")


def _noise(p: Page, t: pd.DataFrame) -> list[Block]:
    pairs = p.a.tables.get("reversals", pd.DataFrame(columns=["comparison", "cells", "metric"]))
    pairs = pairs[pairs["comparison"] == "all_pairs"].set_index(["cells", "metric"])["rate"]
    order = {m: i for i, m in enumerate(METRICS)}
    t = t.sort_values(["population", "cells", "metric"], key=lambda c: c.map(order)
                      if c.name == "metric" else c, kind="stable")
    rows = [[pop_label(r.population), r.cells, METRIC_LABELS[r.metric],
             f"{r.reversals}/{r.comparisons}", Cell(pct(r.rate), "strong"),
             pct(pairs.get((r.cells, r.metric)))] for r in t.itertuples(index=False)]
    return [table(["Split population", "Cells", "Metric", "Reversals / comparable",
                   "Noise floor", "All population pairs"], rows, csv="noise_floor")]


NOISE = SectionSpec(
    "noise", "Noise floor: reversals between two random halves of one population", _noise,
    needs=("noise_floor",),
    intro="What sampling noise alone produces: the same population split at random into two "
          "halves, compared like two populations. Rates between real populations (Table I) "
          "mean little unless they exceed this floor.")


def _outcomes(p: Page, t: pd.DataFrame) -> list[Block]:
    t = t.set_index("controller")
    ctrls = controller_order(t.index)
    theirs = paper.CONTROLLER_OUTCOMES
    cols = ["Outcome"] + ["Ours", "Paper"] * len(ctrls)
    groups = [("", 1)] + [(controller_label(c), 2) for c in ctrls]
    rows: list[list[Any]] = [[label] + [x for c in ctrls for x in (
        Cell(fmt(t.at[c, col], pattern), "num strong"),
        Cell(fmt(theirs.get(c, {}).get(col), pattern), "paper"))] for col, label, pattern in
        OUTCOME_ROWS if col in t.columns]
    rows.append(["Robot runs"] + [x for c in ctrls for x in (int(t.at[c, "n_runs"]), "")])
    return [table(cols, rows, csv="controller_outcomes", groups=groups),
            para("Delays are the mean over (cell, population) rows of each cell's "
                 "statistic; robot time counts 45 s for failed runs.")]


OUTCOMES = SectionSpec("table2", "Controller outcomes (paper Table II, §V-C)", _outcomes,
                       needs=("controller_outcomes",))


def _change(p: Page, t: pd.DataFrame) -> list[Block]:
    out = p.figure("fig2_delay_change", "Shifted minus reference delay over the same cells; "
                   "outlined: the matched deadline intervention (same personas); the other "
                   "rows are compared with the homogeneous population.")
    ctrls = controller_order(t["controller"].unique())
    wide = t.pivot_table(index=["population", "reference"], columns=["metric", "controller"],
                         values="change")
    cols = ["Shifted − reference"] + [controller_label(c) for c in ctrls] * 2
    groups = [("", 1)] + [(f"{METRIC_LABELS[m]} (s)", len(ctrls))
                          for m in CHANGE_METRICS]
    order = change_rows(wide.index.get_level_values("population"))[0]
    refs = dict(wide.index.tolist())
    rows = [[f"{pop_label(q)} − {pop_label(refs[q])}"] + [
        fmt(wide.loc[(q, refs[q])].get((m, c)), "{:+.2f}") for m in CHANGE_METRICS
        for c in ctrls] for q in order]
    sign = paper.MATCHED_CHANGE_SIGN
    return out + [table(cols, rows, csv="delay_change", groups=groups), para(
        "The paper's matched row: lower delay under " + ", ".join(
            controller_label(c) for c, v in sign.items() if v < 0) + "; higher under "
        + ", ".join(controller_label(c) for c, v in sign.items() if v > 0) + ".")]


CHANGE = SectionSpec("change", "Change in pedestrian delay under population shift (paper Fig. 2)",
                     _change, needs=("delay_change",))


def _sensitivity(p: Page, t: pd.DataFrame) -> list[Block]:
    out = p.figure("fig4_width_sensitivity", "Range of mean delay across populations for a "
                   "fixed controller and cell, averaged per width.")
    views = [("sidewalk+bottleneck", "all", "pooled", "Both scenes"),
             ("sidewalk+bottleneck", "completed", "pooled", "Both scenes, completed cells"),
             ("sidewalk", "all", "pooled", "Sidewalks"), ("bottleneck", "all", "pooled",
                                                          "Bottlenecks")]
    views += [("sidewalk+bottleneck", "all", c, f"Both scenes, {controller_label(c)}")
              for c in controller_order(sorted(set(t["controller"]) - {"pooled"}))]
    rows = []
    for w in sorted(t["width"].unique()):
        row: list[Any] = [f"{w:g}"]
        for scenes, cells, ctrl, _ in views:
            v = t[(t["scenes"] == scenes) & (t["cells"] == cells) & (t["controller"] == ctrl)
                  & (t["width"] == w)]["sensitivity"]
            row.append(fmt(v.iloc[0] if len(v) else None))
        row.append(Cell(fmt(paper.WIDTH_SENSITIVITY.get(float(w))), "paper"))
        rows.append(row)
    cols = ["Width (m)"] + [f"{v[3]} (s)" for v in views] + ["Paper, pooled (s)"]
    return out + [table(cols, rows, csv="sensitivity_by_width")]


SENSITIVITY = SectionSpec("sensitivity", "Population sensitivity vs available width (paper "
                          "Fig. 4)", _sensitivity, needs=("sensitivity_by_width",))


def _tau(p: Page, t: pd.DataFrame) -> list[Block]:
    out = p.figure("kendall_tau", "Mean Kendall τ-b per population pair.")
    mats = {m: tau_matrix(t, m) for m in METRICS if (t["metric"] == m).any()}
    pops = list(next(iter(mats.values())).index)
    pairs = [(x, y) for i, x in enumerate(pops) for y in pops[i + 1:]]
    rows = [[f"{pop_label(x)} vs {pop_label(y)}"] + [fmt(m.loc[x, y]) for m in mats.values()]
            for x, y in pairs]
    return out + [table(["Population pair"] + [METRIC_LABELS[m] for m in mats], rows,
                        csv="kendall_tau", collapsed=True)]


TAU = SectionSpec(
    "tau", "Kendall τ between population rankings", _tau, needs=("kendall_tau",),
    intro="Kendall τ-b between the controller rankings of two populations in a cell (ties "
          "within the metric's tolerance), averaged over cells: 1 = same order everywhere, "
          "−1 = always reversed.")


def _tradeoff(p: Page, t: pd.DataFrame) -> list[Block]:
    out = p.figure("tradeoff", "Per population and controller: robot travel time against "
                   "mean (●) and worst-decile (▲) delay.")
    rank = {q: i for i, q in enumerate(population_order(t["population"]))}
    t = t.sort_values("population", key=lambda c: c.map(rank), kind="stable")
    rows = [[pop_label(r.population), controller_label(r.controller), fmt(r.robot_time),
             fmt(r.mean_delay), fmt(r.worst_decile), fmt(r.success_pct, "{:.1f}")]
            for r in t.itertuples(index=False)]
    return out + [table(["Population", "Controller", "Robot time (s)", "Mean delay (s)",
                         "Worst decile (s)", "Success (%)"], rows, csv="tradeoff",
                        collapsed=True)]


TRADEOFF = SectionSpec("tradeoff", "Robot time vs pedestrian burden, per population",
                       _tradeoff, needs=("tradeoff",))
