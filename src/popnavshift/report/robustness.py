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
from ..design.part import PART_ROLES
from ..populations.perturb import ProfileSet
from .blocks import Block, Cell, Page, SectionSpec, para, pct, table
from .figures import METRIC_LABELS


def set_label(r: Any) -> str:
    """A structure row's profile set, from its ``perturbation`` columns, in the words its
    perturbation declares (:attr:`popnavshift.populations.perturb.ProfileSet.words`)."""
    return ProfileSet(r.profile_base, r.perturbation, r.perturbation_arg).words


def _seeds(p: Page, t: pd.DataFrame) -> list[Block]:
    rows = []
    for (part, metric), g in t.groupby(["part", "metric"], sort=True):
        rates = g.sort_values("seed_set")
        rows.append([part, METRIC_LABELS[metric],
                     ", ".join(f"s{r.seed_set}: {pct(r.rate)}" for r in rates.itertuples()),
                     pct(rates["rate"].mean()),
                     f"{pct(rates['rate'].min())} – {pct(rates['rate'].max())}"])
    return [table(["Part", "Metric", "Rate per seed set", "Mean", "Range"], rows,
                  csv="robust_seeds")]


SEEDS = SectionSpec(
    "seeds", "Spread across episode seed sets", _seeds, needs=("robust_seeds",),
    intro="The same part repeated with other episode draws (start positions, walking "
          "directions, slot draws): how much the reversal rates move when only the physical "
          "episodes are redrawn.")


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


def _mapping(p: Page, t: pd.DataFrame) -> list[Block]:
    """Mappings A–D against each other (paper Table III), with agreement with A."""
    ag = p.a.tables["robust_agreement"].set_index(["metric", "mapping"])
    rows = []
    for r in t[t["metric"] != "robot_time"].sort_values(["mapping", "metric"]).itertuples():
        a = ag["agreement"].get((r.metric, r.mapping), np.nan)
        rows.append([r.mapping, METRIC_LABELS[r.metric], *_rate_cells(r),
                     _paper(paper.MAPPING_RATE, _mapping_key(r), r.metric),
                     "—" if r.mapping == "A" else pct(a),
                     _paper(paper.MAPPING_AGREEMENT, _mapping_key(r), r.metric)])
    return [table(["Mapping", *COLS, "Agreement with A", "Paper"], rows, csv="robust_mapping")]


def _structure(p: Page, t: pd.DataFrame) -> list[Block]:
    """Perturbed profile sets against the unperturbed one (paper §V-D)."""
    rows = [[set_label(r), METRIC_LABELS[r.metric], *_rate_cells(r),
             _paper(paper.STRUCTURE_RATE, _perturbation_key(r), r.metric)]
            for r in t.sort_values(["mapping", "metric"]).itertuples()]
    return [table(["Profiles", *COLS], rows, csv="robust_structure")]


def _backend(p: Page, t: pd.DataFrame) -> list[Block]:
    """Ped-ORCA against navground's HL pedestrians (paper §V-E)."""
    rows = [[r.backend, METRIC_LABELS[r.metric], *_rate_cells(r),
             _paper(paper.BACKEND_RATE, r.backend, r.metric)]
            for r in t.sort_values(["backend", "metric"]).itertuples()]
    return [table(["Backend", *COLS], rows, csv="robust_backend")]


def _respondent(p: Page, t: pd.DataFrame) -> list[Block]:
    """The matched intervention answered by a second respondent."""
    rows = [["first (Mapping A)" if r.perturbation == "none" else f"second ({r.mapping})",
             METRIC_LABELS[r.metric], *_rate_cells(r),
             _paper(paper.RESPONDENT_RATE, _perturbation_key(r), r.metric)]
            for r in t.sort_values(["mapping", "metric"]).itertuples()]
    return [para(f"The same persona ids answered by a second respondent "
                 f"({second_respondent(p.study.manifest)}); probe-defined cohorts are not "
                 "compared because their membership depends on the respondent."),
            table(["Respondent", *COLS], rows, csv="robust_respondent")]


def second_respondent(manifest: dict[str, Any]) -> str:
    second = (manifest.get("study_config") or {}).get("respondent2") or {}
    name = second.get("name", "none")
    if name == "rule":
        return "the rule surrogate with a second parameter set, not a language model"
    return f"{name} {second.get('options', {})}"


#: one section per robustness role, titled by the role's declaration
#: (:data:`popnavshift.design.part.PART_ROLES`)
MAPPING = SectionSpec(
    "mapping", PART_ROLES["mapping"], _mapping, needs=("robust_mapping",),
    intro="Twelve representative episodes, all population pairs; Mappings A–D use the same "
          "responses, membership and episode assignments. Agreement: share of controller "
          "orderings (non-tied under both) that a mapping shares with Mapping A.")
STRUCTURE = SectionSpec(
    "structure", PART_ROLES["structure"], _structure, needs=("robust_structure",),
    intro="Five shared populations on the twelve representative episodes. Reassigning whole "
          "profiles among persona ids keeps the profiles and breaks who has them; shuffling "
          "each column keeps every marginal and breaks the associations between parameters; "
          "single blocks let only one response block vary.")
BACKEND = SectionSpec(
    "backend", PART_ROLES["backend"], _backend, needs=("robust_backend",),
    intro="Twelve obstacle-free episodes, four populations, everything else matched; only "
          "(cell, population) units completed by all three controllers under both backends "
          "count.")
RESPONDENT = SectionSpec("respondent", PART_ROLES["respondent"], _respondent,
                         needs=("robust_respondent",))
