"""Mappings A–D from normalised responses to the seven motion controls (SPEC §4).

Notation (all in [0, 1]): q_c clearance, q_w waiting, q_y yielding, q_g small-gap
acceptance, q_d detouring, q_t robot trust, q_u urgency, q_a the mean of fixed
ordered action scores (:data:`ACTION_SCORE`). Every mapping produces normalised
controls z (clipped to [0, 1]) and physical values θ = ℓ + z (h − ℓ) with the
ranges of :data:`popnavshift.tables.PARAM_RANGES`; mobility speed caps are
applied afterwards (:func:`apply_mobility_caps`) and z_v is recomputed so that
θ = ℓ + z (h − ℓ) always holds in the table.

Mapping A (main): the paper's caution score
    C = 0.34 q_c + 0.22 (1 − q_g) + 0.22 q_y + 0.22 q_a
and
    z_v   = 0.32 + 0.60 q_u + 0.15 (1 − C)      urgency → speed (caution slows a little)
    z_d   = q_c                                 clearance direct
    z_a   = 0.60 C + 0.40 (1 − q_t)             avoidance = caution + distrust
    z_y   = 0.75 q_y + 0.25 (1 − q_u)           yielding, urgency lowers it (less)
    z_tau = 0.50 q_u + 0.50 q_t                 urgent/trusting people react later
    z_L   = 0.60 q_d + 0.40 C                   detour response + caution
    z_g   = q_g                                 gap acceptance direct
Mapping B (ordered action construction, reweighted): q_a is replaced by the share
of accommodating actions (slow, stop, yield, detour) and C_B = 0.30 q_c +
0.20 (1 − q_g) + 0.20 q_y + 0.30 q_a; other roles as A with C_B.
Mapping C (equal weights): C_C = mean(q_c, 1 − q_g, q_y, q_a) and every
combination weights its inputs equally (intercepts as in A where A has one).
Mapping D (direct): one response per control, no mixtures: z_v = q_u, z_d = q_c,
z_a = 1 − q_t, z_y = q_y, z_tau = q_t, z_L = q_d, z_g = q_g; its caution column
is A's C (D has none of its own).

The symbols are the paper's; the columns are ``tables.PARAMS`` (v = ``speed_mps``, …)
and ``tables.Z_COLUMNS`` (z_v = ``z_speed``, …), see docs/method.md §4.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pandas as pd

from ..errors import InputError
from ..registry import Registry
from ..tables import (
    ACTION_COLUMNS,
    ACTIONS,
    BLOCK_ITEMS,
    PARAM_RANGES,
    PARAMS,
    Z_COLUMNS,
    check_table,
)

#: Ordered caution score of each action (pass is the least, stop the most accommodating).
ACTION_SCORE: dict[str, float] = {
    "pass": 0.0,
    "continue": 0.2,
    "detour": 0.5,
    "slow": 0.6,
    "yield": 0.8,
    "stop": 1.0,
}
ACCOMMODATING = ("slow", "stop", "yield", "detour")
assert set(ACTION_SCORE) == set(ACTIONS)

#: Ordered speed caps [m/s] after mapping (mild > moderate > aid); Motor needs → moderate cap.
MOBILITY_SPEED_CAPS: dict[str, float] = {
    "Mild limitation": 1.20,
    "Moderate limitation": 1.00,
    "Uses mobility aid": 0.80,
}
MOTOR_NEEDS_CAP = 1.00

Q = dict[str, np.ndarray]
MappingResult = tuple[dict[str, np.ndarray], np.ndarray]  # (z per control, caution score)
#: name → function(q) -> (z, C); ``MAPPINGS.make(name)`` returns the function itself.
MAPPINGS: Registry[Callable[[Q], MappingResult]] = Registry("mapping", construct=False)

def _q(responses: pd.DataFrame) -> Q:
    q = {k: responses[f"q_{k}"].to_numpy(float) for k in BLOCK_ITEMS}
    acts = responses[list(ACTION_COLUMNS)].to_numpy(str)
    q["a"] = np.vectorize(ACTION_SCORE.__getitem__, otypes=[float])(acts).mean(axis=1)
    q["a_share"] = np.isin(acts, ACCOMMODATING).mean(axis=1)
    return q


def caution_a(q: Q) -> np.ndarray:
    """The paper's Mapping A caution score C in [0, 1]."""
    return 0.34 * q["clearance"] + 0.22 * (1 - q["gap"]) + 0.22 * q["yielding"] + 0.22 * q["a"]


def _roles(q: Q, c: np.ndarray, equal: bool = False) -> dict[str, np.ndarray]:
    u, t = q["urgency"], q["trust"]
    if equal:
        return {
            "speed_mps": 0.32 + 0.5 * (0.6 * u + 0.6 * (1 - c)),
            "clearance_m": q["clearance"],
            "avoidance_gain": 0.5 * c + 0.5 * (1 - t),
            "yield_fraction": 0.5 * q["yielding"] + 0.5 * (1 - u),
            "reaction_delay_s": 0.5 * u + 0.5 * t,
            "detour_distance_m": 0.5 * q["detour"] + 0.5 * c,
            "gap_acceptance": q["gap"],
        }
    return {
        "speed_mps": 0.32 + 0.60 * u + 0.15 * (1 - c),
        "clearance_m": q["clearance"],
        "avoidance_gain": 0.60 * c + 0.40 * (1 - t),
        "yield_fraction": 0.75 * q["yielding"] + 0.25 * (1 - u),
        "reaction_delay_s": 0.50 * u + 0.50 * t,
        "detour_distance_m": 0.60 * q["detour"] + 0.40 * c,
        "gap_acceptance": q["gap"],
    }


@MAPPINGS.register("A")
def mapping_a(q: Q) -> tuple[dict[str, np.ndarray], np.ndarray]:
    c = caution_a(q)
    return _roles(q, c), c


@MAPPINGS.register("B")
def mapping_b(q: Q) -> tuple[dict[str, np.ndarray], np.ndarray]:
    c = 0.30 * q["clearance"] + 0.20 * (1 - q["gap"]) + 0.20 * q["yielding"] + 0.30 * q["a_share"]
    return _roles(q, c), c


@MAPPINGS.register("C")
def mapping_c(q: Q) -> tuple[dict[str, np.ndarray], np.ndarray]:
    c = (q["clearance"] + (1 - q["gap"]) + q["yielding"] + q["a"]) / 4
    return _roles(q, c, equal=True), c


@MAPPINGS.register("D")
def mapping_d(q: Q) -> tuple[dict[str, np.ndarray], np.ndarray]:
    z = {
        "speed_mps": q["urgency"],
        "clearance_m": q["clearance"],
        "avoidance_gain": 1 - q["trust"],
        "yield_fraction": q["yielding"],
        "reaction_delay_s": q["trust"],
        "detour_distance_m": q["detour"],
        "gap_acceptance": q["gap"],
    }
    return z, caution_a(q)


def speed_cap(health_mobility: object, accessibility_needs: object) -> float:
    """The speed cap [m/s] of one persona (inf when none applies)."""
    cap = MOBILITY_SPEED_CAPS.get(str(health_mobility), np.inf)
    if accessibility_needs == "Motor":
        cap = min(cap, MOTOR_NEEDS_CAP)
    return float(cap)


def apply_mobility_caps(v: np.ndarray, caps: np.ndarray) -> np.ndarray:
    """Preferred speed after the ordered mobility caps (never below the range's low end)."""
    lo = PARAM_RANGES["speed_mps"][0]
    return np.maximum(np.minimum(v, caps), lo)


def build_profiles(
    responses: pd.DataFrame, personas: pd.DataFrame, mapping: str = "A"
) -> pd.DataFrame:
    """Motion profiles (``profiles`` table) for every response row under ``mapping``.

    ``personas`` supplies the mobility fields for the speed caps (matched by
    persona_id; variants share the persona's mobility).
    """
    fn = MAPPINGS.make(mapping)
    check_table(responses, "responses")
    mob = personas.set_index("persona_id")[["health_mobility", "accessibility_needs"]]
    missing = sorted(set(responses["persona_id"]) - set(mob.index))
    if missing:
        raise InputError(f"responses name persona ids not in the persona table: {missing[:5]}")
    z, c = fn(_q(responses))
    out = {
        "persona_id": responses["persona_id"].astype(str).to_numpy(),
        "variant": responses["variant"].astype(str).to_numpy(),
        "mapping": mapping,
    }
    m = mob.loc[responses["persona_id"]]
    caps = np.array(
        [
            speed_cap(h, a)
            for h, a in zip(m["health_mobility"], m["accessibility_needs"], strict=True)
        ]
    )
    for p in PARAMS:
        lo, hi = PARAM_RANGES[p]
        zp = np.clip(z[p], 0.0, 1.0)
        theta = np.clip(lo + zp * (hi - lo), lo, hi)  # exact bounds despite rounding
        if p == "speed_mps":
            theta = apply_mobility_caps(theta, caps)
            zp = (theta - lo) / (hi - lo)
        out[p] = theta
        out[Z_COLUMNS[p]] = zp
    out["caution"] = np.clip(c, 0.0, 1.0)
    df = pd.DataFrame(out)
    return check_table(df, "profiles")
