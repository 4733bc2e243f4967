"""Every stage table's columns, dtypes and keys, declared once.

``check_table(df, stage)`` validates a table against its declaration and raises
:class:`InputError` naming the stage, the column and what was expected. Stages
and tests call it on what they produce and what they read.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from .errors import InputError

PARAMS: tuple[str, ...] = ("v", "d", "a", "y", "tau", "L", "g")
"""The seven motion parameters θ = (v, d, a, y, τ, L, g), in this order."""

PARAM_RANGES: dict[str, tuple[float, float]] = {
    "v": (0.60, 1.80),  # preferred speed [m/s]
    "d": (0.30, 1.20),  # robot clearance [m]
    "a": (0.60, 2.20),  # avoidance strength [-]
    "y": (0.0, 1.0),  # yielding propensity [-]
    "tau": (0.15, 1.20),  # reaction delay [s]
    "L": (1.0, 4.0),  # detour threshold [m]
    "g": (0.0, 1.0),  # gap acceptance [-]
}

#: Ordered five-level response block (SPEC §3), encoded 0, .25, .5, .75, 1.
BLOCK_ITEMS: tuple[str, ...] = (
    "clearance",
    "waiting",
    "yielding",
    "gap",
    "detour",
    "trust",
    "urgency",
)
#: response-table columns: one action per probe, one level value per block item
ACTION_COLUMNS: tuple[str, ...] = tuple(f"action_{i}" for i in range(1, 9))
Q_COLUMNS: tuple[str, ...] = tuple(f"q_{k}" for k in BLOCK_ITEMS)
ACTIONS: tuple[str, ...] = ("continue", "slow", "stop", "yield", "pass", "detour")
VARIANTS: tuple[str, ...] = ("baseline", "deadline")


@dataclass(frozen=True)
class Column:
    name: str
    kind: str  # "str", "float", "int", "bool"
    nullable: bool = False


@dataclass(frozen=True)
class TableSpec:
    stage: str
    columns: tuple[Column, ...]
    key: tuple[str, ...]

    @property
    def names(self) -> list[str]:
        return [c.name for c in self.columns]


def _cols(kind: str, names, nullable: bool = False) -> tuple[Column, ...]:
    return tuple(Column(n, kind, nullable) for n in names)


SPECS: dict[str, TableSpec] = {}


def declare(stage: str, columns: tuple[Column, ...], key: tuple[str, ...]) -> TableSpec:
    spec = TableSpec(stage, columns, key)
    SPECS[stage] = spec
    return spec


def _persona_columns() -> tuple[Column, ...]:
    from .personas.fields import OPTIONAL_FIELDS, REQUIRED_FIELDS

    return (
        Column("persona_id", "str"),
        Column("source", "str"),
        *_cols("str", REQUIRED_FIELDS),
        *_cols("str", OPTIONAL_FIELDS, nullable=True),
    )


PERSONAS = declare("personas", _persona_columns(), ("persona_id",))

RESPONSES = declare(
    "responses",
    (
        Column("persona_id", "str"),
        Column("variant", "str"),
        Column("respondent", "str"),
        Column("model", "str"),  # the model asked for
        Column("served_model", "str", nullable=True),  # the model that answered, as served
        Column("probe_set", "str"),
        *_cols("str", ACTION_COLUMNS),
        *_cols("float", Q_COLUMNS),
    ),
    ("persona_id", "variant"),
)

PROFILES = declare(
    "profiles",
    (
        Column("persona_id", "str"),
        Column("variant", "str"),
        Column("mapping", "str"),
        *_cols("float", PARAMS),
        *_cols("float", [f"z_{p}" for p in PARAMS]),
        Column("caution", "float"),
    ),
    ("persona_id", "variant", "mapping"),
)

POPULATIONS = declare(
    "populations",
    (
        Column("population", "str"),
        Column("member", "int"),
        Column("persona_id", "str"),
        Column("variant", "str"),
        Column("mapping", "str"),
        *_cols("float", PARAMS),
    ),
    ("population", "mapping", "member"),
)

RUN_KEY: tuple[str, ...] = ("episode", "population", "controller", "backend", "mapping")
NO_ROBOT = "none"
"""The ``controller`` value of a no-robot baseline run."""
"""A run's identity: ``controller == "none"`` is the no-robot baseline."""

RUNS = declare(
    "runs",
    (
        Column("part", "str"),
        *_cols("str", RUN_KEY),
        Column("scene", "str"),
        *_cols("float", ("width", "density", "robot_speed")),
        *_cols("int", ("variant", "n_peds")),
        # success | pedestrian_collision | world_collision | timeout | controller_error | none
        Column("outcome", "str"),
        *_cols(
            "float",
            (
                "robot_time",
                "outcome_time",
                "robot_path_length",
                "robot_stop_time",
                "robot_min_clearance",
            ),
            nullable=True,  # NaN for no-robot runs
        ),
        *_cols("int", ("ped_collisions", "world_collisions", "peds_arrived", "steps")),
        Column("error", "str", nullable=True),  # what the controller raised (controller_error)
    ),
    RUN_KEY,
)

PEDESTRIANS = declare(
    "pedestrians",
    (
        Column("part", "str"),
        *_cols("str", RUN_KEY),
        Column("slot", "int"),
        Column("persona_id", "str"),
        Column("arrived", "bool"),
        # NaN when the pedestrian never arrived (travel time, detour) or without a robot
        *_cols("float", ("travel_time", "detour", "min_robot_clearance"), nullable=True),
        *_cols("float", ("walk_distance", "stop_time")),
        *_cols("float", PARAMS),
    ),
    (*RUN_KEY, "slot"),
)


_KIND_CHECK = {
    "str": lambda s: pd.api.types.is_string_dtype(s) or pd.api.types.is_object_dtype(s),
    "float": pd.api.types.is_float_dtype,
    "int": pd.api.types.is_integer_dtype,
    "bool": pd.api.types.is_bool_dtype,
}


def check_table(df: pd.DataFrame, stage: str) -> pd.DataFrame:
    """Validate ``df`` against the declaration of ``stage``; return it unchanged.

    Checks presence and dtype of every column, nulls in non-nullable columns,
    finiteness of float columns and uniqueness of the key.
    """
    spec = SPECS[stage]
    missing = [c for c in spec.names if c not in df.columns]
    if missing:
        raise InputError(f"{stage} table: missing column(s) {', '.join(missing)}")
    for col in spec.columns:
        s = df[col.name]
        if len(s) and not s.isna().all() and not _KIND_CHECK[col.kind](s):
            raise InputError(
                f"{stage} table: column {col.name!r} should be {col.kind}, got {s.dtype}"
            )
        if not col.nullable and s.isna().any():
            row = int(np.flatnonzero(s.isna().to_numpy())[0])
            raise InputError(f"{stage} table: column {col.name!r} has a missing value at row {row}")
        if col.kind == "float" and len(s) and not np.isfinite(s.dropna().to_numpy(float)).all():
            raise InputError(f"{stage} table: column {col.name!r} has a non-finite value")
    dup = df.duplicated(list(spec.key))
    if dup.any():
        row = int(np.flatnonzero(dup.to_numpy())[0])
        keys = {k: df[k].iloc[row] for k in spec.key}
        raise InputError(f"{stage} table: duplicate key {keys} at row {row}")
    return df
