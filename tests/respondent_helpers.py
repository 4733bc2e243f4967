"""Respondents, answers and the audit page the audit tests share (test_audit.py,
test_audit_cli.py, test_audit_retest.py)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from popnavshift.analysis.audit_verdict import MIN_PERMUTATIONS, audit_tables
from popnavshift.analysis.study import Analysis
from popnavshift.hashing import stable_seed
from popnavshift.personas.variants import matched_ids
from popnavshift.read.folder import StudyFolder
from popnavshift.read.respondent_tables import read_respondent_tables
from popnavshift.report.page import render_report
from popnavshift.responses.collect import collect_responses
from popnavshift.responses.probes import PROBE_IDS
from popnavshift.responses.respondent import Answer, ProbeRequest, Progress, Respondent
from popnavshift.responses.schema import LEVELS
from popnavshift.tables import ACTIONS, BLOCK_ITEMS


class BlindRespondent(Respondent):
    """Valid, varied answers drawn from the persona id alone: it never reads a field."""

    name = "blind"

    def answer_all(self, requests: Sequence[ProbeRequest],
                   progress: Progress | None = None) -> list[Answer]:
        out = []
        for r in requests:
            rng = np.random.default_rng(stable_seed("blind", r.persona_id))
            answer = {"actions": {p: ACTIONS[rng.integers(len(ACTIONS))] for p in PROBE_IDS},
                      "block": {k: LEVELS[rng.integers(len(LEVELS))] for k in BLOCK_ITEMS}}
            out.append(Answer(r.persona_id, r.variant, answer=answer))
        return out


def answers(personas: pd.DataFrame, respondent: Respondent) -> pd.DataFrame:
    responses, invalid, _ = collect_responses(personas, respondent, matched_ids(personas, 202))
    assert invalid.empty
    return responses


def render_audit(folder: Path) -> str:
    """The report page of a folder holding only respondent tables: the audit and its banner."""
    tables = audit_tables(*read_respondent_tables(folder), n_perm=MIN_PERMUTATIONS, n_boot=200)
    study = StudyFolder(folder, manifest={}, tables={"runs": pd.DataFrame(),
                                                     "pedestrians": pd.DataFrame(),
                                                     "populations": None, "episodes": None})
    a = Analysis(selection="none", tables=tables,
                 missing={"evidence_headline": "no comparison was run"}, delays_missing="none")
    return render_report(study, a, {}, folder / "report", {})
