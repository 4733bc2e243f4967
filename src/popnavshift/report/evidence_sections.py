"""The report's evidence beyond the headline: rates against seed sets with the power
advice, and the calibration of every verdict rule on the study's own placebos. Built from
the ``evidence_*`` tables. (The paper's findings, each with its check beyond noise, are
one list in :func:`.sections.summary_section`.)"""

from __future__ import annotations

import numpy as np
import pandas as pd

from .blocks import Block, Cell, Page, SectionSpec, fmt, pct, table
from .plain import LABELS, pp


def _advice(r) -> str:
    if r.limit == "decided":
        return "–"
    if not np.isfinite(r.runs_needed):
        return r.limit
    minutes = f", ~{r.minutes_needed:.0f} min" if np.isfinite(r.minutes_needed) else ""
    sets = int(r.seed_sets_needed)
    return (f"{r.limit}: {sets} seed set{'s' if sets != 1 else ''}, {int(r.nulls_needed)} nulls "
            f"(+{int(r.runs_needed):,} runs at most{minutes})")


def _predicted(r) -> str:
    """``t 4.3 [−5.1, 13.8], 81%``: the advised design's predicted t, its 10–90% interval
    and its chance of a decision (– when nothing is advised)."""
    t = getattr(r, "t_predicted", np.nan)
    if not np.isfinite(t):
        return "–"
    return (f"t {t:.1f} [{r.t_low:.1f}, {r.t_high:.1f}], "
            f"{100 * getattr(r, 'chance', np.nan):.0f}%")


def _holdout(r) -> str:
    """``at 4 sets: t 2.3, predicted 1.9``: the study's own hold-out (– without one)."""
    at = getattr(r, "holdout_at", np.nan)
    if not np.isfinite(at):
        return "–"
    return f"at {int(at)} sets: t {r.holdout_t:.1f}, predicted {r.holdout_predicted:.1f}"


def power_block(power: pd.DataFrame) -> dict:
    rows = [[r.comparison, LABELS.get(r.metric, r.metric),
             "raw" if r.rule == "raw" else "significant", pp(r.excess),
             fmt(100 * r.null_sd, "{:.1f} pp"),
             f"{int(r.seed_sets)} / {int(r.n_null)}", Cell(r.verdict, "strong"), _advice(r),
             _predicted(r), _holdout(r)]
            for r in power.itertuples()]
    return table(["Comparison", "Metric", "Rule", "Excess", "Null SD", "Seed sets / nulls",
                  "Verdict", "What would decide it (80% chance)",
                  "Predicted t there [10–90%], chance", "Hold-out on this study"], rows,
                 caption="Power: what would decide each verdict, from a model of the study's "
                 "own curve (the excess and the null's SD on its first 1, 2, … seed sets), "
                 "with the growth of the excess per doubling of seed sets and the model's "
                 "error measured on held-out seed sets (docs/analysis.md §8a); the hold-out "
                 "column predicts this study's last seed-set count from its first two",
                 csv="evidence_power")


def _replicates(p: Page, _: pd.DataFrame) -> list[Block]:
    """Each comparison against its number of seed sets, and what would decide it."""
    rep, power = p.a.tables.get("evidence_replicability"), p.a.tables.get("evidence_power")
    out = p.figure("evidence_curve", "Raw reversal rate (solid) and its null (dashed, band = "
                   "range of the null replicates) on the first 1, 2, … seed sets.")
    if rep is not None and not rep.empty:
        rows = [[r.comparison, r.kind, LABELS.get(r.metric, r.metric), pct(r.marginal),
                 Cell(pct(r.recurrence), "strong"), f"{r.recurred}/{r.opportunities}"]
                for r in rep.itertuples()]
        out.append(table(["Comparison", "Pair", "Metric", "Reversal rate (one seed set)",
                          "P(recurs in another seed set)", "Recurred / opportunities"],
                         rows, caption="Replicability of a reversal seen in one seed set "
                         "(raw rule): a population effect recurs more often than its rate",
                         csv="evidence_replicability"))
    if power is not None and not power.empty:
        out.append(power_block(power))
    return out


REPLICATES = SectionSpec("replicates", "Replicates: rates against seed sets, replicability "
                         "and power", _replicates, needs=("evidence_curve", "evidence_power"),
                         otherwise="the study ran one seed set and no null")


def _calibration(p: Page, cal: pd.DataFrame) -> list[Block]:
    """Every verdict rule's false-positive rate on placebos drawn from the study's nulls."""
    c = cal[cal["comparison"].isin(["table", "all"])]
    c = c if not c.empty else cal
    rows = [["the headline table" if r.comparison == "table" else r.test, r.rule, r.claim,
             "–" if not np.isfinite(r.nominal) else pct(r.nominal), f"{r.claims}/{r.placebos}",
             Cell(pct(r.rate), "strong"), f"[{pct(r.cp_low)}, {pct(r.cp_high)}]",
             Cell(r.status, "bad" if r.status == "above nominal" else
                  "ok" if r.status == "within" else "")] for r in c.itertuples()]
    out = [table(["Test", "Rule", "Claim", "Nominal", "Claims / placebos", "Rate",
                  "95% CI", "Status"], rows,
                 caption="Every verdict rule on the study's placebos: the headline "
                 "table as a whole, then each test pooled over comparisons and metrics",
                 csv="evidence_calibration")]
    inter = p.a.tables.get("evidence_interaction_nulls")
    if inter is not None and not inter.empty:
        out.append(table(["Comparison", "Metric", "Replicate", "T", "As a placebo: t",
                          "p (one-sided)"],
                         [[r.comparison, LABELS.get(r.metric, r.metric), int(r.replicate),
                           fmt(r.T, "{:.3f}"), fmt(r.placebo_t), fmt(r.placebo_p_t, "{:.3f}")]
                          for r in inter.itertuples()],
                         caption="The interaction test's null replicates: each one's T, and "
                         "the replicate taken as the observed against the others (its "
                         "placebo)", csv="evidence_interaction_nulls", collapsed=True))
    return out


CALIBRATION = SectionSpec(
    "calibration", "Calibration: how often each verdict rule is wrong on placebos",
    _calibration, needs=("evidence_calibration",),
    otherwise="the study ran no null replicates to draw placebos from",
    intro="A placebo takes one null replicate as if it were the observed populations and the "
          "study's other replicates as its null: the truth is no population effect, so every "
          "claim is false. Shifted placebos add a known excess (5 or 10 pp) to check the 'no "
          "excess' claim and the power. Clopper–Pearson 95% intervals; status 'within' when "
          "the interval reaches down to the nominal level and rules out twice it, 'above "
          "nominal' when it lies above it, else 'too few placebos to tell'. Leave-one-out "
          "placebos check the tests' assumptions, not whether the null itself is built right "
          "(docs/analysis.md §7). Placebos of one study share episodes and replicates "
          "(`popnavshift calibrate` prints this table; the test suite checks the rules on "
          "synthetic studies with many independent replicates).")
