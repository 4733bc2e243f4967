"""The report's first paragraph: the answer in plain words, generated from the verdicts.

"Do controller rankings change with the pedestrian population beyond noise?" is
answered per aspect — pedestrian burden (mean delay, worst-decile delay, CVaR-90) and
robot time — from the raw-rule verdicts of the headline (:mod:`popnavshift.analysis.verdicts`),
for the matched time-pressure shift and for the population pairs, each with its design;
then what orderings decided under both populations do, what the overall controller
order does across populations, and the false-positive rate the deciding test showed on
the study's own placebos. Nothing here is written by hand: every word that carries a
result comes from a table, so a study with other results reads otherwise.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pandas as pd

from ..analysis.interaction import CHANGES
from ..analysis.ranked import RANKED_METRICS, names
from ..analysis.reversals import COMPARISONS
from ..analysis.verdicts import (
    ABOVE,
    BELOW,
    NOT_SHOWN,
    SMALL,
    UNDECIDED,
    min_nulls_permutation,
)
from ..populations.identity import NULL_KINDS
from ..viz.style import controller_label
from .blocks import pct
from .figures import pop_label

BURDEN = names("burden")
ROBOT = names("robot")
LABELS = {m.name: m.label for m in RANKED_METRICS}


def null_words(kind: str, otherwise: str) -> str:
    """A null design kind's replicates in words, as it declares them
    (:data:`popnavshift.populations.identity.NULL_KINDS`); ``otherwise`` for another kind."""
    return NULL_KINDS[kind].words if kind in NULL_KINDS else otherwise


def pp(x: float, signed: bool = True) -> str:
    """A rate difference in percentage points: ``+8.6 pp``."""
    return "–" if not np.isfinite(x) else f"{100 * x:{'+' if signed else ''}.1f} pp"


def interval(r: Any) -> str:
    """``+9.0 pp [+3.6, +14.5]``: an excess and its deciding (simultaneous) interval."""
    low, high = (pp(r[k]).removesuffix(" pp") for k in ("ci_low", "ci_high"))
    return f"{pp(r['excess'])} [{low}, {high}]"


def join(words: list[str]) -> str:
    return words[0] if len(words) == 1 else ", ".join(words[:-1]) + " and " + words[-1]




def _phrase(comp: str) -> str:
    """A comparison in a sentence, as it is declared (:data:`.reversals.COMPARISONS`)."""
    return COMPARISONS[comp].phrase if comp in COMPARISONS else comp


def design_phrase(r: Any, n_pairs: int, n_populations: int) -> str:
    """Where a comparison's rates come from: its design and its null."""
    design = (f"{int(r['variants_per_cell'])} variants per cell, against {int(r['n_null'])} "
              f"{null_words(str(r['null']), 'null replicates')}")
    if r["comparison"] == "matched":
        return f"under the matched time-pressure shift (same personas; {design})"
    return f"across the {n_pairs} pairs of the {n_populations} populations ({design})"


def _clauses(rows: pd.DataFrame) -> list[str]:
    """The metrics of one comparison grouped by verdict, each with its excess and interval."""
    words = {ABOVE: "reverse more often than under the null",
             SMALL: "show no excess of 5 pp or more over the null",
             BELOW: "reverse less often than under the null",
             UNDECIDED: "are undecided"}
    out = []
    for verdict, phrase in words.items():
        sel = rows[rows["verdict"] == verdict]
        if sel.empty:
            continue
        names = [LABELS[m] for m in sel["metric"]]
        figures = "; ".join(f"{LABELS[r.metric]} {interval(r._asdict())}"
                            for r in sel.itertuples()) if len(sel) > 1 else interval(
            sel.iloc[0])
        out.append(f"{join(names)} orderings {phrase} ({figures})")
    return out


def _answer_word(rows: pd.DataFrame) -> str:
    if (rows["verdict"] == ABOVE).any():
        return "yes"
    if rows["verdict"].isin([SMALL, BELOW]).all():
        return "no"
    return "not decided"


def aspect_sentences(head: pd.DataFrame, metrics: tuple[str, ...], lead: str, n_pairs: int,
                     n_populations: int, *, designs: bool = True) -> dict[str, str] | None:
    """One aspect's answer (yes / no / not decided) and, per comparison, its clauses;
    ``designs`` spells out each comparison's design (the first aspect does, the next
    refer back to it)."""
    raw = head[(head["rule"] == "raw") & head["metric"].isin(metrics) & (head["n_null"] > 0)]
    if raw.empty:
        return None
    parts = []
    for comp in COMPARISONS:
        rows = raw[raw["comparison"] == comp]
        if rows.empty:
            continue
        where = (design_phrase(rows.iloc[0], n_pairs, n_populations) if designs
                 else _phrase(comp))
        parts.append(where[0].upper() + where[1:] + ", " + "; ".join(_clauses(rows)) + ".")
    return {"lead": f"{lead}: {_answer_word(raw)}.", "text": " ".join(parts)}


def interaction_sentence(inter: pd.DataFrame | None) -> dict[str, str] | None:
    """Whether controller differences change with the population more than under the null
    (the interaction test, :mod:`popnavshift.analysis.interaction`), per comparison."""
    if inter is None or inter.empty or "verdict" not in inter:
        return None
    rows = inter[inter["n_null"] >= 3]
    if rows.empty:
        return None
    order = {m: i for i, m in enumerate((*BURDEN, *ROBOT))}
    parts = []
    for comp in [c for c in COMPARISONS if c in set(rows["comparison"])]:
        c = rows[rows["comparison"] == comp].sort_values(
            "metric", key=lambda m: m.map(lambda x: order.get(x, 99)))
        bits = []
        for changes, words in ((True, "change more than under the null"),
                               (False, "are not shown to change more than under the null")):
            sel = c[(c["verdict"] == CHANGES) == changes]
            if sel.empty:
                continue
            figures = "; ".join(f"{LABELS.get(r.metric, r.metric)} t = {r.t:.1f}, adjusted "
                                f"p = {r.p_adj:.2g}" for r in sel.itertuples())
            bits.append(f"{join([LABELS.get(m, m) for m in sel['metric']])} differences "
                        f"{words} ({figures})")
        parts.append(f"{_phrase(comp)}, " + "; ".join(bits))
    some = (rows["verdict"] == CHANGES).any()
    m, alpha = int(rows["family"].max()), float(rows["alpha_row"].max())
    return {"lead": "Controller differences change with the population: "
                    + ("yes, beyond the null." if some else "not shown beyond the null."),
            "text": "Whether the difference between two controllers changes from one "
                    "population to the other more than between null replicates, over every "
                    "cell and controller pair (a rank test of the standardized differences "
                    f"against {int(rows['n_null'].min())} replicates, each of its {m} rows at "
                    f"p ≤ {alpha:.3g}; not whether orderings cross): " + "; ".join(parts)
                    + "."}


def decided_sentence(head: pd.DataFrame) -> dict[str, str] | None:
    """What orderings significant under both populations do (the significant rule)."""
    sig = head[(head["rule"] == "sig") & (head["n_null"] > 0)]
    if sig.empty:
        return None
    parts = []
    for comp, rows in sig.groupby("comparison", sort=False):
        name = _phrase(comp)
        above = [LABELS[m] for m in rows.loc[rows["verdict"] == ABOVE, "metric"]]
        counts = (f"{rows['reversals'].min()}–{rows['reversals'].max()}"
                  if rows["reversals"].nunique() > 1 else f"{rows['reversals'].iloc[0]}")
        total = (f"{rows['comparable'].min():,}–{rows['comparable'].max():,}"
                 if rows["comparable"].nunique() > 1 else f"{rows['comparable'].iloc[0]:,}")
        # the words follow the verdicts, decided at the table's level (5% / its m rates)
        level = (float(rows["level"].iloc[0]) if "level" in rows else 0.95)
        alpha = 1 - level
        test = ("; the exact permutation test puts " + join(above) + " above the null"
                if above else "; the exact permutation test shows none above the null"
                if (rows["verdict"] == NOT_SHOWN).all() else
                f" (descriptive: {int(rows['n_null'].min())} null replicates cannot bring the "
                f"exact test to its level, p ≤ {alpha:.3g}; it needs "
                f"{min_nulls_permutation(alpha)})")
        parts.append(f"{name}, {counts} reversals per metric among {total}{test}")
    low, high = 100 * sig["observed"].min(), 100 * sig["observed"].max()
    return {"lead": f"Decided orderings flip in {low:.0f}–{high:.0f}% of comparisons.",
            "text": "Of the orderings significant under both populations (90% paired "
                    "interval excludes 0): " + "; ".join(parts) + "."}


def order_sentence(ranks: pd.DataFrame | None) -> dict[str, str] | None:
    """Whether the controllers' overall (grid-mean) order is the same in every population."""
    if ranks is None or ranks.empty:
        return None
    r = ranks[ranks["comparison"] == "all_pairs"] if (ranks["comparison"] == "all_pairs").any() \
        else ranks
    same, differ = [], []
    n_pops = r["population"].nunique()
    for metric in [m for m in (*BURDEN, *ROBOT) if m in set(r["metric"])]:
        sub = r[r["metric"] == metric]
        orders = sub.sort_values("rank").groupby("population", sort=False)["controller"].agg(
            tuple)
        modal = orders.value_counts().index[0]
        text = " < ".join(controller_label(c) for c in modal)
        if orders.nunique() == 1:
            same.append(f"{LABELS[metric]} ({text})")
        else:
            other = [pop_label(p) for p in orders.index[orders != modal]]
            differ.append(f"{LABELS[metric]} ({text} in {n_pops - len(other)} of {n_pops}; "
                          f"another order in {join(other)})")
    if not differ:
        return {"lead": "The overall order does not change.",
                "text": f"The controllers' grid-mean order (lowest first) is the same in all "
                        f"{n_pops} populations for " + join(same) + "."}
    text = ("The controllers' grid-mean order (lowest first; point ranks, whose intervals are in "
            "the rank table) changes for " + join(differ))
    if same:
        text += " and is the same in every population for " + join(same)
    return {"lead": "The overall order changes for some metrics.", "text": text + "."}


def crossover_sentence(crossovers: pd.DataFrame | None) -> dict[str, str] | None:
    """Cell by cell: crossovers found, and the size the tests could have seen (80 % power)."""
    if crossovers is None or crossovers.empty or "detectable" not in crossovers:
        return None
    x = crossovers[crossovers["metric"] == "mean_delay"]
    if x.empty:
        return None
    parts = []
    for comp, g in x.groupby("comparison", sort=False):
        found, tests = int(g["crossover"].sum()), int(g["p"].notna().sum())
        if tests == 0:
            parts.append(f"{_phrase(comp)}, no test is possible (one episode per "
                         "cell has no spread to judge a sign by)")
            continue
        size = float(g["detectable"].median())
        parts.append(f"{_phrase(comp)}, {found} of {tests} (cell, controller pair) "
                     f"tests find a mean-delay crossover, with 80% power only for one of "
                     f"±{size:.2g} s")
    total = int(x["crossover"].sum())
    return {"lead": ("Cell by cell, nothing can be tested." if x["p"].notna().sum() == 0 else
                     "No crossover is detected cell by cell." if total == 0 else
                     f"{total} mean-delay crossover{'s' if total != 1 else ''} cell by cell."),
            "text": "A crossover is one population under which a controller pair's ordering is "
                    "significantly one way and another under which it is the other (a paired "
                    "test, Holm over the cells): " + "; ".join(parts) + "."}


def calibration_sentence(calibration: pd.DataFrame | None) -> dict[str, str] | None:
    """The deciding test's false-positive rate on the study's own placebos: the headline
    table as a whole, and the test alone."""
    if calibration is None or calibration.empty:
        return None
    table = calibration[(calibration["comparison"] == "table")
                        & calibration["claim"].str.startswith("any rate")]
    test = calibration[(calibration["comparison"] == "all")
                       & (calibration["test"] == "prediction t")
                       & calibration["claim"].str.startswith("an effect")]
    if test.empty:
        return None
    t = test.iloc[0]
    family = ""
    if not table.empty:
        f = table.iloc[0]
        family = (f" The table's rates are decided together (Bonferroni): the whole table "
                  f"claimed an effect on {int(f['claims'])} of {int(f['placebos'])} placebo "
                  f"tables ({pct(f['rate'])} [95% {pct(f['cp_low'])}, {pct(f['cp_high'])}]) at "
                  f"a nominal {pct(f['nominal'])}.")
    return {"lead": "How these are decided.",
            "text": "Each yes or no rests on the raw reversal rate (the paper's tie rule) against "
                    "null replicates run on the same episodes, by a prediction t on the spread "
                    f"between replicates; alone, on {int(t['placebos'])} placebos drawn from this "
                    f"study's own nulls, it claimed an effect in {pct(t['rate'])} "
                    f"[95% {pct(t['cp_low'])}, {pct(t['cp_high'])}] at a nominal "
                    f"{pct(t['nominal'])}." + family + " Intervals are simultaneous 95% "
                    "intervals over the headline table (calibration section)."}


def answer_sentences(tables: dict[str, pd.DataFrame]
                     ) -> tuple[list[dict[str, str]], list[dict[str, str]]]:
    """The first paragraph — the question's answer per aspect and what the overall order
    does — and the second — what the answer rests on (decided orderings, calibration)."""
    head = tables.get("evidence_headline")
    if head is None or head.empty:
        return [], []
    ranks = tables.get("evidence_ranks")
    n_pops = int(ranks.loc[ranks["comparison"] == "all_pairs", "population"].nunique()) \
        if ranks is not None and not ranks.empty else 0
    pairs = n_pops * (n_pops - 1) // 2
    answer = [aspect_sentences(head, BURDEN, "Pedestrian burden", pairs, n_pops),
              aspect_sentences(head, ROBOT, "Robot time", pairs, n_pops, designs=False)]
    if not any(answer):
        answer = [{"lead": "Not decided.",
                   "text": "This study ran no null replicates, so no reversal rate can be set "
                           "against what noise alone produces at the same design: its rates are "
                           "descriptive. The paper study runs them (`null_design` parts: "
                           "`popnavshift run`)."}]
    answer.append(interaction_sentence(tables.get("evidence_interaction")))
    answer.append(order_sentence(ranks))
    support = [decided_sentence(head), crossover_sentence(tables.get("evidence_crossovers")),
               calibration_sentence(tables.get("evidence_calibration"))]
    return [s for s in answer if s], [s for s in support if s]
