"""The answer's caveat where a verdict rule's false-positive rate was measured above nominal
on many null replicates of this very design (``data/larger_studies.json``, its
``calibration`` and ``calibration_reversal``; docs/analysis.md §7): the claims it made here
are said to hold at that rate. The design, not the seed, is what was measured, so it is
said for any seed of the study and for no other design (other variants per cell, another
test)."""

from __future__ import annotations

import numpy as np
import pandas as pd

from ..analysis.interaction import CHANGES, PREDICTION
from ..analysis.verdicts import ALPHA
from .larger import Measured, MeasuredClaim, measured_calibration, measured_claims
from .plain_words import by_metric, join, label, phrase

SHARED = ("the placebos share replicates, so the intervals are narrower than independent "
          "draws would give")


def _count(at: dict) -> str:
    """``28 of 375 placebos (7.5% [5.0, 10.6])``."""
    return (f"{at['claims']:,} of {at['placebos']:,} placebos ({100 * at['rate']:.1f}% "
            f"[{100 * at['cp_low']:.1f}, {100 * at['cp_high']:.1f}])")


def _on_design(m: Measured | MeasuredClaim) -> str:
    """``On 200 null replicates of this design (3 variants per cell; seed 0) each taken as
    the observed, the``"""
    return (f"On {m.replicates} null replicates of this design ({m.variants_per_cell} "
            f"variants per cell; seed {m.seed}) each taken as the observed, the")


def _variants(inter: pd.DataFrame, comparison: str) -> int | None:
    own = inter[inter["comparison"] == comparison]
    return None if own.empty else int(own["variants_per_cell"].iloc[0])


def _interaction(rows: pd.DataFrame, inter: pd.DataFrame, study: str) -> list[str]:
    said = []
    for m in measured_calibration(study):
        own = inter[inter["comparison"] == m.comparison]
        claims = rows[(rows["comparison"] == m.comparison) & (rows["inter"] == CHANGES)]
        level = float(own["alpha_row"].max()) if "alpha_row" in own else np.nan
        above = m.at_05["cp_low"] > ALPHA or m.at_level["cp_low"] > level
        if m.test != "interaction" or own.empty or claims.empty or not above or \
                _variants(inter, m.comparison) != m.variants_per_cell or \
                own.get("reference", pd.Series([PREDICTION])).iloc[0] != m.reference:
            continue
        said.append(
            f"{_on_design(m)} interaction test {phrase(m.comparison)} claimed a change on "
            f"{_count(m.at_05)} at 5% and on "
            f"{_count(m.at_level)} at the headline's level"
            + (f" ({level:.3g})" if np.isfinite(level) else "")
            + f": read its claims here ({join([label(x) for x in by_metric(claims)['metric']])})"
            f" at that rate, not the nominal one ({SHARED}; with more variants per cell, as in "
            "the larger built-in studies, the rate is not measured).")
    return said


def _reversal(rows: pd.DataFrame, inter: pd.DataFrame, study: str) -> list[str]:
    said = []
    for m in measured_claims(study):
        claims = rows[(rows["comparison"] == m.comparison) & (rows["rev"] == m.claim)
                      & (rows["test"] == m.test)]
        if claims.empty or m.measured["cp_low"] <= m.nominal or \
                _variants(inter, m.comparison) != m.variants_per_cell:
            continue
        said.append(
            f"{_on_design(m)} reversal rule {phrase(m.comparison)} claimed '{m.claim}' on "
            f"{_count(m.measured)} at a nominal "
            f"{100 * m.nominal:.1f}% (one-sided, before the table's adjustment): read its "
            f"'{m.claim}' verdicts here "
            f"({join([label(x) for x in by_metric(claims)['metric']])}) with a false-positive "
            f"rate above nominal ({SHARED}; docs/analysis.md §7).")
    return said


def measured_rate_sentence(rows: pd.DataFrame, inter: pd.DataFrame | None,
                           study: tuple[str, int | None] | None) -> dict[str, str] | None:
    """Where a rule's false-positive rate was measured above nominal on many null
    replicates of this very design (:func:`.larger.measured_calibration`,
    :func:`.larger.measured_claims`), the claims it made here are said to hold at that
    rate."""
    if study is None or inter is None or inter.empty or "variants_per_cell" not in inter:
        return None
    said = _interaction(rows, inter, study[0]) + _reversal(rows, inter, study[0])
    if not said:
        return None
    lead = ("One test claims more often than nominal at this design." if len(said) == 1
            else "Some tests claim more often than nominal at this design.")
    return {"lead": lead, "text": " ".join(said)}
