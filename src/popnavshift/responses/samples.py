"""Independent samples of one question, and the one answer profiles are built from.

A study with ``samples: k`` asks every persona (and matched variant) k times, each
sample with its own seed (:func:`~popnavshift.responses.respondent.sample_seed`), and
keeps every sample in ``responses.parquet`` (column ``sample``): the respondent audit
measures test–retest from them. Profiles and population membership read one answer per
persona and variant, :func:`aggregate_samples` (docs/method.md, "Several samples per
persona"):

* a block item: the **median** of its levels across the samples. With an odd k it is
  one of the five levels; with an even k it can fall half-way between two (0.375): the
  mappings are linear in the levels, so the midpoint takes neither sample's side.
* a probe action (nominal, no median): the **modal** action; a tie goes to the action of
  the lowest-numbered sample among the tied, a choice that favours no action.

The other columns (respondent, model, served model, identity) are sample 0's.
"""

from __future__ import annotations

import pandas as pd

from ..tables import ACTION_COLUMNS, DTYPES, Q_COLUMNS, RESPONSES, check_table

#: the declared aggregation, as the manifest and responses.json name it
AGGREGATION = "per-item median of the levels, modal action (ties: lowest sample)"
RECORD = ["persona_id", "variant"]


def with_samples(responses: pd.DataFrame) -> pd.DataFrame:
    """``responses`` with every declared column: a table written before samples and the
    served model's identity were recorded held one answer per record (sample 0) and no
    identity (missing)."""
    if set(RESPONSES.names) <= set(responses.columns):
        return responses
    old = responses.assign(sample=0) if "sample" not in responses.columns else responses
    missing = {c.name: pd.Series(None, index=old.index, dtype=DTYPES[c.kind] if c.kind ==
                                 "float" else object)
               for c in RESPONSES.columns if c.nullable and c.name not in old.columns}
    return old.assign(**missing)[RESPONSES.names]


def sample_count(responses: pd.DataFrame) -> int:
    """The most samples any record has (1 for a one-sample table)."""
    if responses.empty:
        return 1
    return int(with_samples(responses).groupby(RECORD)["sample"].nunique().max())


def aggregate_samples(responses: pd.DataFrame) -> pd.DataFrame:
    """One answer per persona and variant (module docstring), ``sample`` 0, records in the
    order they first appear (a collected table lists every sample 0 first). A one-sample
    table comes back as it is (the same rows, bit for bit)."""
    responses = with_samples(responses)
    if sample_count(responses) == 1:
        return responses
    ordered = responses.sort_values([*RECORD, "sample"], kind="stable")
    groups = ordered.groupby(RECORD, sort=False)
    first = groups.head(1).set_index(RECORD)
    items = groups[list(Q_COLUMNS)].median()
    actions = groups[list(ACTION_COLUMNS)].agg(_mode)
    out = first.assign(sample=0)
    out[list(Q_COLUMNS)] = items.loc[out.index, list(Q_COLUMNS)].to_numpy(float)
    out[list(ACTION_COLUMNS)] = actions.loc[out.index, list(ACTION_COLUMNS)].to_numpy()
    order = responses.drop_duplicates(RECORD).set_index(RECORD).index
    out = out.loc[order].reset_index()[list(responses.columns)]
    return check_table(out, "responses")


def _mode(values: pd.Series) -> str:
    """The most frequent value; among tied ones, the first in the series (samples are in
    order, so the lowest-numbered sample's)."""
    counts = values.value_counts(sort=False)
    top = counts[counts == counts.max()].index
    return str(next(v for v in values if v in top))
