"""The paragraph after the answer (:mod:`.plain`): what it rests on — what orderings
significant under both populations do, the cell-by-cell crossover tests and the deciding
test's false-positive rate on the study's own placebos. Each sentence opens with a verdict;
counts and rates follow it, one metric at a time, never as its lead.
"""

from __future__ import annotations

import pandas as pd

from ..analysis.recombine import PREDICTION, RECOMBINED
from ..analysis.verdicts import ABOVE, DESCRIPTIVE, NOT_SHOWN, min_nulls_permutation
from .blocks import pct
from .plain_words import by_metric, join, label, phrase

SIG = "orderings significant under both populations"


def _sig_verdict(rows: pd.DataFrame) -> str:
    """One comparison's significant-rule verdict, in words (before any count)."""
    above = [label(m) for m in rows.loc[rows["verdict"] == ABOVE, "metric"]]
    level = float(rows["level"].iloc[0]) if "level" in rows else 0.95
    alpha = 1 - level
    if above:
        return f"the exact permutation test puts {join(above)} above the null"
    if (rows["verdict"] == NOT_SHOWN).all():
        return "the exact permutation test shows none above the null"
    if (rows["verdict"] == DESCRIPTIVE).all():
        return (f"the exact permutation test cannot decide ({int(rows['n_null'].max())} null "
                f"replicates cannot bring it to its level, p ≤ {alpha:.3g}; it needs "
                f"{min_nulls_permutation(alpha)}), so the counts are descriptive")
    return ("the exact permutation test shows none above the null where it can decide "
            f"(elsewhere too few null replicates: it needs {min_nulls_permutation(alpha)})")


def decided_sentence(head: pd.DataFrame) -> dict[str, str] | None:
    """What orderings significant under both populations do (the significant rule): the
    exact permutation verdict first, then each metric's count."""
    sig = head[(head["rule"] == "sig") & (head["n_null"] > 0)]
    if sig.empty:
        return None
    parts = []
    for comp, rows in sig.groupby("comparison", sort=False):
        rows = by_metric(rows)
        counts = join([f"{label(r.metric)} {r.reversals} of {r.comparable:,} "
                       f"({pct(r.observed)})" for r in rows.itertuples()])
        parts.append(f"{phrase(str(comp))}, {_sig_verdict(rows)}; reversed: {counts}")
    above = sig[sig["verdict"] == ABOVE]
    if not above.empty:
        lead = (f"Among {SIG}, reversals exceed the null for "
                + join([f"{label(r.metric)} {phrase(r.comparison)}"
                        for r in by_metric(above).itertuples()]) + ".")
    elif (sig["verdict"] == DESCRIPTIVE).all():
        lead = f"Whether {SIG} reverse beyond the null is not decided at this design."
    else:
        lead = f"Among {SIG}, reversals are not shown to exceed the null."
    return {"lead": lead,
            "text": f"Of the {SIG} (90% paired interval excludes 0): " + "; ".join(parts) + "."}


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
            parts.append(f"{phrase(str(comp))}, no test is possible (one episode per "
                         "cell has no spread to judge a sign by)")
            continue
        size = float(g["detectable"].median())
        parts.append(f"{phrase(str(comp))}, {found} of {tests} (cell, controller pair) "
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
                       & calibration["test"].isin([PREDICTION, RECOMBINED])
                       & calibration["claim"].str.startswith("an effect")]
    if test.empty:
        return None
    by = {r["test"]: r for _, r in test.iterrows()}

    def rate(r: pd.Series) -> str:
        return (f"on {int(r['placebos'])} placebos drawn from this study's own nulls it "
                f"claimed an effect in {pct(r['rate'])} [95% {pct(r['cp_low'])}, "
                f"{pct(r['cp_high'])}] at a nominal {pct(r['nominal'])}")

    tests = []
    if PREDICTION in by:
        tests.append("by a prediction t on the spread between replicates (alone, "
                     + rate(by[PREDICTION]) + ")")
    if RECOMBINED in by:
        tests.append("across the population pairs, whose null is drawn population by "
                     "population, by the exact randomization test over designs recombined "
                     "from the replicates (" + rate(by[RECOMBINED]) + ")")
    family = ""
    if not table.empty:
        f = table.iloc[0]
        family = (f" The table's rates are decided together (Bonferroni): the whole table "
                  f"claimed an effect on {int(f['claims'])} of {int(f['placebos'])} placebo "
                  f"tables ({pct(f['rate'])} [95% {pct(f['cp_low'])}, {pct(f['cp_high'])}]) at "
                  f"a nominal {pct(f['nominal'])}.")
    return {"lead": "How the reversal verdicts are decided.",
            "text": "Each reversal verdict rests on the raw reversal rate (the paper's tie rule) "
                    "against null replicates run on the same episodes, "
                    + "; ".join(tests) + "." + family + " Intervals are simultaneous 95% "
                    "intervals over the headline table (calibration section)."}
