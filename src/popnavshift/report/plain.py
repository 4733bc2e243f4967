"""The report's first paragraph: the answer in plain words, generated from the verdicts.

"Do controller rankings change with the pedestrian population beyond noise?" is answered
per aspect — pedestrian burden (mean delay, worst-decile delay, CVaR-90, blocked
pedestrians) and robot time — per metric and per comparison design (the matched
time-pressure shift; the population pairs), by two questions, each with its own test:

1. do controller differences change with the population beyond the null? — the interaction
   test (``evidence_interaction``, :mod:`popnavshift.analysis.interaction`);
2. do orderings reverse beyond the null? — the raw reversal rate's verdict
   (``evidence_headline``, :mod:`popnavshift.analysis.verdicts`).

Every "no" says what it ruled out (a reversal excess of 5 pp or more; the interaction test
has no margin, so "not shown" rules out no size of change and says so); every "undecided"
says so and what would decide it (``evidence_power``, else ``popnavshift plan``). The
overall order is said to change only where rank intervals separate (:mod:`.plain_order`).
Nothing here is written by hand: every word that carries a result comes from a table, so
a study with other results reads otherwise. The second paragraph is :mod:`.plain_support`.
"""

from __future__ import annotations

import re
from typing import Any

import numpy as np
import pandas as pd

from ..analysis.interaction import CHANGES, NO_TERMS
from ..analysis.interaction import NOT_SHOWN as NOT_CHANGED
from ..analysis.power import POWER
from ..analysis.recombine import PREDICTION
from ..analysis.reversals import COMPARISONS
from ..analysis.verdicts import ABOVE, BELOW, MIN_NULLS_T, SMALL, UNDECIDED
from .larger import (
    larger_clause,
    larger_studies,
    measured_here,
    row_keys,
    split_undecided,
    unresolved,
)
from .plain_measured import measured_rate_sentence
from .plain_order import order_sentence
from .plain_support import calibration_sentence, crossover_sentence, decided_sentence
from .plain_words import (
    BURDEN,
    LABELS,
    MARGIN,
    ROBOT,
    by_metric,
    design_phrase,
    interval,
    join,
    label,
    null_words,
    phrase,
    pp,
)

__all__ = ["LABELS", "answer_sentences", "larger_study_sentence", "null_words", "pp"]

UNTESTED = "untested"
#: the interaction verdicts in a clause, a lead's main claim and a lead's aside
INTERACTION = {CHANGES: ("change more than under the null", "change beyond the null",
                         "change for"),
               NOT_CHANGED: ("are not shown to change more than under the null",
                             "are not shown to change beyond the null", "not shown for"),
               UNTESTED: ("cannot be tested for a change", "cannot be tested for a change",
                          "untested for")}
#: the reversal verdicts in a clause, a lead's main claim and a lead's aside
REVERSAL = {ABOVE: ("reverse more often than under the null", "reverse beyond the null",
                    "beyond the null for"),
            BELOW: ("reverse less often than under the null, so no excess is left",
                    "reverse less often than under the null", "below the null for"),
            SMALL: (f"show no excess of reversals of {MARGIN} or more over the null (an excess "
                    "that large is ruled out", f"show no excess of reversals of {MARGIN} or "
                    "more", f"no excess of {MARGIN} or more for"),
            UNDECIDED: (f"are undecided between no excess of reversals and one of {MARGIN} or "
                        "more (each interval holds 0 and reaches past " + MARGIN,
                        "are undecided", "undecided for")}


#: an undecided rate without an interval (its null replicates gave it no spread)
NO_INTERVAL = ("are undecided, with no interval to decide by (the null replicates give the "
               "rate no spread to judge it by")


def _interaction_verdict(r: Any) -> str:
    return UNTESTED if int(r["n_null"]) < MIN_NULLS_T else str(r["verdict"])


def _rows(tables: dict[str, pd.DataFrame]) -> pd.DataFrame:
    """One row per (comparison, metric) with a reversal verdict (``rev``, the raw rule's,
    where the rate has a null) and an interaction verdict (``inter``), either may be NaN."""
    head = tables["evidence_headline"]
    raw = head[(head["rule"] == "raw") & (head["n_null"] > 0)]
    rev = raw.assign(rev=raw["verdict"], test=raw.get("test", PREDICTION))[
        ["comparison", "metric", "rev", "excess", "ci_low", "ci_high", "test"]]
    inter = tables.get("evidence_interaction")
    if inter is None or inter.empty or "verdict" not in inter:
        return rev.assign(inter=np.nan, t=np.nan, p_adj=np.nan, n_null_i=0, terms_i=np.nan)
    terms = inter.get("terms", np.nan)
    i = inter.assign(inter=[_interaction_verdict(r) for _, r in inter.iterrows()],
                     n_null_i=inter["n_null"], terms_i=terms)[
        ["comparison", "metric", "inter", "t", "p_adj", "n_null_i", "terms_i"]]
    return rev.merge(i, on=["comparison", "metric"], how="outer")


def _figures(sel: pd.DataFrame, one: Any) -> str:
    """Per metric of ``sel`` the figure ``one(row)``, labelled when there are several."""
    figures = [one(r) for _, r in sel.iterrows()]
    if len(set(figures)) == 1:  # one figure (or the same words for every metric): once
        return figures[0]
    return "; ".join(f"{label(m)} {f}" for m, f in zip(sel["metric"], figures, strict=True))


def _inter_figure(r: Any) -> str:
    if r["inter"] == UNTESTED:
        if r.get("terms_i") == 0:  # not the replicates: nothing to rank in any design
            return NO_TERMS
        return f"{int(r['n_null_i'])} null replicates; the test needs {MIN_NULLS_T}"
    return f"t = {r['t']:.1f}, adjusted p = {r['p_adj']:.2g}"


def clause(sel: pd.DataFrame) -> str:
    """Metrics sharing both verdicts in one comparison: what their controller differences
    and their orderings do, each with its figures."""
    names = join([label(m) for m in sel["metric"]])
    their = "their" if len(sel) > 1 else "its"
    inter, rev = sel["inter"].iloc[0], sel["rev"].iloc[0]
    parts = []
    if isinstance(inter, str):
        tail = "; this rules out no size of change" if inter == NOT_CHANGED else ""
        parts.append(f"{names} differences {INTERACTION[inter][0]} "
                     f"({_figures(sel, _inter_figure)}{tail})")
    if isinstance(rev, str):
        words = REVERSAL.get(rev, (f"are {rev}",))[0]
        if rev == UNDECIDED and not np.isfinite(sel[["ci_low", "ci_high"]].to_numpy(float)).any():
            words = NO_INTERVAL  # no interval holds 0 or reaches anywhere
        opened = "(" in words  # the words open a parenthesis the figures close
        figures = _figures(sel, interval)
        rev_text = f"{words}: {figures})" if opened else f"{words} ({figures})"
        subject = f"{their} orderings" if parts else f"{names} orderings"
        parts.append(f"{subject} {rev_text}")
    return ", and ".join(parts)


def design_sentence(rows: pd.DataFrame, comp: str, where: str) -> str:
    """One comparison's clauses for one aspect, after its design (or its short name)."""
    keys = by_metric(rows).assign(i=rows["inter"].astype(object).fillna(""),
                                  r=rows["rev"].astype(object).fillna(""))
    clauses = [clause(g) for _, g in keys.groupby(["i", "r"], sort=False, dropna=False)]
    return where[0].upper() + where[1:] + ", " + "; ".join(clauses) + "."


def _fragment(rows: pd.DataFrame, column: str, words: dict, subject: str,
              metrics: tuple[str, ...]) -> str:
    """A lead's answer to one question for one comparison: its main claim, the rest aside."""
    groups = [(v, [label(m) for m in by_metric(rows[rows[column] == v])["metric"]])
              for v in words if (rows[column] == v).any()]
    if not groups:
        return ""
    every = len(metrics) == 1 or len(groups) == 1

    def names(ms: list[str]) -> str:
        return "" if every else " for " + join(ms)

    (v0, m0), rest = groups[0], groups[1:]
    main = f"{subject} {words[v0][1]}{names(m0)}"
    if rest:
        main += " (" + "; ".join(f"{words[v][2]} {join(ms)}" for v, ms in rest) + ")"
    return main


def aspect_sentence(rows: pd.DataFrame, metrics: tuple[str, ...], aspect: str,
                    head: pd.DataFrame, populations: list[str], *,
                    designs: bool = True) -> dict[str, str] | None:
    """One aspect's answer to both questions, per comparison: the lead sums it up, the text
    gives every metric's verdicts and figures; ``designs`` spells out each comparison's
    design (the first aspect does, the next refer back to it)."""
    own = rows[rows["metric"].isin(metrics)]
    if own.empty:
        return None
    comps = [c for c in COMPARISONS if c in set(own["comparison"])]
    leads, texts = {}, []
    for comp in comps:
        r = own[own["comparison"] == comp]
        frags = [_fragment(r, "inter", INTERACTION, "controller differences", metrics),
                 _fragment(r, "rev", REVERSAL, "orderings", metrics)]
        leads[comp] = " and ".join(f for f in frags if f)
        h = head[(head["comparison"] == comp) & (head["n_null"] > 0) & (head["rule"] == "raw")]
        where = (design_phrase(h, head, populations) if designs and not h.empty
                 else phrase(comp))
        texts.append(design_sentence(r, comp, where))
    if len(comps) > 1 and len(set(leads.values())) == 1:
        lead = f"{aspect}: under both designs, {leads[comps[0]]}."
    else:
        lead = f"{aspect}: " + "; ".join(f"{phrase(c)}, {leads[c]}" for c in comps) + "."
    return {"lead": lead, "text": " ".join(texts)}


def method_sentence(rows: pd.DataFrame, inter: pd.DataFrame | None) -> dict[str, str]:
    """The two questions and their tests, before the answers."""
    first = "whether orderings reverse more often than between null replicates"
    how = ("the raw reversal rate against its null; a simultaneous 95% interval: a no when it "
           f"rules out an excess of {MARGIN} or more")
    if inter is None or inter.empty or not rows["inter"].notna().any():
        return {"lead": "One question per metric and design.",
                "text": f"It is {first} ({how}); this study has no interaction test."}
    tested = inter[inter["n_null"] >= MIN_NULLS_T]
    level = (f", each of its {int(tested['family'].max())} rows at one-sided "
             f"p ≤ {float(tested['alpha_row'].max()):.3g}" if not tested.empty else "")
    return {"lead": "Two questions per metric and design.",
            "text": "Whether the difference between two controllers changes from one "
                    "population to the other more than between null replicates (a rank test "
                    "of the standardized differences over every cell and controller pair"
                    f"{level}; not whether orderings cross), and {first} ({how})."}


def _advice(r: Any) -> str:
    """What the power advice says would decide one undecided rate."""
    if np.isfinite(r.get("seed_sets_needed", np.nan)):
        minutes = r.get("minutes_needed", np.nan)
        cost = f"+{r['runs_needed']:,.0f} runs" + (f", about {minutes:.0f} min at this study's "
                                                   "speed" if np.isfinite(minutes) else "")
        chance = r.get("chance", np.nan)
        design = (f"{int(r['seed_sets_needed'])} seed sets and {int(r['nulls_needed'])} null "
                  f"replicates (about {cost})")
        model = "by the model of this study's own curve (the growth of its excess with seed " \
                "sets included)"
        if np.isfinite(chance) and chance < POWER:  # the most the limits promise: said so
            return (f"even the largest design within the power advice's limits, {design}, "
                    f"would decide it with only a {100 * chance:.0f}% chance {model}")
        odds = (f"with a {100 * chance:.0f}% chance" if np.isfinite(chance) else
                "with 80% power")
        return f"{design} would decide it {odds} {model}"
    if not isinstance(r.get("limit"), str):
        return ""
    if r["limit"].startswith("cannot estimate"):  # its reason is the advice: kept
        return "the power advice " + r["limit"].replace("cannot estimate",
                                                        "cannot estimate what would decide it", 1)
    # the limit without its parenthesised figures (they are in the power table)
    return "the power advice finds " + re.sub(r"\s*\([^()]*\)", "", r["limit"])


def larger_study_sentence(undecided: pd.DataFrame,
                          study: tuple[str, int | None] | None = None) -> str | None:
    """The larger built-in studies that decided some of the ``undecided`` rows
    (``comparison``, ``metric``, ``question``: "reversals" or "interaction") of ``study``
    (its name and seed), each row named with the smallest that did, with its runs and time,
    measured on its own seed (:mod:`.larger`); rows no measured design decided are said so
    with what was measured, and any other row is said to be decided by no built-in study.
    None when nothing is recorded for this study."""
    name, seed = study if study is not None else (None, None)
    studies = larger_studies(name) if name else []
    measured = unresolved(name) if name else []
    if not (studies or measured) or undecided.empty:
        return None
    said = []
    for question, words in (("reversals", "the reversal verdict"),
                            ("interaction", "the interaction test")):
        rest = undecided[undecided["question"] == question]
        for larger in studies:
            hit, rest = split_undecided(rest, question, larger)
            if len(hit):
                said.append(f"For {words} of {_where(hit)}, "
                            f"{larger_clause(larger, seed, len(hit))}.")
        for u in (u for u in measured if u.question == question):
            known = row_keys(rest).isin(u.rows).to_numpy()
            if known.any():
                said.append(f"No built-in study decides {words} of {_where(rest[known])}: "
                            f"{u.why}.")
            rest = rest[~known]
        if len(rest):
            said.append(f"No built-in study decided {words} of {_where(rest)}.")
    return " ".join(said) or None


def _where(rows: pd.DataFrame) -> str:
    """``worst-decile delay under the matched shift and CVaR-90 delay across the pairs``."""
    return join([f"{label(r.metric)} {phrase(r.comparison)}" for r in rows.itertuples()])


def undecided_sentence(rows: pd.DataFrame, power: pd.DataFrame | None,
                       study: tuple[str, int | None] | None = None) -> dict[str, str] | None:
    """The undecided rows and what would decide each: a measurement on this study's seed
    where one is recorded (:func:`larger_study_sentence`), else the power advice, else
    `plan`."""
    rev = rows[rows["rev"] == UNDECIDED]
    untested = rows[rows["inter"] == UNTESTED]
    if rev.empty and untested.empty:
        return None
    advice: dict[str, dict[str, list[str]]] = {}
    # a row a measurement on this seed settles gets the measurement, not the model's guess
    settled = measured_here(*study)["reversals"] if study is not None else frozenset()
    modelled = rev[~row_keys(rev).isin(settled).to_numpy()]
    for comp in [c for c in COMPARISONS if c in set(modelled["comparison"])]:
        for _, r in by_metric(modelled[modelled["comparison"] == comp]).iterrows():
            p = (power[(power["comparison"] == comp) & (power["metric"] == r["metric"])
                       & (power["rule"] == "raw")] if power is not None else pd.DataFrame())
            said = (_advice(p.iloc[0]) if not p.empty else "") or (
                "`popnavshift plan <study> --from <this folder>` estimates what would decide it")
            advice.setdefault(said, {}).setdefault(comp, []).append(label(r["metric"]))
    parts = ["For " + join([f"{join(ms)} {phrase(c)}" for c, ms in where.items()]) + ", "
             + said + "." for said, where in advice.items()]
    terms = untested.get("terms_i", pd.Series(np.nan, index=untested.index))
    no_terms = terms == 0  # untested for want of episodes, not of null replicates
    for group, words in ((untested[~no_terms], f"needs {MIN_NULLS_T} null replicates for "),
                         (untested[no_terms], "needs more episodes per cell (no controller "
                          "difference varies over one cell's episodes) for ")):
        if not group.empty:
            parts.append("The interaction test " + words
                         + join([f"{label(m)} {phrase(c)}" for c, m in
                                 zip(group["comparison"], group["metric"], strict=True)]) + ".")
    open_inter = rows[rows["inter"].isin([UNTESTED, NOT_CHANGED])]
    frame = pd.concat([rev.assign(question="reversals"),
                       open_inter.assign(question="interaction")])[
        ["comparison", "metric", "question"]]
    extra = larger_study_sentence(frame, study)
    return {"lead": "Undecided rows and what would decide them.",
            "text": " ".join(parts + ([extra] if extra else []))}


def _populations(ranks: pd.DataFrame | None) -> list[str]:
    if ranks is None or ranks.empty:
        return []
    return sorted(set(ranks.loc[ranks["comparison"] == "all_pairs", "population"]))


NO_NULLS = {"lead": "Not decided.",
            "text": "This study ran no null replicates, so no reversal rate can be set against "
                    "what noise alone produces at the same design: its rates are descriptive. "
                    "The paper study runs them (`null_design` parts: `popnavshift run`)."}


def answer_sentences(tables: dict[str, pd.DataFrame],
                     study: tuple[str, int | None] | None = None
                     ) -> tuple[list[dict[str, str]], list[dict[str, str]]]:
    """The first paragraph — both questions answered per aspect, metric and design, what
    would decide the undecided rows, what the overall order does — and the second — what
    the answer rests on (decided orderings, crossovers, calibration)."""
    head = tables.get("evidence_headline")
    if head is None or head.empty:
        return [], []
    ranks = tables.get("evidence_ranks")
    pops = _populations(ranks)
    rows = _rows(tables)
    answer: list[dict[str, str] | None]
    if rows.empty or rows["rev"].isna().all() and rows["inter"].isna().all():
        answer = [NO_NULLS]
    else:
        answer = [method_sentence(rows, tables.get("evidence_interaction")),
                  aspect_sentence(rows, BURDEN, "Pedestrian burden", head, pops),
                  aspect_sentence(rows, ROBOT, "Robot time", head, pops, designs=False),
                  undecided_sentence(rows, tables.get("evidence_power"), study),
                  measured_rate_sentence(rows, tables.get("evidence_interaction"), study)]
    answer.append(order_sentence(ranks))
    support = [decided_sentence(head), crossover_sentence(tables.get("evidence_crossovers")),
               calibration_sentence(tables.get("evidence_calibration"))]
    return [s for s in answer if s], [s for s in support if s]
