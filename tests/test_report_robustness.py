"""The robustness sections name profile sets and find the paper's figures by the
profile-set columns (``profile_base``, ``perturbation``, ``perturbation_arg``), not by
parsing the ``mapping`` label."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import pandas as pd

from popnavshift.analysis import paper_reference as paper
from popnavshift.analysis.study import Analysis
from popnavshift.populations.perturb import ProfileSet
from popnavshift.report.blocks import Page
from popnavshift.report.robustness import BACKEND, MAPPING, RESPONDENT, STRUCTURE


def rates(labels: list[str], metric: str = "mean_delay") -> pd.DataFrame:
    rows = []
    for i, label in enumerate(labels):
        s = ProfileSet.parse(label)
        rows.append({"metric": metric, "backend": "orca", "mapping": label, "reversals": i,
                     "comparisons": 10, "rate": i / 10, "ci_low": 0.0, "ci_high": 0.5,
                     "profile_base": s.base, "perturbation": s.perturbation,
                     "perturbation_arg": s.arg})
    return pd.DataFrame(rows)


def table_rows(section) -> list[list[str]]:
    block = next(b for b in section.blocks if b["kind"] == "table")
    return [[c.text for c in row] for row in block["rows"]]


def sections(tables):
    study = SimpleNamespace(manifest={"study_config": {"respondent2": {"name": "rule"}}})
    page = Page(study, Analysis(selection="", tables=tables), {}, Path("."), {})  # type: ignore[arg-type]
    return {s.id: s.render(page) for s in (MAPPING, STRUCTURE, BACKEND, RESPONDENT)}


def test_structure_rows_are_named_and_matched_to_the_paper_by_their_columns():
    labels = ["A", "A~block-time_pressure", "A~reassign", "A~shuffle"]
    rows = table_rows(sections({"robust_structure": rates(labels)})["structure"])
    assert [r[0] for r in rows] == ["unperturbed (Mapping A)", "time-pressure block only",
                                    "whole profiles reassigned", "columns shuffled"]
    expected = [paper.STRUCTURE_RATE["none"]["mean_delay"], None,
                paper.STRUCTURE_RATE["reassign"]["mean_delay"],
                paper.STRUCTURE_RATE["shuffle"]["mean_delay"]]
    assert [r[-1] for r in rows] == ["—" if v is None else f"{100 * v:.1f}%" for v in expected]


def test_mapping_and_respondent_rows_use_the_base_and_the_perturbation():
    mapping = rates(["A", "B", "D"])
    agreement = mapping[["metric", "mapping"]].assign(agreement=[1.0, 0.9, 0.7])
    respondent = rates(["A", "A~gpt-x-2"])
    got = sections({"robust_mapping": mapping, "robust_agreement": agreement,
                    "robust_respondent": respondent})
    rows = table_rows(got["mapping"])
    assert [r[5] for r in rows] == [f"{100 * paper.MAPPING_RATE[m]['mean_delay']:.1f}%"
                                    for m in ("A", "B", "D")]
    agree_d = paper.MAPPING_AGREEMENT["D"]["mean_delay"]
    assert rows[0][7] == "—" and rows[2][7] == f"{100 * agree_d:.1f}%"
    rows = table_rows(got["respondent"])
    assert [r[0] for r in rows] == ["first (Mapping A)", "second (A~gpt-x-2)"]
    assert rows[1][-1] == f"{100 * paper.RESPONDENT_RATE['second_respondent']['mean_delay']:.1f}%"
