"""Report sections of the robustness parts (paper §IV-C, §V-D, §V-E).

The tables of :mod:`popnavshift.analysis.study_robustness` (mapping, structure, backend,
respondent, seed-set spread), shown with the paper's figures beside ours. Parts the study
did not run say so.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pandas as pd

from ..analysis import paper_reference as paper
from .blocks import Cell, Section, para, pct, table
from .figures import METRIC_LABELS

#: how the structure section names a profile set, by its ``perturbation``
PERTURBATION_LABELS = {
    "reassign": "whole profiles reassigned",
    "shuffle": "columns shuffled",
}


def set_label(r: Any) -> str:
    """A structure row's profile set, from its ``perturbation`` columns."""
    if r.perturbation == "none":
        return f"unperturbed (Mapping {r.profile_base})"
    if r.perturbation == "block":
        return f"{r.perturbation_arg.replace('_', '-')} block only"
    return PERTURBATION_LABELS.get(r.perturbation, r.mapping)


def seeds_section(tables: dict[str, pd.DataFrame], missing: str) -> Section:
    s = Section("seeds", "Spread across episode seed sets", missing=missing)
    t = tables.get("robust_seeds")
    if t is None:
        return s
    s.blocks.append(
        para(
            "The same part repeated with other episode draws (start positions, "
            "walking directions, slot draws): how much the reversal rates move "
            "when only the physical episodes are redrawn."
        )
    )
    rows = []
    for (part, metric), g in t.groupby(["part", "metric"], sort=True):
        rates = g.sort_values("seed_set")
        rows.append(
            [
                part,
                METRIC_LABELS[metric],
                ", ".join(f"s{r.seed_set}: {pct(r.rate)}" for r in rates.itertuples()),
                pct(rates["rate"].mean()),
                f"{pct(rates['rate'].min())} – {pct(rates['rate'].max())}",
            ]
        )
    s.blocks.append(
        table(
            ["Part", "Metric", "Rate per seed set", "Mean", "Range"],
            rows,
            csv="robust_seeds",
        )
    )
    return s


def _rate_cells(r: Any) -> list[Any]:
    return [
        Cell(pct(r.rate), "num strong"),
        f"[{pct(r.ci_low)}, {pct(r.ci_high)}]",
        f"{r.reversals}/{r.comparisons}",
    ]


def _paper(figures: dict[str, paper.Rates], key: str | None, metric: str) -> Cell:
    value = None if key is None else figures.get(key, {}).get(metric)
    return Cell(pct(value) if value is not None else "—", "paper")


def _mapping_key(r: Any) -> str | None:
    """The paper's key of a mapping row: an unperturbed mapping A–D (a perturbed set
    has no paper figure in Table III)."""
    return r.profile_base if r.perturbation == "none" else None


def _perturbation_key(r: Any) -> str | None:
    """The paper's key of a structure or respondent row: its perturbation of Mapping A."""
    return r.perturbation if r.profile_base == "A" else None


COLS = ["Metric", "Ours", "95% CI", "Reversals / comparable", "Paper"]


def mapping_section(tables: dict[str, pd.DataFrame], missing: str) -> Section:
    """Mappings A–D against each other (paper Table III), with agreement with A."""
    s = Section("mapping", "Mapping sensitivity (paper Table III)", missing=missing)
    if "robust_mapping" not in tables:
        return s
    s.blocks.append(para("Twelve representative episodes, all population pairs; Mappings "
                         "A–D use the same responses, membership and episode assignments. "
                         "Agreement: share of controller orderings (non-tied under both) "
                         "that a mapping shares with Mapping A."))
    t, ag = tables["robust_mapping"], tables["robust_agreement"].set_index(["metric", "mapping"])
    rows = []
    for r in t[t["metric"] != "robot_time"].sort_values(["mapping", "metric"]).itertuples():
        a = ag["agreement"].get((r.metric, r.mapping), np.nan)
        rows.append([r.mapping, METRIC_LABELS[r.metric], *_rate_cells(r),
                     _paper(paper.MAPPING_RATE, _mapping_key(r), r.metric),
                     "—" if r.mapping == "A" else pct(a),
                     _paper(paper.MAPPING_AGREEMENT, _mapping_key(r), r.metric)])
    s.blocks.append(table(["Mapping", *COLS, "Agreement with A", "Paper"], rows,
                          csv="robust_mapping"))
    return s


def structure_section(tables: dict[str, pd.DataFrame], missing: str) -> Section:
    """Perturbed profile sets against the unperturbed one (paper §V-D)."""
    s = Section("structure", "Profile structure (paper §V-D)", missing=missing)
    if "robust_structure" not in tables:
        return s
    s.blocks.append(para("Five shared populations on the twelve representative episodes. "
                         "Reassigning whole profiles among persona ids keeps the profiles "
                         "and breaks who has them; shuffling each column keeps every "
                         "marginal and breaks the associations between parameters; single "
                         "blocks let only one response block vary."))
    rows = [[set_label(r), METRIC_LABELS[r.metric], *_rate_cells(r),
             _paper(paper.STRUCTURE_RATE, _perturbation_key(r), r.metric)]
            for r in tables["robust_structure"].sort_values(["mapping", "metric"]).itertuples()]
    s.blocks.append(table(["Profiles", *COLS], rows, csv="robust_structure"))
    return s


def backend_section(tables: dict[str, pd.DataFrame], missing: str) -> Section:
    """Ped-ORCA against navground's HL pedestrians (paper §V-E)."""
    s = Section("backend", "Pedestrian dynamics: Ped-ORCA vs navground HL (paper §V-E)",
                missing=missing)
    if "robust_backend" not in tables:
        return s
    s.blocks.append(para("Twelve obstacle-free episodes, four populations, everything else "
                         "matched; only (cell, population) units completed by all three "
                         "controllers under both backends count."))
    rows = [[r.backend, METRIC_LABELS[r.metric], *_rate_cells(r),
             _paper(paper.BACKEND_RATE, r.backend, r.metric)]
            for r in tables["robust_backend"].sort_values(["backend", "metric"]).itertuples()]
    s.blocks.append(table(["Backend", *COLS], rows, csv="robust_backend"))
    return s


def respondent_section(tables: dict[str, pd.DataFrame], missing: str,
                       respondent2: str) -> Section:
    """The matched intervention answered by a second respondent (``respondent2``)."""
    s = Section("respondent", "Respondent robustness: the matched intervention again",
                missing=missing)
    if "robust_respondent" not in tables:
        return s
    s.blocks.append(para(f"The same persona ids answered by a second respondent "
                         f"({respondent2}); probe-defined cohorts are not compared because "
                         "their membership depends on the respondent."))
    rows = [["first (Mapping A)" if r.perturbation == "none" else f"second ({r.mapping})",
             METRIC_LABELS[r.metric], *_rate_cells(r),
             _paper(paper.RESPONDENT_RATE, _perturbation_key(r), r.metric)]
            for r in tables["robust_respondent"].sort_values(["mapping", "metric"]).itertuples()]
    s.blocks.append(table(["Respondent", *COLS], rows, csv="robust_respondent"))
    return s
