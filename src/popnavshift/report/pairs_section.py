"""The report's section on the all-pairs comparison: what its null is, how closely it
matches the cohorts, and which pairs carry the excess.

From the tables of :mod:`popnavshift.analysis.pair_excess` and
:mod:`popnavshift.analysis.cohorts`: the verdict's null in words (random subsets of mixed
of the cohorts' sizes, not matched in dispersion), the measured match (SD ratios, shared
personas, homogeneous's random member), the pairs and the attribute that carry the excess
(Holm over each table), and each rule's false-claim rate on the study's placebos.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pandas as pd

from ..analysis.cohorts import dispersion_summary
from ..analysis.pair_excess import (
    ATTRIBUTE,
    GROUP_DIFF,
    GROUP_OTHERS,
    GROUP_WITH,
    NOT_SHOWN,
    SELF_NULL,
    self_null_direction,
)
from ..analysis.verdicts import ALPHA
from ..populations.identity import SIZED_SOURCE
from ..tables import PARAMS
from .blocks import Block, Cell, Page, SectionSpec, fmt, para, pct, table
from .figures import pop_label
from .plain import LABELS, pp


def _p(x: Any) -> str:
    return fmt(x, "{:.3f}")


def null_words(cohorts: pd.DataFrame | None) -> str:
    """What the all-pairs verdict is judged against, and how far that null is from the
    cohorts (measured), with the direction it implies."""
    text = (f"The all-pairs verdict judges each pair of cohorts against random subsets of "
            f"{SIZED_SOURCE} of the same sizes: matched in size only, not in the dispersion "
            "of the motion parameters, nor in the personas two cohorts share.")
    if cohorts is None or cohorts.empty:
        return text
    s = dispersion_summary(cohorts)
    if s.empty:
        return text
    less = s[s["sd_ratio_mean"] < 1]
    text += (f" Measured here: averaged over the {len(PARAMS)} parameters, the cohorts' SDs are "
             f"{fmt(s['sd_ratio_mean'].min())}–{fmt(s['sd_ratio_mean'].max())} times those of "
             f"such subsets ({len(less)} of {len(s)} cohorts less dispersed; "
             f"{int(s['params_below'].sum())} of {len(s) * len(PARAMS)} cohort parameters "
             "below 97.5% of the random subsets). A less dispersed cohort puts less "
             "persona-to-persona variation into its cells, so two such cohorts should reverse "
             "less by persona sampling alone than two random subsets do: on that account the "
             "null overstates the cohorts' noise (conservative for 'above the null', generous "
             "for 'below' and 'no excess ≥ 5 pp'). That direction is reasoned from how slots "
             "are drawn, not measured on runs; shared personas pull both ways (below).")
    return text


def _self_null_words(pairs: pd.DataFrame) -> str:
    d = self_null_direction(pairs)
    if d.empty:
        return ""
    parts = [f"{LABELS.get(r.metric, r.metric)} {pp(r.difference)} ({r.pairs_lower} of "
             f"{r.pairs} pairs lower)" for r in d.itertuples()]
    who = " and ".join(SELF_NULL)
    return (f"{who.capitalize()} (one fixed profile, not a member of {SIZED_SOURCE}) is stood in "
            f"for by one random member of {SIZED_SOURCE} in each null replicate. Its pairs' null "
            f"with that random member minus the same null with {who} itself: "
            + "; ".join(parts) + ". Where this is negative the random member makes the null "
            "reverse less than an exact one, so those pairs' excess is overstated "
            "(generous for 'above the null').")


def _group_words(groups: pd.DataFrame) -> str:
    out = []
    for metric, g in groups.groupby("metric", sort=False):
        g = g.set_index("group")
        if not {GROUP_WITH, GROUP_OTHERS, GROUP_DIFF} <= set(g.index):
            continue
        w, o, d = g.loc[GROUP_WITH], g.loc[GROUP_OTHERS], g.loc[GROUP_DIFF]
        out.append(f"{LABELS.get(metric, metric)}: {int(w['pairs'])} pairs with a "
                   f"{ATTRIBUTE[0]} population {pp(w['excess'])} (t {fmt(w['t'])}, "
                   f"{w['claim']}), the other {int(o['pairs'])} {pp(o['excess'])} (t "
                   f"{fmt(o['t'])}, {o['claim']}); difference {d['claim']}")
    return "; ".join(out)


def carriers_sentence(pairs: pd.DataFrame, groups: pd.DataFrame | None, *,
                      alpha: float = ALPHA) -> str:
    """Which pairs (and which attribute) carry the all-pairs excess, in one sentence: the
    pairs named by the exact test (or why none can be), the largest excesses as descriptions,
    and the groups by attribute."""
    shown = pairs[pairs["claim"] != NOT_SHOWN]
    family = int(pairs["family"].max()) if len(pairs) else 0
    n_null = int(pairs["n_null"].max()) if len(pairs) else 0
    names = "; ".join(f"{pop_label(r.pair)} ({LABELS.get(r.metric, r.metric)}, "
                      f"{pp(r.excess)}, {r.claim})" for r in shown.itertuples())
    if names:
        text = f"Pair by pair (exact step-down max-t over {family} pair × metric rows): {names}."
    elif 1 / (n_null + 1) > alpha:
        text = (f"Pair by pair, no pair can be named on its own with {n_null} null replicates: "
                f"the exact step-down max-t over the {family} pair × metric rows cannot go "
                f"below 1/{n_null + 1} (it needs {int(np.ceil(1 / alpha)) - 1}).")
    else:
        text = (f"Pair by pair (exact step-down max-t over {family} pair × metric rows), no "
                "pair is shown above or below its null on its own.")
    top = pairs.dropna(subset=["t"]).sort_values("t", ascending=False).head(3)
    if shown.empty and not top.empty:
        text += " Largest excesses (descriptive): " + "; ".join(
            f"{pop_label(r.pair)} ({LABELS.get(r.metric, r.metric)}, {pp(r.excess)}, t "
            f"{fmt(r.t)})" for r in top.itertuples()) + "."
    if groups is not None and not groups.empty:
        text += f" By attribute (prediction t, Holm over {int(groups['family'].max())} rows): " \
                + _group_words(groups) + "."
    return text


def _pair_rows(pairs: pd.DataFrame) -> list[list[Any]]:
    return [[pop_label(r.pair), LABELS.get(r.metric, r.metric), "yes" if r.carries else "",
             f"{r.reversals}/{r.comparable}", Cell(pct(r.observed), "strong"), pct(r.null_mean),
             Cell(pp(r.excess), "strong"), f"{fmt(r.t)} on {int(r.df)} df", _p(r.p_t),
             _p(r.p_holm), _p(r.p_maxt), pct(r.null_mean_self), Cell(r.claim, "strong")]
            for r in pairs.itertuples()]


def _group_rows(groups: pd.DataFrame) -> list[list[Any]]:
    words = {GROUP_WITH: f"with a {ATTRIBUTE[0]} population", GROUP_OTHERS: "the others",
             GROUP_DIFF: "difference (with − others)"}
    return [[words.get(r.group, r.group), LABELS.get(r.metric, r.metric), int(r.pairs),
             Cell(pp(r.observed) if r.group == GROUP_DIFF else pct(r.observed), "strong"),
             pp(r.null_mean) if r.group == GROUP_DIFF else pct(r.null_mean),
             Cell(pp(r.excess), "strong"), f"{fmt(r.t)} on {int(r.df)} df", _p(r.p_t),
             _p(r.p_holm), _p(r.p_maxt), Cell(r.claim, "strong")] for r in groups.itertuples()]


def _match_blocks(cohorts: pd.DataFrame | None, overlaps: pd.DataFrame | None) -> list[Block]:
    out: list[Block] = []
    if cohorts is not None and not cohorts.empty:
        s = dispersion_summary(cohorts).set_index(["mapping", "cohort"])
        rows = []
        for (mapping, cohort), g in cohorts.groupby(["mapping", "cohort"], sort=False):
            g = g.set_index("parameter")
            ratio = [f"{fmt(g.at[q, 'sd_ratio'])} ({pct(g.at[q, 'share_below'])})"
                     for q in PARAMS]
            mean = s.at[(mapping, cohort), "sd_ratio_mean"] if (mapping, cohort) in s.index \
                else np.nan
            rows.append([mapping, pop_label(cohort), int(g["n"].iloc[0]),
                         pct(g["in_source"].iloc[0]), *ratio, Cell(fmt(mean), "strong")])
        draws = int(cohorts["draws"].max())
        out.append(table(["Mapping", "Cohort", "Size", f"Profiles in {SIZED_SOURCE}", *PARAMS,
                          "Mean ratio"], rows, csv="evidence_cohorts",
                         caption=f"Each cohort's SD of a motion parameter over the mean SD of "
                         f"{draws} random subsets of {SIZED_SOURCE} of its size (the null's "
                         "construction), with the share of those subsets at or below it; "
                         "below 1 (and a share near 0%): the cohort is less dispersed than "
                         "its null"))
    if overlaps is not None and not overlaps.empty:
        rows = [[r.mapping, f"{pop_label(r.cohort_a)} & {pop_label(r.cohort_b)}", r.shared,
                 f"{fmt(r.expected, '{:.1f}')} ± {fmt(r.expected_sd, '{:.1f}')}",
                 _p(r.p_low), _p(r.p_high)] for r in overlaps.itertuples()]
        out.append(table(["Mapping", "Cohorts", "Shared personas", "Random subsets",
                          "P(≤ shared)", "P(≥ shared)"], rows, csv="evidence_cohort_overlaps",
                         caption="Personas two cohorts share against two independent random "
                         "subsets of their sizes (hypergeometric mean ± SD): sharing fewer "
                         "than random subsets makes the null too alike (it reverses less "
                         "than an exact one), sharing more makes it too different",
                         collapsed=True))
    return out


def _placebo_block(placebos: pd.DataFrame) -> Block:
    rows = [[r.rule, int(r.placebos), int(r.null_replicates), int(r.tables_with_claim),
             Cell(pct(r.rate), "strong"), f"[{pct(r.ci_low)}, {pct(r.ci_high)}]",
             pct(r.nominal), f"{int(r.false_claims)}/{int(r.rows)}"]
            for r in placebos.itertuples()]
    return table(["Rule", "Placebos", "Nulls each", "Tables with a claim", "Rate",
                  "Clopper–Pearson 95%", "Nominal", "False rows / rows"], rows,
                 csv="evidence_pair_placebos",
                 caption="Each rule on this study's placebos: every null replicate taken as "
                 "the observed against the others; any claim is false. A table (pairs or "
                 "groups) should claim something in at most the nominal share of placebos.")


def _pairs(p: Page, pairs: pd.DataFrame) -> list[Block]:
    t = p.a.tables
    groups, cohorts = t.get("evidence_pair_groups"), t.get("evidence_cohorts")
    out: list[Block] = [para(null_words(cohorts))]
    self_words = _self_null_words(pairs)
    if self_words:
        out.append(para(self_words))
    out += _match_blocks(cohorts, t.get("evidence_cohort_overlaps"))
    out.append(para(carriers_sentence(pairs, groups)))
    if groups is not None and not groups.empty:
        out.append(table(["Pairs", "Metric", "Pairs", "Observed", "Null mean", "Excess", "t",
                          "p (t)", "p (Holm, decides)", "p (exact max-t)", "Claim"],
                         _group_rows(groups),
                         csv="evidence_pair_groups",
                         caption=f"Pairs grouped by whether one population is under "
                         f"{ATTRIBUTE[0]} ({', '.join(map(pop_label, ATTRIBUTE[1]))}): each "
                         "group's pooled raw rate against the same pooling of every null "
                         "replicate, and the difference of the two; prediction t, Holm over "
                         "the table"))
    out.append(table(["Pair", "Metric", ATTRIBUTE[0].capitalize(), "Reversals / comparable",
                      "Observed", "Null mean", "Excess", "t", "p (t)", "p (Holm of t)",
                      "p (exact max-t, decides)", f"Null with {' / '.join(SELF_NULL)} itself",
                      "Claim"], _pair_rows(pairs),
                     csv="evidence_pairs", collapsed=True,
                     caption="Every pair's raw rate against the same pair in every null "
                     "replicate (the matched pair: its swap permutations). Decided by the exact "
                     "step-down max-t over the replicates (Westfall–Young: exact whatever the "
                     "replicates' shape, its least p is 1/(replicates + 1)); Holm on the "
                     "prediction t is shown beside it, not used: on placebos of the seed-0 and "
                     "seed-1 studies it claimed a false pair in 6 of 48 tables"))
    placebos = t.get("evidence_pair_placebos")
    if placebos is not None and not placebos.empty:
        out.append(_placebo_block(placebos))
    return out


PAIRS = SectionSpec(
    "pairs", "All population pairs: their null, and which pairs carry the excess", _pairs,
    needs=("evidence_pairs",), otherwise="the study ran no null of the all-pairs comparison",
    intro="The all-pairs rate of the answer pools every pair of the main part's populations. "
          "Here is what it is judged against, how closely that null matches the cohorts, and "
          "which pairs carry the excess — each pair and each group of pairs tested against the "
          "same pairs in every null replicate, as the answer tests the pool, with family-wise "
          "control over each table.")
