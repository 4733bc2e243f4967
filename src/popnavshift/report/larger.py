"""Where a larger built-in study decided what this one leaves undecided (issue #32, item 3).

A study that cannot decide a headline row within the default's budget says so, and names
the smallest larger built-in study that did decide it, with its runs and time. What each
larger study decided is a measurement (docs/method.md, "The default design and the larger
study"), recorded in ``data/larger_studies.json`` by the study it enlarges; it holds only
for that study's seed, and the sentence says so. Rows that no measured design decided are
recorded too, each with what was measured and what would decide it, so the report says
that instead of only "no built-in study".
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from importlib import resources

import pandas as pd

from ..analysis.recombine import PREDICTION

#: the two questions of the headline, as the record names them
QUESTIONS = ("reversals", "interaction")


@dataclass(frozen=True)
class Larger:
    """A larger built-in study: its name, the seed its decisions were measured on, its
    runs, the minutes it took on 2 cores to grow a finished folder of the smaller study
    into it (None if not measured), and the rows it decided by question
    (``comparison/metric``)."""

    name: str
    seed: int
    runs: int
    minutes: float | None
    decided: dict[str, frozenset[str]]


@dataclass(frozen=True)
class Unresolved:
    """Rows (``comparison/metric``) of one question that no measured design decided on study
    seed ``seed``, and the measurement that says so, as a clause (what was run, what it
    gave, what would decide them)."""

    question: str
    seed: int
    rows: frozenset[str]
    why: str


@dataclass(frozen=True)
class Measured:
    """A rule's false-positive rate measured on ``replicates`` null replicates of a study's
    design (seed ``seed``) for one comparison at ``variants_per_cell``, by the test's
    ``reference`` (the interaction table's column): claims and placebos at 5 % and at the
    headline's level, each with its Clopper–Pearson interval."""

    comparison: str
    test: str
    reference: str
    seed: int
    replicates: int
    variants_per_cell: int
    at_05: dict
    at_level: dict


@dataclass(frozen=True)
class MeasuredClaim:
    """A reversal verdict's claim (``claim``: :data:`..analysis.verdicts.ABOVE`) as the raw
    rule makes it at its ``nominal`` one-sided level, measured on ``replicates`` null
    replicates of a study's design (seed ``seed``) for one comparison at
    ``variants_per_cell``, decided by ``test`` (the headline's ``test``: a rate decided by
    another says nothing of it): ``measured`` holds the claims, placebos, rate and
    Clopper–Pearson interval."""

    comparison: str
    claim: str
    nominal: float
    seed: int
    replicates: int
    variants_per_cell: int
    measured: dict
    test: str = PREDICTION


def _record(study: str) -> dict:
    text = resources.files("popnavshift").joinpath("data/larger_studies.json").read_text("utf-8")
    rec = json.loads(text).get(study)
    return rec if isinstance(rec, dict) else {}


def larger_studies(study: str) -> list[Larger]:
    """The larger built-in studies recorded for ``study``, smallest first (empty if none)."""
    found = [Larger(r["name"], int(r["seed"]), int(r["runs"]), r.get("minutes"),
                    {q: frozenset(r["decided"].get(q, ())) for q in QUESTIONS})
             for r in _record(study).get("larger", [])]
    return sorted(found, key=lambda s: s.runs)


def unresolved(study: str) -> list[Unresolved]:
    """The rows of ``study`` that no measured design decided, with why."""
    rec = _record(study)
    if "unresolved_as" in rec:  # the same grid: the same measurement
        rec = _record(rec["unresolved_as"])
    return [Unresolved(u["question"], int(u["seed"]), frozenset(u["rows"]), u["why"])
            for u in rec.get("unresolved", [])]


def measured_here(study: str, seed: int | None) -> dict[str, frozenset[str]]:
    """Per question, the rows of ``study`` whose fate a measurement on this very seed
    settles: decided by a larger built-in study, or decided by no design of the grid. The
    report says the measurement for them, not a model's prediction."""
    rows: dict[str, set[str]] = {q: set() for q in QUESTIONS}
    for larger in larger_studies(study):
        if larger.seed == seed:
            for q in QUESTIONS:
                rows[q] |= larger.decided[q]
    for u in unresolved(study):
        if u.seed == seed:
            rows[u.question] |= u.rows
    return {q: frozenset(r) for q, r in rows.items()}


def row_keys(rows: pd.DataFrame) -> pd.Series:
    """``comparison/metric`` of each row, the record's key."""
    return rows["comparison"].astype(str) + "/" + rows["metric"].astype(str)


def split_undecided(rows: pd.DataFrame, question: str, larger: Larger | None
                    ) -> tuple[pd.DataFrame, pd.DataFrame]:
    """``rows`` (undecided, with ``comparison`` and ``metric``) split into those the larger
    study decided on its seed for ``question`` and the rest."""
    if larger is None or rows.empty:
        return rows.iloc[:0], rows
    hit = row_keys(rows).isin(larger.decided.get(question, frozenset())).to_numpy()
    return rows[hit], rows[~hit]


def larger_clause(larger: Larger, seed: int | None, n_rows: int = 2) -> str:
    """``the built-in study paper-large (386,928 runs, 14 min on 2 cores) decided them on
    seed 0`` — with "on another seed" when this study's seed differs."""
    cost = f"{larger.runs:,} runs" + (f"; about {larger.minutes:.0f} min on 2 cores from a "
                                      f"finished folder of this study"
                                      if larger.minutes else "")
    where = (f"on this study's seed ({larger.seed})" if seed == larger.seed
             else f"on seed {larger.seed}, not this study's")
    return (f"the built-in study {larger.name} ({cost}; `popnavshift run {larger.name}`) "
            f"decided {'it' if n_rows == 1 else 'them'} {where}")


def measured_calibration(study: str) -> list[Measured]:
    """The false-positive rates measured on many null replicates of ``study``'s design."""
    return [Measured(c["comparison"], c["test"], c["reference"], int(c["seed"]),
                     int(c["replicates"]),
                     int(c["variants_per_cell"]), c["at_05"], c["at_level"])
            for c in _record(study).get("calibration", [])]


def measured_claims(study: str) -> list[MeasuredClaim]:
    """The reversal claims whose raw rate was measured on many null replicates of
    ``study``'s design (the record's ``calibration_reversal``)."""
    return [MeasuredClaim(c["comparison"], c["claim"], float(c["nominal"]), int(c["seed"]),
                          int(c["replicates"]), int(c["variants_per_cell"]), c["measured"],
                          str(c.get("test", PREDICTION)))
            for c in _record(study).get("calibration_reversal", [])]
