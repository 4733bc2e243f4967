"""Respondent audit, test–retest: does a respondent give the same persona the same answer
when asked again?

A study with ``samples: k`` (``--samples k``) asks every persona and variant k times,
each sample with its own seed (:mod:`popnavshift.responses.samples`). The records
(persona × variant) that have all k samples are the subjects, the samples the repeated
measurements:

* a probe's action (nominal): the share of records whose k samples all agree and
  Cohen's κ of sample 0 against sample 1 for k = 2, Fleiss' κ over all k samples above
  (chance agreement from the pooled action shares);
* a block item, the action score q_a and each motion parameter (mapped from one sample at
  a time): the one-way random-effects ICC(1) (Shrout & Fleiss 1979; the samples are
  exchangeable, no sample effect), with its two variance components — within a record
  (the mean square within, sample-to-sample noise) and between records (the persona
  signal, (MSB − MSW) / k, floored at 0) — and the share of records whose samples agree.

A noisy respondent that replaces an answer by a random level with probability p comes
out at ICC ≈ (1 − p)² Var(T) / Var(X) (tests/test_audit_retest.py). A respondent at
temperature 0 should give identical samples: when it does not, the server is **not
reproducible** (it batches, caches prompts or ignores the seed), and the audit says so.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pandas as pd

from ..profiles.mappings import ACTION_SCORE
from ..tables import ACTION_COLUMNS, PARAMS, Q_COLUMNS
from .audit import ACTION_SCORE_TARGET, ANSWER_COLUMNS, cohen_kappa

RECORD = ["persona_id", "variant"]
#: how to ask for test–retest when a study has one sample per persona
HOW_TO_MEASURE = ("ask each persona at least twice: `popnavshift probe --samples 2`, or "
                  "`samples: 2` under the study's respondent")


def complete_records(responses: pd.DataFrame) -> tuple[pd.DataFrame, int]:
    """(rows of the records that have every sample 0 … k−1, sorted by record then
    sample; k), k being the most samples any record has."""
    k = int(responses.groupby(RECORD)["sample"].nunique().max()) if len(responses) else 0
    have = responses.groupby(RECORD)["sample"].transform("nunique") == k
    rows = responses[have & (responses["sample"] < k)]
    return rows.sort_values([*RECORD, "sample"], kind="stable").reset_index(drop=True), k


def fleiss_kappa(labels: np.ndarray) -> float:
    """Fleiss' κ of ``labels`` (n subjects × k raters, k ≥ 2); NaN when chance agreement
    is 1 (one category throughout)."""
    n, k = labels.shape
    cats = np.unique(labels)
    counts = np.stack([(labels == c).sum(axis=1) for c in cats], axis=1)  # n × categories
    observed = ((counts * (counts - 1)).sum(axis=1) / (k * (k - 1))).mean()
    shares = counts.sum(axis=0) / (n * k)
    expected = float((shares**2).sum())
    return np.nan if expected >= 1 else float((observed - expected) / (1 - expected))


def icc_oneway(x: np.ndarray) -> dict[str, float]:
    """ICC(1) of ``x`` (n records × k samples) with its parts: ``within_var`` (mean square
    within records), ``between_var`` ((MSB − MSW) / k, floored at 0) and ``icc``
    ((MSB − MSW) / (MSB + (k − 1) MSW); NaN when every value is equal)."""
    n, k = x.shape
    means = x.mean(axis=1)
    msb = k * ((means - x.mean()) ** 2).sum() / max(n - 1, 1)
    msw = ((x - means[:, None]) ** 2).sum() / max(n * (k - 1), 1)
    denom = msb + (k - 1) * msw
    icc = (msb - msw) / denom if denom > 1e-15 else np.nan
    return {"within_var": float(msw), "between_var": float(max((msb - msw) / k, 0.0)),
            "icc": float(icc)}


def _wide(rows: pd.DataFrame, col: str, k: int) -> np.ndarray:
    """Column ``col`` as records × samples (rows sorted by record, then sample)."""
    return rows[col].to_numpy().reshape(-1, k)


def retest(responses: pd.DataFrame,
           profile: Callable[[pd.DataFrame], pd.DataFrame] | None = None) -> pd.DataFrame:
    """One row per answer column, the action score and (with ``profile``: one sample's
    responses → its profiles, rows aligned) each motion parameter: ``target``, ``kind``,
    ``records``, ``samples`` (k), ``agree`` (all k samples equal), and ``kappa`` (actions)
    or ``icc`` with ``within_var`` and ``between_var`` (module docstring). Empty with
    fewer than 2 samples."""
    rows, k = complete_records(responses)
    if k < 2 or rows.empty:
        return pd.DataFrame()
    n = len(rows) // k
    out = []
    for col in ACTION_COLUMNS:
        labels = _wide(rows, col, k).astype(str)
        kappa = cohen_kappa(labels[:, 0], labels[:, 1]) if k == 2 else fleiss_kappa(labels)
        out.append({"target": col, "kind": "action", "agree": _all_equal(labels),
                    "kappa": kappa})
    score = rows[list(ACTION_COLUMNS)].astype(str).apply(lambda c: c.map(ACTION_SCORE))
    values = {col: _wide(rows, col, k).astype(float) for col in Q_COLUMNS}
    values[ACTION_SCORE_TARGET] = score.mean(axis=1).to_numpy().reshape(-1, k)
    kinds = dict.fromkeys(Q_COLUMNS, "item") | {ACTION_SCORE_TARGET: "action score"}
    if profile is not None:
        per_sample = [profile(rows[rows["sample"] == s].reset_index(drop=True))
                      for s in range(k)]
        for p in PARAMS:
            values[p] = np.stack([ps[p].to_numpy(float) for ps in per_sample], axis=1)
            kinds[p] = "parameter"
    for target, x in values.items():
        out.append({"target": target, "kind": kinds[target], "agree": _all_equal(x),
                    **icc_oneway(x)})
    return pd.DataFrame(out).assign(records=n, samples=k)


def _all_equal(x: np.ndarray) -> float:
    """Share of rows whose values are all equal (floats within 1e-9)."""
    if x.dtype.kind == "f":
        return float((np.ptp(x, axis=1) <= 1e-9).mean())
    return float((x == x[:, :1]).all(axis=1).mean())


def identical_share(responses: pd.DataFrame) -> float:
    """Share of complete records whose k samples give the same answer in every column
    (NaN with fewer than 2 samples)."""
    rows, k = complete_records(responses)
    if k < 2 or rows.empty:
        return np.nan
    same = np.ones(len(rows) // k, bool)
    for col in ANSWER_COLUMNS:
        x = _wide(rows, col, k).astype(str)
        same &= (x == x[:, :1]).all(axis=1)
    return float(same.mean())

