"""The report's answer first: do controller rankings change with the population beyond noise?

Sections built from the ``evidence_*`` tables (:mod:`.evidence`): the plain-words answer
(:mod:`.plain`), then the headline box — per comparison and metric, the raw reversal rate
against its null with the verdict of the test it rests on (the prediction t on the
spread between null replicates, or across the population pairs the randomization test
over recombined designs), the exact permutation p and the episode-only interval
beside it, and the significant rule as a second line — the full observed-vs-null table,
the nulls drawn as dots, "burden reverses more than robot time" against the null, and
each controller's rank per population with rank intervals. The survival of the paper's
findings, the seed-set curve, power and calibration are in :mod:`.evidence_sections`.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pandas as pd

from ..analysis.interaction import DRAWS, PREDICTION, RECOMBINED
from ..analysis.ranked import names, ranked_metric
from ..analysis.reversals import COMPARISONS
from ..analysis.verdicts import ABOVE, BELOW, CLAIMS, SMALL
from ..populations.build import population_order
from ..viz.style import controller_label
from .blocks import Block, Cell, Page, SectionSpec, fmt, pct, table
from .figures import pop_label
from .plain import LABELS, answer_sentences, null_words, pp

#: The headline's metrics, in the order the box lists them: burden first, then robot time.
HEADLINE_METRICS: tuple[str, ...] = (*names("burden"), *names("robot"))  # burden first


def _p(x: Any) -> str:
    """A p value: three decimals, two significant digits below 0.01 (a randomization p near
    a level of 0.005 reads 0.0049 or 0.0051, not 0.005 both)."""
    if x is None or pd.isna(x):
        return fmt(None)
    if 1e-4 <= float(x) < 0.01:
        return f"{float(x):#.2g}"
    if 0 < float(x) < 1e-4:  # the smallest a randomization p over 19,999 draws can be
        return np.format_float_positional(float(x), 2, unique=False, fractional=False)
    return fmt(float(x), "{:.3f}")


def design_text(r: Any) -> str:
    """A comparison's design: seed sets, variants per cell and its null."""
    return (f"{int(r['seed_sets'])} episode seed set{'s' if r['seed_sets'] != 1 else ''} "
            f"({int(r['variants_per_cell'])} variants per cell); null: {int(r['n_null'])} "
            f"{null_words(str(r['null']), str(r['null']))}, run on the same episodes")


def _raw_line(raw: Any) -> str:
    test = (f"randomization p = {_p(raw['p_t'])} against {DRAWS:,} recombined designs "
            f"(t = {fmt(raw['t'])} on {int(raw['df'])} df, shown, not used)"
            if raw.get("test") == RECOMBINED else
            f"prediction t = {fmt(raw['t'])} on {int(raw['df'])} df, p = {_p(raw['p_t'])}")
    return (f"{LABELS[raw['metric']]}: {pct(raw['observed'])} of comparable orderings reverse "
            f"({raw['reversals']}/{raw['comparable']}) against {pct(raw['null_mean'])} under the "
            f"null — excess {pp(raw['excess'])} [{pp(raw['ci_low'])}, {pp(raw['ci_high'])}], "
            f"{test} (× {int(raw.get('family', 1))} rates: {_p(raw.get('p_adj', raw['p_t']))})")


def _details(raw: Any, sig: Any | None) -> list[str]:
    below = int(raw["n_null"]) - int(raw["n_null_above"])
    out = [f"Exact permutation: the observed exceeds {below}"
           f" of {int(raw['n_null'])} null replicates, p = {_p(raw['p_value'])}. Beyond episode "
           f"noise for these personas (episode-only interval, not a test against the null): "
           f"[{pp(raw['episode_ci_low'])}, {pp(raw['episode_ci_high'])}]."]
    if sig is not None and np.isfinite(sig["observed"]):
        out.append(f"Orderings significant under both populations: {sig['reversals']}/"
                   f"{sig['comparable']} = {pct(sig['observed'])} reverse against "
                   f"{pct(sig['null_mean'])} under the null, exact p = {_p(sig['p_value'])} → "
                   f"{sig['verdict']}.")
    elif sig is not None:
        out.append("No ordering is significant under both populations at this design.")
    return out


def headline_entries(head: pd.DataFrame) -> list[dict[str, Any]]:
    """The headline box: per comparison with a null, its design and one line per metric —
    the raw rate's verdict first, then the exact p, the episode-only interval and the
    significant rule as details."""
    box = []
    for comp, c in COMPARISONS.items():
        h = head[(head["comparison"] == comp) & (head["n_null"] > 0)]
        if h.empty:
            continue
        lines = []
        for metric in [m for m in HEADLINE_METRICS if m in set(h["metric"])]:
            rows = h[h["metric"] == metric].set_index("rule")
            if "raw" not in rows.index:
                continue
            raw = rows.loc["raw"]
            sig = rows.loc["sig"] if "sig" in rows.index else None
            lines.append({"text": _raw_line(raw), "verdict": raw["verdict"],
                          "good": raw["verdict"] in CLAIMS, "details": _details(raw, sig)})
        box.append({"title": c.title, "design": design_text(h.iloc[0]), "lines": lines})
    return box


NOTE = ("Raw rule: the paper's reversal rate (tie tolerance 0.02 s for delays, 0.05 s for robot "
        "time). Excess = observed − mean of the null replicates. The verdict rests on the "
        "spread between null replicates: a prediction t under the matched shift; across the "
        "population pairs, whose null is drawn population by population, the exact "
        "randomization test over designs recombined from the replicates (its interval the "
        "test inverted under a shift). The rates of the box are decided "
        "together, each at 5%/m for m rates (Bonferroni), so the intervals in brackets are "
        "simultaneous 95% intervals and the p after '×' is the adjusted one: "
        f"'{ABOVE}' or '{BELOW}' when the interval excludes 0, '{SMALL}' when it rules out an "
        "excess of 5 percentage points, else 'undecided'. Its false-positive rate on this "
        "study's own placebos is in the calibration section. The significant rule counts only "
        "orderings whose 90% paired-bootstrap interval excludes 0 under both populations; its "
        "rates are small counts, decided by the exact permutation test at the same adjusted "
        "level (which needs 1/level − 1 null replicates; with fewer it is descriptive).")


def _answer(p: Page, head: pd.DataFrame) -> list[Block]:
    """The plain answer, the headline box and the full observed-vs-null table."""
    out: list[Block] = []
    stored = p.study.study
    answer, support = answer_sentences(
        p.a.tables, None if stored is None else (stored.name, p.study.seed))
    if answer:
        out.append({"kind": "answer", "question": "Do controller rankings change with the "
                    "pedestrian population beyond noise?", "sentences": answer,
                    "support": support})
    out.append({"kind": "headline", "entries": headline_entries(head), "note": NOTE})
    inter = p.a.tables.get("evidence_interaction")
    if inter is not None and not inter.empty:
        out.append(interaction_block(inter))
    rows = []
    for r in head.sort_values(["comparison", "metric", "rule"], kind="stable").itertuples():
        rows.append([r.comparison, LABELS.get(r.metric, r.metric),
                     "significant" if r.rule == "sig" else "raw (near-ties incl.)",
                     f"{int(r.seed_sets)} ({int(r.variants_per_cell)}/cell)",
                     f"{r.reversals}/{r.comparable}", Cell(pct(r.observed), "strong"),
                     pct(r.null_mean), f"[{pct(r.null_min)}, {pct(r.null_max)}]",
                     Cell(pp(r.excess), "strong"), f"[{pp(r.ci_low)}, {pp(r.ci_high)}]",
                     r.test, _p(r.p_t), _p(r.p_value), _p(r.p_adj),
                     f"[{pp(r.episode_ci_low)}, {pp(r.episode_ci_high)}]", int(r.n_null),
                     Cell(r.verdict, "strong")])
    out.append(table(["Comparison", "Metric", "Rule", "Seed sets", "Reversals / comparable",
                      "Observed", "Null mean", "Null range", "Excess",
                      "Simultaneous 95% interval", "Decided by", "p (its test)",
                      "p (exact, vs replicates)",
                      "p (adjusted)", "Episode-only interval", "Nulls", "Verdict"], rows,
                     caption="Every headline rate against its null",
                     csv="evidence_headline", collapsed=True))
    out += p.figure("evidence_nulls", "Observed reversal rates (red) against every null "
                    "replicate (grey dots) and the null mean (grey line), in % of comparable "
                    "orderings; top: the raw rule the verdicts rest on.")
    burden = p.a.tables.get("evidence_burden")
    if burden is not None and not burden.empty:
        out.append(_burden_block(burden))
    return out


ANSWER = SectionSpec("answer", "The answer: do rankings change with the population beyond "
                     "noise?", _answer, needs=("evidence_headline",),
                     otherwise="no comparison could be tested")


def interaction_block(inter: pd.DataFrame) -> Block:
    """The interaction test per comparison and metric, beside the headline."""
    rows = []
    for r in inter.sort_values(["comparison", "metric"], kind="stable").itertuples():
        test = getattr(r, "reference", PREDICTION)
        recombined = test == RECOMBINED
        rows.append([r.comparison, LABELS.get(r.metric, r.metric), test, fmt(r.T, "{:.3f}"),
                     f"{fmt(r.null_mean, '{:.3f}')} (SD {fmt(r.null_sd, '{:.3f}')})",
                     fmt(r.t) if recombined else f"{fmt(r.t)} on {int(r.df)} df", _p(r.p_t),
                     _p(r.p_adj), _p(r.p_value), int(r.n_null), Cell(r.verdict, "strong")])
    return table(["Comparison", "Metric", "Test", "T", "Reference mean (SD)", "t",
                  "p (one-sided)", "p (adjusted)", "p (exact)", "Nulls", "Verdict"], rows,
                 caption="Do controller differences change with the population more than "
                 "under the null? Per (population pair, cell, controller pair), the change of "
                 "the controller difference between the two populations in units of its SE "
                 "(z, from the same episode resamples); T = the mean rank of |z| among the "
                 "observed and every null replicate (scaled to [0, 1]; about 0.5 when the "
                 "observed is typical). Across population pairs, an exact randomization "
                 f"test: the observed against {DRAWS:,} designs recombined population by "
                 "population from the observed and its null replicates (t: its standardized "
                 "excess over them; p: the share at least as large); the matched pair alone, "
                 "a one-sided prediction t on the replicates' T. Each row decided at 5%/m "
                 "(Bonferroni over the table's m rows). It does not say that orderings cross. "
                 "This study's placebos are in the calibration section.",
                 csv="evidence_interaction")


def _burden_block(burden: pd.DataFrame) -> dict[str, Any]:
    rows = [[r.comparison, LABELS.get(r.metric, r.metric), r.rule,
             pp(r.observed_difference), pp(r.null_difference), Cell(pp(r.excess), "strong"),
             f"[{pp(r.ci_low)}, {pp(r.ci_high)}]", r.test, Cell(r.verdict, "strong")]
            for r in burden.itertuples()]
    return table(["Comparison", "Burden metric", "Rule", "Burden − robot-time rate",
                  "Same under the null", "Excess", "95% interval", "Decided by", "Verdict"], rows,
                 caption="'Burden reverses more than robot time', tested against the null "
                 "(every null reverses burden more often too)", csv="evidence_burden")


def _ranks(p: Page, ranks: pd.DataFrame) -> list[Block]:
    """Each controller's rank per population, with its bootstrap rank interval."""
    r = ranks[ranks["comparison"] == "all_pairs"] if (ranks["comparison"] == "all_pairs").any() \
        else ranks
    out = []
    for metric in [m for m in HEADLINE_METRICS if m in set(r["metric"])]:
        sub = r[r["metric"] == metric]
        ctrls = sorted(sub["controller"].unique())
        rows = []
        for pop in population_order(sub["population"].unique()):
            row: list[Any] = [pop_label(pop)]
            for c in ctrls:
                x = sub[(sub["population"] == pop) & (sub["controller"] == c)]
                if x.empty:
                    row.append("–")
                    continue
                x = x.iloc[0]
                span = (f"{x['rank']}" if x["rank_low"] == x["rank_high"]
                        else f"{x['rank']} [{x['rank_low']}–{x['rank_high']}]")
                unit = ranked_metric(metric).unit
                row.append(f"{span} · {fmt(x['value'])} {unit} · P(first) {pct(x['p_first'])}")
            rows.append(row)
        out.append(table(["Population", *[controller_label(c) for c in ctrls]], rows,
                         caption=f"{LABELS[metric]}: rank [interval] · grid mean · P(first)",
                         csv="evidence_ranks"))
    return out


RANKS = SectionSpec(
    "ranks", "Controller ranks per population, with rank intervals", _ranks,
    needs=("evidence_ranks",), otherwise="no population had every controller in a common cell",
    intro="Rank 1 = lowest grid mean (over the cells where every controller has a value). The "
          "interval is the 90% range of the rank over episode resamples; P(first) is the "
          "share of resamples in which it ranks first. Populations whose intervals overlap do "
          "not order the controllers differently beyond noise.")
