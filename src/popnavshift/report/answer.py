"""The report's answer first: do controller rankings change with the population beyond noise?

Sections built from the ``evidence_*`` tables (:mod:`.evidence`): the headline box
(each comparison's significant reversal rate as its excess over its null, with
interval, p-value and verdict, the paper's raw rate beside it), the nulls drawn
as lines, each controller's rank per population with rank intervals, the paper's
findings under the significance rule, and the matched comparison against its
number of seed sets (curve, replicability, power). Figures are pure functions of
the tables.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from ..analysis.replicates import MIN_EFFECT  # noqa: E402
from ..populations.build import population_order  # noqa: E402
from ..populations.figures import save_figure  # noqa: E402
from .blocks import Cell, Section, figure, fmt, para, pct, table  # noqa: E402
from .figures import controller_label, pop_label  # noqa: E402

#: The metrics the headline leads with (mean burden, its tail on pooled records, robot time).
HEADLINE_METRICS: tuple[str, ...] = ("mean_delay", "cvar90", "robot_time")
LABELS = {"robot_time": "robot time", "mean_delay": "mean delay",
          "worst_decile": "worst-decile delay", "cvar90": "CVaR-90 delay"}
COMPARISONS = {"matched": "Matched time-pressure intervention (same personas, swap null)",
               "all_pairs": "All population pairs of the main grid (size-matched null)"}
NULL_WORDS = {"swap": "swap permutations", "sized": "size-matched subsets of mixed"}


def _pp(x: Any) -> str:
    return fmt(None if x is None else 100 * float(x), "{:+.1f} pp")


def _p(x: Any) -> str:
    return fmt(x, "{:.3f}")


def _row(head: pd.DataFrame, comp: str, metric: str, rule: str) -> pd.Series | None:
    sel = head[(head["comparison"] == comp) & (head["metric"] == metric)
               & (head["rule"] == rule)]
    return None if sel.empty else sel.iloc[0]


def _verdict(r: pd.Series) -> str:
    v = str(r.get("verdict", "undecided"))
    if v == "undecided" and np.isfinite(r.get("seed_sets_needed", np.nan)):
        return (f"undecided: about {int(r['seed_sets_needed'])} seed sets would detect an excess "
                f"of {100 * r['effect']:.0f} pp")
    return v


def headline_lines(head: pd.DataFrame) -> list[dict[str, Any]]:
    """One entry per (comparison, headline metric) with a null: the headline box's sentence
    (the significant rule, or why it is undefined) and the paper's raw rule beside it."""
    lines = []
    for comp in COMPARISONS:
        for metric in HEADLINE_METRICS:
            sig, raw = _row(head, comp, metric, "sig"), _row(head, comp, metric, "raw")
            if raw is None or not raw["n_null"]:
                continue
            raw_text = (f"raw rate incl. near-ties {pct(raw['observed'])} vs "
                        f"{pct(raw['null_mean'])}, excess {_pp(raw['excess'])} "
                        f"[{_pp(raw['ci_low'])}, {_pp(raw['ci_high'])}], "
                        f"p = {_p(raw['p_value'])}")
            raw_verdict = {"raw_verdict": _verdict(raw),
                           "raw_good": str(raw.get("verdict")) == "beats the null"}
            if sig is None or not sig["n_null"] or not np.isfinite(sig["observed"]):
                lines.append({"comparison": comp, "metric": metric, "good": False, **raw_verdict,
                              "verdict": "undecided: no ordering is significant under both "
                              "populations at this design (add seed sets)",
                              "text": f"{LABELS[metric]}: significant rate undefined",
                              "raw": raw_text})
                continue
            lines.append({
                "comparison": comp, "metric": metric, "verdict": _verdict(sig), **raw_verdict,
                "good": str(sig.get("verdict")) == "beats the null",
                "text": (f"{LABELS[metric]}: significant reversals {pct(sig['observed'])} "
                         f"({sig['reversals']}/{sig['comparable']}) against "
                         f"{pct(sig['null_mean'])} "
                         f"under the null — excess {_pp(sig['excess'])} "
                         f"[95% CI {_pp(sig['ci_low'])}, {_pp(sig['ci_high'])}], "
                         f"p = {_p(sig['p_value'])}"),
                "raw": raw_text})
    return lines


def design_text(head: pd.DataFrame, comp: str) -> str:
    r = head[head["comparison"] == comp].iloc[0]
    return (f"{int(r['n_null'])} {NULL_WORDS.get(str(r['null']), str(r['null']))}; "
            f"{int(r['seed_sets'])} episode seed set{'s' if r['seed_sets'] != 1 else ''} "
            f"({int(r['variants_per_cell'])} variants per cell)")


def answer_section(tables: dict[str, pd.DataFrame], missing: dict[str, str],
                   figs: dict[str, Path], out: Path) -> Section:
    """The headline box and the full observed-vs-null table."""
    s = Section("answer", "The answer: do rankings change with the population beyond noise?",
                missing=missing.get("evidence", ""))
    head = tables.get("evidence_headline")
    if head is None or head.empty:
        s.missing = s.missing or "no comparison could be tested"
        return s
    power = tables.get("evidence_power")
    if power is not None and not power.empty:
        keep = ["comparison", "metric", "rule", "verdict", "seed_sets_needed", "effect"]
        head = head.merge(power[keep], on=["comparison", "metric", "rule"], how="left")
    box = []
    for comp, title in COMPARISONS.items():
        if not (head["comparison"] == comp).any():
            continue
        lines = [x for x in headline_lines(head) if x["comparison"] == comp]
        if lines:
            box.append({"title": title, "design": design_text(head, comp), "lines": lines})
    s.blocks.append({"kind": "headline", "entries": box,
                     "note": ("A reversal counts only when the controller ordering is significant "
                              "under both populations (paired episode bootstrap, 90% interval "
                              "excludes 0). Excess = observed − mean of the null at the same "
                              "design; its 95% interval resamples episodes within cells; p = "
                              "(1 + #null ≥ observed)/(1 + P). Verdicts: 'beats the null' needs "
                              f"the interval above 0 and p ≤ 0.05; 'no excess ≥ {MIN_EFFECT:g}' "
                              f"means the interval rules out an excess of "
                              f"{100 * MIN_EFFECT:g} points.")})
    rows = []
    for r in head.sort_values(["comparison", "metric", "rule"], kind="stable").itertuples():
        rows.append([r.comparison, LABELS.get(r.metric, r.metric),
                     "significant" if r.rule == "sig" else "raw (near-ties incl.)",
                     f"{r.reversals}/{r.comparable}", Cell(pct(r.observed), "strong"),
                     pct(r.null_mean), f"[{pct(r.null_min)}, {pct(r.null_max)}]",
                     Cell(_pp(r.excess), "strong"), f"[{_pp(r.ci_low)}, {_pp(r.ci_high)}]",
                     _p(r.p_value), int(r.n_null)])
    s.blocks.append(table(["Comparison", "Metric", "Rule", "Reversals / comparable", "Observed",
                           "Null mean", "Null range", "Excess", "95% CI", "p", "Nulls"], rows,
                          caption="Every headline rate against its null",
                          csv="tables/evidence_headline.csv", collapsed=True))
    if "evidence_nulls" in figs:
        s.blocks.append(figure(figs["evidence_nulls"], out,
                               "Observed reversal rates (red) against every null replicate "
                               "(grey dots) and the null mean (grey line)."))
    burden = tables.get("evidence_burden")
    if burden is not None and not burden.empty:
        s.blocks.append(_burden_block(burden))
    return s


def _burden_block(burden: pd.DataFrame) -> dict[str, Any]:
    rows = [[r.comparison, LABELS.get(r.metric, r.metric), r.rule,
             _pp(r.observed_difference), _pp(r.null_difference), Cell(_pp(r.excess), "strong"),
             f"[{_pp(r.ci_low)}, {_pp(r.ci_high)}]", _p(r.p_value)]
            for r in burden.itertuples()]
    return table(["Comparison", "Burden metric", "Rule", "Burden − robot-time rate",
                  "Same under the null", "Excess", "95% CI", "p"], rows,
                 caption="'Burden reverses more than robot time', tested against the null "
                 "(every null reverses burden more often too)", csv="tables/evidence_burden.csv")


def ranks_section(tables: dict[str, pd.DataFrame]) -> Section:
    """Each controller's rank per population, with its bootstrap rank interval."""
    s = Section("ranks", "Controller ranks per population, with rank intervals")
    ranks = tables.get("evidence_ranks")
    if ranks is None or ranks.empty:
        s.missing = "no population had every controller in a common cell"
        return s
    s.blocks.append(para("Rank 1 = lowest grid mean (over the cells where every controller has "
                         "a value). The interval is the 90% range of the rank over episode "
                         "resamples; P(first) is the share of resamples in which it ranks "
                         "first. Populations whose intervals overlap do not order the "
                         "controllers differently beyond noise."))
    r = ranks[ranks["comparison"] == "all_pairs"] if (ranks["comparison"] == "all_pairs").any() \
        else ranks
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
                row.append(f"{span} · {fmt(x['value'])} s · P(first) {pct(x['p_first'])}")
            rows.append(row)
        s.blocks.append(table(["Population", *[controller_label(c) for c in ctrls]], rows,
                              caption=f"{LABELS[metric]}: rank [interval] · grid mean · P(first)",
                              csv="tables/evidence_ranks.csv"))
    return s


def surviving_section(tables: dict[str, pd.DataFrame]) -> Section:
    """The paper's findings re-checked with intervals, and which survive."""
    s = Section("surviving", "The paper's findings under the significance rule")
    f = tables.get("evidence_findings")
    if f is None or f.empty:
        s.missing = "the main grid lacks the populations or controllers the findings need"
        return s
    held, survived = int(f["holds"].sum()), int(f["survives"].sum())
    s.blocks.append(para(f"{survived} of {len(f)} findings survive (their whole 90% interval "
                         f"agrees with the claim); {held} hold on the point estimate alone. "
                         "Intervals resample episodes within cells, shared by every "
                         "population and controller."))
    s.blocks.append({"kind": "findings", "entries": [
        {"holds": bool(r.survives),
         "statement": r.statement + ("" if r.survives else (" (holds on the point estimate only)"
                                                             if r.holds else "")),
         "numbers": f"{r.statistic} = {fmt(r.estimate)} [{fmt(r.ci_low)}, {fmt(r.ci_high)}]"}
        for r in f.itertuples()]})
    return s


def replicates_section(tables: dict[str, pd.DataFrame], missing: dict[str, str],
                       figs: dict[str, Path], out: Path) -> Section:
    """The matched comparison against its number of seed sets, and the power advice."""
    s = Section("replicates", "Replicates: rates against seed sets, replicability and power")
    curve, rep = tables.get("evidence_curve"), tables.get("evidence_replicability")
    power = tables.get("evidence_power")
    if curve is None and power is None:
        s.missing = missing.get("curve", "the study ran one seed set and no null")
        return s
    if "evidence_curve" in figs:
        s.blocks.append(figure(figs["evidence_curve"], out,
                               "Significant reversal rate of the matched pair (solid) and its "
                               "swap null (dashed, band = range of the permutations) on the "
                               "first 1, 2, … seed sets."))
    if rep is not None and not rep.empty:
        rows = [[r.kind, LABELS.get(r.metric, r.metric), pct(r.marginal),
                 Cell(pct(r.recurrence), "strong"), f"{r.recurred}/{r.opportunities}"]
                for r in rep.itertuples()]
        s.blocks.append(table(["Pair", "Metric", "Reversal rate (one seed set)",
                               "P(recurs in another seed set)", "Recurred / opportunities"],
                              rows, caption="Replicability of a reversal seen in one seed set "
                              "(raw rule): a population effect recurs more often than its rate",
                              csv="tables/evidence_replicability.csv"))
    if power is not None and not power.empty:
        p = power[power["rule"] == "sig"]
        rows = [[r.comparison, LABELS.get(r.metric, r.metric), _pp(r.excess),
                 fmt(100 * r.se, "{:.1f} pp"), f"{100 * r.effect:.0f} pp ({r.effect_source})",
                 int(r.seed_sets_used),
                 "–" if not np.isfinite(r.seed_sets_needed) else int(r.seed_sets_needed),
                 Cell(r.verdict, "strong")] for r in p.itertuples()]
        s.blocks.append(table(["Comparison", "Metric", "Excess", "SE", "Effect to detect",
                               "Seed sets used", "Seed sets needed (80% power, α = 0.05)",
                               "Verdict"], rows, caption="Power: seed sets needed to separate "
                              "the effect from the null (SE assumed to shrink as 1/√seed sets)",
                              csv="tables/evidence_power.csv"))
    return s


def with_null_rates(reversals: pd.DataFrame, tables: dict[str, pd.DataFrame]) -> pd.DataFrame:
    """Table I with ``null_rate``: the raw rate of each comparison's null at Table I's design
    (one seed set, all cells) — the matched pair's swap null on the study seed's episodes,
    the pairs' size-matched null on the main grid; NaN where the study ran no null."""
    null = {}
    curve, head = tables.get("evidence_curve"), tables.get("evidence_headline")
    if curve is not None and not curve.empty:
        c = curve[(curve["seed_sets"] == 1) & (curve["rule"] == "raw")
                  & (curve["comparison"] == "matched")]
        null.update({("matched", m): v for m, v in zip(c["metric"], c["null_mean"], strict=True)})
    if head is not None and not head.empty:
        h = head[(head["rule"] == "raw") & (head["seed_sets"] == 1)]
        for r in h.itertuples():
            null.setdefault((r.comparison, r.metric), r.null_mean)
    key = zip(reversals["comparison"], reversals["metric"], strict=True)
    rates = [null.get(k, np.nan) for k in key]
    return reversals.assign(null_rate=np.where(reversals["cells"] == "all", rates, np.nan))


# --- figures ------------------------------------------------------------------------------------


def plot_nulls(head: pd.DataFrame, null_rates: pd.DataFrame) -> plt.Figure:
    """Per comparison (columns) and rule (rows): observed rate per metric (red diamond),
    every null replicate (grey dots) and the null mean (grey line)."""
    comps = [c for c in COMPARISONS if (head["comparison"] == c).any()]
    metrics = [m for m in ("robot_time", "mean_delay", "worst_decile", "cvar90")
               if m in set(head["metric"])]
    fig, axes = plt.subplots(2, len(comps), figsize=(5.0 * len(comps), 6.0), squeeze=False)
    x = np.arange(len(metrics))
    for j, comp in enumerate(comps):
        for i, rule in enumerate(("sig", "raw")):
            ax = axes[i][j]
            for k, m in enumerate(metrics):
                obs = _row(head, comp, m, rule)
                nr = null_rates[(null_rates["comparison"] == comp) & (null_rates["metric"] == m)
                                & (null_rates["rule"] == rule)]["rate"].to_numpy(float) * 100
                jitter = np.linspace(-0.15, 0.15, max(len(nr), 1))[: len(nr)]
                ax.scatter(k + jitter, nr, s=9, color="#999999", zorder=2,
                           label="null replicates" if k == 0 else None)
                if np.isfinite(nr).any():
                    ax.hlines(np.nanmean(nr), k - 0.3, k + 0.3, color="#555555", lw=2,
                              label="null mean" if k == 0 else None)
                if obs is not None:
                    ax.scatter([k], [100 * obs["observed"]], marker="D", s=40, color="#C44E52",
                               zorder=3, label="observed" if k == 0 else None)
            ax.set_xticks(x, [LABELS[m] for m in metrics], fontsize=8)
            ax.set_xlim(-0.6, len(metrics) - 0.4)
            ax.set_title(f"{'Matched intervention' if comp == 'matched' else 'All pairs'} — "
                         f"{'significant' if rule == 'sig' else 'raw (near-ties incl.)'}",
                         fontsize=9)
            ax.grid(axis="y", alpha=0.3)
            ax.set_ylabel("reversals (% of comparable)", fontsize=8)
    axes[0][0].legend(fontsize=7)
    fig.tight_layout()
    return fig


def plot_curve(curve: pd.DataFrame) -> plt.Figure:
    """Matched significant reversal rate against variants per cell, observed vs swap null."""
    metrics = [m for m in HEADLINE_METRICS if m in set(curve["metric"])]
    fig, axes = plt.subplots(1, len(metrics), figsize=(4.2 * len(metrics), 3.3), squeeze=False,
                             sharey=True)
    for ax, m in zip(axes[0], metrics, strict=True):
        c = curve[(curve["metric"] == m) & (curve["rule"] == "sig")].sort_values("seed_sets")
        v = c["variants_per_cell"].to_numpy()
        ax.plot(v, 100 * c["observed"], marker="o", color="#C44E52", label="matched pair")
        ax.plot(v, 100 * c["null_mean"], ls="--", marker=".", color="#555555", label="swap null")
        ax.fill_between(v, 100 * c["null_min"], 100 * c["null_max"], color="#999999", alpha=0.25)
        ax.set_title(LABELS[m], fontsize=9)
        ax.set_xlabel("variants per cell (3 per seed set)", fontsize=8)
        ax.set_xticks(v)
        ax.grid(alpha=0.3)
    axes[0][0].set_ylabel("significant reversals (%)", fontsize=8)
    axes[0][0].legend(fontsize=7)
    fig.tight_layout()
    return fig


def write_answer_figures(tables: dict[str, pd.DataFrame], out: Path) -> dict[str, Path]:
    """The evidence figures the tables allow, as PNG + SVG in ``out``; name → PNG path."""
    paths = {}
    head, nulls = tables.get("evidence_headline"), tables.get("evidence_null_rates")
    if head is not None and nulls is not None and not head.empty:
        paths["evidence_nulls"] = save_figure(plot_nulls(head, nulls), out / "evidence_nulls")[0]
    curve = tables.get("evidence_curve")
    if curve is not None and not curve.empty and curve["seed_sets"].nunique() > 1:
        paths["evidence_curve"] = save_figure(plot_curve(curve), out / "evidence_curve")[0]
    return paths
