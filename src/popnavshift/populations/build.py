"""The eight population conditions of SPEC §5, as one long membership table.

Membership is decided once from the personas, the responses and the Mapping A
profiles (``membership``); the member profiles of any mapping are then attached
(``attach_profiles``), so Mappings A–D share membership, as the mapping
sensitivity study requires. Members are sorted by persona id; slot k of an
episode takes member ⌊u_k · n⌋ (see :mod:`popnavshift.episodes`).
"""

from __future__ import annotations

from collections.abc import Callable, Collection, Mapping, Sequence
from functools import cache

import numpy as np
import pandas as pd

from ..errors import InputError, UnknownNameError
from ..hashing import stable_seed
from ..personas.fields import HIGH_TIME_PRESSURE, MOBILITY_SUPPORT
from ..tables import PARAMS, check_table
from .identity import (
    ARMS,
    MATCHED_PAIR,
    Members,
    PopulationSpec,
    Records,
    index_of,
    null_kind,
    spec_of,
)

POPULATIONS: tuple[str, ...] = (
    "homogeneous",
    "mixed",
    "high_time_pressure",
    "mobility_support",
    "high_caution",
    "low_robot_trust",
    "matched_base",
    "matched_deadline",
)
#: Grouping used by figures: reference, source-field cohorts, probe cohorts, matched pair.
POPULATION_GROUPS: dict[str, tuple[str, ...]] = {
    "reference": ("homogeneous", "mixed"),
    "source-field": ("high_time_pressure", "mobility_support"),
    "probe-defined": ("high_caution", "low_robot_trust"),
    "matched": MATCHED_PAIR,
}
#: Random halves of mixed, for the noise floor: ``mixed_half_a`` / ``mixed_half_b``.
HALVES: tuple[PopulationSpec, ...] = tuple(PopulationSpec.half("mixed", arm) for arm in ARMS)
SPLIT_HALVES: tuple[str, ...] = tuple(h.name for h in HALVES)
#: Every population a study part may list by name, as its identity: the conditions and
#: the split halves (a null replicate comes from a part's ``null_design``, never a name).
KNOWN: dict[str, PopulationSpec] = index_of([*map(PopulationSpec, POPULATIONS), *HALVES])
HOMOGENEOUS_ID = "median"
LOW_TRUST_MAX = 0.25
HIGH_CAUTION_QUANTILE = 0.75

Selector = Callable[[pd.DataFrame], pd.Series]

_SELECTORS: dict[str, Selector] = {
    "mixed": lambda b: pd.Series(True, index=b.index),
    "high_time_pressure": lambda b: b["time_pressure"].isin(HIGH_TIME_PRESSURE),
    "mobility_support": lambda b: (
        b["health_mobility"].isin(MOBILITY_SUPPORT) | (b["accessibility_needs"] == "Motor")
    ),
    # ties at the quartile are kept (>=)
    "high_caution": lambda b: b["caution"] >= b["caution"].quantile(HIGH_CAUTION_QUANTILE),
    "low_robot_trust": lambda b: b["q_trust"] <= LOW_TRUST_MAX,
}


#: what each population holds, for the message that says one came out empty
DEFINITIONS: dict[str, str] = {
    "homogeneous": "the median profile",
    "mixed": "every persona with a valid baseline response",
    "high_time_pressure": f"personas whose time_pressure is {' or '.join(HIGH_TIME_PRESSURE)}",
    "mobility_support": (f"personas whose health_mobility is {' or '.join(MOBILITY_SUPPORT)} "
                         "or whose accessibility_needs is Motor"),
    "high_caution": f"personas at or above the {HIGH_CAUTION_QUANTILE:.0%} quantile of caution",
    "low_robot_trust": f"personas whose probe trust answer is at most {LOW_TRUST_MAX}",
    "matched_base": "the matched_n personas with a valid answer in both variants",
    "matched_deadline": "the matched_n personas with a valid answer in both variants",
}


def definition(spec: PopulationSpec) -> str:
    """What population ``spec`` holds, in words (nulls and halves by their source)."""
    if spec.is_null:
        return f"a null replicate of {' and '.join(spec.bases)}"
    if spec.role == "half":
        return f"a random half of {definition(PopulationSpec(spec.base))}"
    return DEFINITIONS.get(spec.name, spec.name)


def membership(
    personas: pd.DataFrame,
    responses: pd.DataFrame,
    profiles_a: pd.DataFrame,
    matched: Sequence[str],
    populations: Sequence[str | PopulationSpec] = POPULATIONS + SPLIT_HALVES,
    seed: int = 0,
    required: Collection[str] | None = None,
) -> pd.DataFrame:
    """Rows (population, member, persona_id, variant), members sorted by id.

    Only baseline records with a valid response belong to cohorts; the matched
    pair uses the ``matched`` ids present in both variants. Null populations are
    drawn from the same records by their kind (:class:`.identity.NullKind`
    ``members``: swap arms of the matched pair, size-matched subsets of mixed, …).
    A population that comes out empty is an error
    when it is ``required`` (default: all of them) and left out otherwise: a cohort
    a study does not run must not block it.
    """
    specs = [p if isinstance(p, PopulationSpec) else known(p) for p in populations]
    base = (
        personas.merge(
            responses[responses["variant"] == "baseline"][["persona_id", "q_trust"]],
            on="persona_id",
        )
        .merge(
            profiles_a[profiles_a["variant"] == "baseline"][["persona_id", "caution"]],
            on="persona_id",
        )
        .sort_values("persona_id", kind="stable")
        .reset_index(drop=True)
    )
    have_deadline = set(responses.loc[responses["variant"] == "deadline", "persona_id"])
    pair = sorted(set(matched) & have_deadline & set(base["persona_id"]))

    @cache
    def members(spec: PopulationSpec) -> Members:
        name = spec.name
        if spec.is_null:
            return null_kind(spec).members(spec, Records(members, seed))
        if name == "homogeneous":
            return [(HOMOGENEOUS_ID, "baseline")]
        if name in MATCHED_PAIR:
            return [(pid, "baseline" if name == MATCHED_PAIR[0] else "deadline") for pid in pair]
        if spec.role == "half":
            return [(pid, "baseline") for pid in split_half(base, spec, seed)]
        ids = base.loc[_SELECTORS[name](base).to_numpy(), "persona_id"]
        return [(str(pid), "baseline") for pid in ids]

    rows = [(spec.name, pid, variant) for spec in specs for pid, variant in members(spec)]
    df = pd.DataFrame(rows, columns=["population", "persona_id", "variant"])
    df["member"] = df.groupby("population", sort=False).cumcount().astype("int64")
    index = index_of(specs)
    check_members(df["population"], list(index) if required is None else required, index)
    return df[["population", "member", "persona_id", "variant"]]


def check_members(built: Collection[str], required: Collection[str],
                  specs: Mapping[str, PopulationSpec]) -> None:
    """InputError naming the first ``required`` population without members in ``built``
    and what it would hold (``specs``: the study's index)."""
    have = set(built)
    empty = [p for p in required if p not in have]
    if empty:
        more = f" (and {len(empty) - 1} more)" if len(empty) > 1 else ""
        raise InputError(
            f"population {empty[0]} has no members{more}: it holds "
            f"{definition(spec_of(specs, empty[0]))}",
            hint="more personas (personas.n, matched_n) or another persona source; or "
                 "drop it from the study's populations")


def population_order(names) -> list[str]:
    """The built-in populations in SPEC order, then any other name sorted: the one fixed
    order every table and figure shows populations in."""
    given = set(names)
    return [p for p in POPULATIONS if p in given] + sorted(given - set(POPULATIONS))


def is_known(name: str) -> bool:
    """Whether a study part may list ``name``: a built-in condition or a split half."""
    return name in KNOWN


def known(name: str) -> PopulationSpec:
    """The identity of the listed population ``name``; UnknownNameError if it is none."""
    if name not in KNOWN:
        raise UnknownNameError("population", name, tuple(KNOWN))
    return KNOWN[name]


def split_half(base: pd.DataFrame, spec: PopulationSpec, seed: int) -> list[str]:
    """The sorted ids of one random half (seeded) of the population ``spec`` splits."""
    parent, half = str(spec.base), spec.arm
    ids = base.loc[_SELECTORS[parent](base).to_numpy(), "persona_id"].astype(str).to_numpy()
    rng = np.random.default_rng(stable_seed("split_half", seed, parent))
    order = rng.permutation(len(ids))
    chosen = order[: len(ids) // 2] if half == "a" else order[len(ids) // 2 :]
    return sorted(ids[chosen].tolist())


def attach_profiles(members: pd.DataFrame, profiles: pd.DataFrame) -> pd.DataFrame:
    """The ``populations`` table: membership joined with one mapping's profiles.

    The homogeneous member gets the per-parameter median of the baseline profiles.
    """
    mapping = str(profiles["mapping"].iloc[0])
    base = profiles[profiles["variant"] == "baseline"]
    median = {p: float(np.median(base[p].to_numpy())) for p in PARAMS}
    median_row = pd.DataFrame([{"persona_id": HOMOGENEOUS_ID, "variant": "baseline", **median}])
    table = pd.concat([profiles[["persona_id", "variant", *PARAMS]], median_row], ignore_index=True)
    out = members.merge(table, on=["persona_id", "variant"], how="left", validate="many_to_one")
    if out[list(PARAMS)].isna().any().any():
        bad = out.loc[out[list(PARAMS)].isna().any(axis=1), ["population", "persona_id"]].head(3)
        raise InputError(f"members without a profile: {bad.to_dict('records')}")
    out.insert(4, "mapping", mapping)
    return check_table(out.reset_index(drop=True), "populations")


def population_sizes(populations: pd.DataFrame) -> dict[str, int]:
    """Members per population, in the canonical order."""
    counts = populations.groupby("population")["member"].count()
    return {p: int(counts[p]) for p in POPULATIONS + SPLIT_HALVES if p in counts.index}
