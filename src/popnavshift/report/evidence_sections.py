"""The report's evidence beyond the headline: rates against seed sets with the power
advice, and the calibration of every verdict rule on the study's own placebos. Built from
the ``evidence_*`` tables. (The paper's findings, each with its check beyond noise, are
one list in :func:`.sections.summary_section`.)"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from .blocks import Cell, Section, figure, fmt, para, pct, table
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


def power_block(power: pd.DataFrame) -> dict:
    rows = [[r.comparison, LABELS.get(r.metric, r.metric),
             "raw" if r.rule == "raw" else "significant", pp(r.excess),
             fmt(100 * r.null_sd, "{:.1f} pp"),
             "–" if not np.isfinite(r.sd_exponent) else f"{r.sd_exponent:.2f}",
             f"{int(r.seed_sets)} / {int(r.n_null)}", Cell(r.verdict, "strong"), _advice(r)]
            for r in power.itertuples()]
    return table(["Comparison", "Metric", "Rule", "Excess", "Null SD", "b", "Seed sets / nulls",
                  "Verdict", "What would decide it (80% power)"], rows,
                 caption="Power: what would decide each verdict. b: the null's SD falls as "
                 "(seed sets)^−b, fitted on the study's own replicate curve (0: more seed sets "
                 "do not help)", csv="evidence_power")


def replicates_section(tables: dict[str, pd.DataFrame], missing: dict[str, str],
                       figs: dict[str, Path], out: Path) -> Section:
    """Each comparison against its number of seed sets, and what would decide it."""
    s = Section("replicates", "Replicates: rates against seed sets, replicability and power")
    curve, rep = tables.get("evidence_curve"), tables.get("evidence_replicability")
    power = tables.get("evidence_power")
    if curve is None and power is None:
        s.missing = next((v for k, v in missing.items() if k.startswith("curve")),
                         "the study ran one seed set and no null")
        return s
    if "evidence_curve" in figs:
        s.blocks.append(figure(figs["evidence_curve"], out,
                               "Raw reversal rate (solid) and its null (dashed, band = range of "
                               "the null replicates) on the first 1, 2, … seed sets."))
    if rep is not None and not rep.empty:
        rows = [[r.comparison, r.kind, LABELS.get(r.metric, r.metric), pct(r.marginal),
                 Cell(pct(r.recurrence), "strong"), f"{r.recurred}/{r.opportunities}"]
                for r in rep.itertuples()]
        s.blocks.append(table(["Comparison", "Pair", "Metric", "Reversal rate (one seed set)",
                               "P(recurs in another seed set)", "Recurred / opportunities"],
                              rows, caption="Replicability of a reversal seen in one seed set "
                              "(raw rule): a population effect recurs more often than its rate",
                              csv="evidence_replicability"))
    if power is not None and not power.empty:
        s.blocks.append(power_block(power))
    return s


def calibration_section(tables: dict[str, pd.DataFrame]) -> Section:
    """Every verdict rule's false-positive rate on placebos drawn from the study's nulls."""
    s = Section("calibration", "Calibration: how often each verdict rule is wrong on placebos")
    cal = tables.get("evidence_calibration")
    if cal is None or cal.empty:
        s.missing = "the study ran no null replicates to draw placebos from"
        return s
    s.blocks.append(para("A placebo takes one null replicate as if it were the observed "
                         "populations and the study's other replicates as its null: the truth "
                         "is no population effect, so every claim is false. Shifted placebos "
                         "add a known excess (5 or 10 pp) to check the 'no excess' claim and "
                         "the power. Clopper–Pearson 95% intervals; status 'within' when the "
                         "interval reaches down to the nominal level and rules out twice it, "
                         "'above nominal' when it lies above it, else 'too few placebos to "
                         "tell'. Leave-one-out placebos check the tests' assumptions, not "
                         "whether the null itself is built right (docs/analysis.md §7). "
                         "Placebos of one study share episodes and replicates (`popnavshift "
                         "calibrate` prints this table; the test suite checks the rules on "
                         "synthetic studies with many independent replicates)."))
    c = cal[cal["comparison"].isin(["table", "all"])]
    c = c if not c.empty else cal
    rows = [["the headline table" if r.comparison == "table" else r.test, r.rule, r.claim,
             "–" if not np.isfinite(r.nominal) else pct(r.nominal), f"{r.claims}/{r.placebos}",
             Cell(pct(r.rate), "strong"), f"[{pct(r.cp_low)}, {pct(r.cp_high)}]",
             Cell(r.status, "bad" if r.status == "above nominal" else
                  "ok" if r.status == "within" else "")] for r in c.itertuples()]
    s.blocks.append(table(["Test", "Rule", "Claim", "Nominal", "Claims / placebos", "Rate",
                           "95% CI", "Status"], rows,
                          caption="Every verdict rule on the study's placebos: the headline "
                          "table as a whole, then each test pooled over comparisons and metrics",
                          csv="evidence_calibration"))
    return s
