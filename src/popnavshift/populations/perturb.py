"""Profile sets for the robustness studies (paper §IV-C, §V-D/E).

Every set gets a label in the ``mapping`` column of the populations table, so the
engine and the analysis treat it like a mapping: a run's identity includes it and
controllers are only compared within one set. Labels:

* ``A``–``D``: the four mappings (:mod:`popnavshift.profiles.mappings`);
* ``A~reassign``: whole Mapping A profile vectors reassigned among persona ids by a
  seeded permutation before the populations are rebuilt (membership unchanged);
* ``A~shuffle``: within each population, each parameter column permuted
  independently (marginals kept exactly, associations broken);
* ``A~block-<name>``: profiles mapped from responses in which only one response block
  varies across personas and every other answer is set to its population-wide typical
  value (median level; most common action per probe);
* ``A~<respondent label>``: the matched pair re-profiled from a second respondent.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from ..hashing import stable_seed
from ..tables import ACTION_COLUMNS, PARAMS, Q_COLUMNS, Z_COLUMNS, check_table

#: Response blocks for the single-block runs: item columns (and whether actions vary).
BLOCKS: dict[str, tuple[tuple[str, ...], bool]] = {
    "time_pressure": (("q_urgency", "q_waiting"), False),
    "caution": (("q_clearance", "q_yielding", "q_gap", "q_detour"), True),
    "trust": (("q_trust",), False),
}


UNPERTURBED = "original"
SECOND_RESPONDENT = "second_respondent"


def profile_set_of(mapping: str) -> str:
    """The ``profile_set`` column: how a profile set was made, from its label.

    ``original`` (a mapping A–D of the respondent's answers), ``reassign``, ``shuffle``,
    ``block-<name>``, or ``second_respondent`` (``A~<respondent>-2``).
    """
    base, sep, kind = mapping.partition("~")
    if not sep:
        return UNPERTURBED
    if kind in ("reassign", "shuffle") or kind.startswith("block-"):
        return kind
    return SECOND_RESPONDENT if kind.endswith("-2") else kind


def label(kind: str, detail: str | None = None, base: str = "A") -> str:
    return f"{base}~{kind}" if detail is None else f"{base}~{kind}-{detail}"


def reassign_profiles(profiles: pd.DataFrame, seed: int) -> pd.DataFrame:
    """Baseline profile vectors moved to other persona ids by one seeded permutation.

    The multiset of profile vectors is unchanged; which persona carries which vector
    is not. Deadline rows are left as they are (the structure study does not use the
    matched pair).
    """
    out = profiles.copy()
    base = np.flatnonzero((out["variant"] == "baseline").to_numpy())
    ids = out["persona_id"].to_numpy()[base]
    order = np.argsort(ids, kind="stable")  # permutation defined on sorted ids
    rng = np.random.default_rng(stable_seed("reassign", seed))
    perm = rng.permutation(len(base))
    cols = [*PARAMS, *(Z_COLUMNS[p] for p in PARAMS), "caution"]
    values = out[cols].to_numpy(copy=True)
    src = base[order][perm]
    values[base[order]] = out[cols].to_numpy()[src]
    out[cols] = values
    out["mapping"] = label("reassign")
    return check_table(out, "profiles")


def shuffle_columns(populations: pd.DataFrame, seed: int) -> pd.DataFrame:
    """Each parameter column permuted independently within each population."""
    out = populations.copy()
    for name, idx in out.groupby("population", sort=True).indices.items():
        for p in PARAMS:
            rng = np.random.default_rng(stable_seed("shuffle", seed, name, p))
            col = out.columns.get_loc(p)
            out.iloc[idx, col] = out.iloc[idx, col].to_numpy()[rng.permutation(len(idx))]
    out["mapping"] = label("shuffle")
    return check_table(out, "populations")


def single_block_responses(responses: pd.DataFrame, block: str) -> pd.DataFrame:
    """Responses in which only ``block`` varies; all else is set to its typical value."""
    items, actions_vary = BLOCKS[block]
    out = responses.copy()
    base = responses[responses["variant"] == "baseline"]
    for q in Q_COLUMNS:
        if q not in items:
            levels = np.sort(base[q].to_numpy())
            out[q] = float(levels[(len(levels) - 1) // 2])  # a median that is a real level
    if not actions_vary:
        for a in ACTION_COLUMNS:
            out[a] = str(base[a].value_counts().sort_index().idxmax())
    return out
