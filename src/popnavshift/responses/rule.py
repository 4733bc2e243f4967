"""The ``rule`` respondent: an offline, deterministic, persona-sensitive surrogate.

It is a transparent stand-in for an LLM, **not** an LLM and not a model of real
people: a handful of documented formulas turn persona fields into latent traits
and the traits into probe answers, with small deterministic noise keyed by
``(persona id, probe/item, seed)``. Because the noise does not depend on the
variant, the matched deadline intervention moves answers only through the
``time_pressure`` field, in known directions: urgency up, waiting and yielding
down, small-gap acceptance up.

Traits in [0, 1] (from ordered field vocabularies, first value → last value):

* caution  = mean(risk aversion, big-5 cautiousness, 1 − DOSPERT safety risk tolerance,
  decision-style caution)
* urgency  = 0.75 · time pressure + 0.25 · decision speed
* patience = cog_patience (Very high = 1 … None = 0)
* trust    = mean(trust level, tech savviness, attitude to automation)
* mobility = limitation (Full = 0 … Uses mobility aid = 1; Motor needs ≥ 2/3)

Block items (before noise, then rounded to the nearest of five levels) are fixed
linear combinations listed in :data:`BLOCK_WEIGHTS`; actions are the argmax of
per-action utilities (:data:`ACTION_WEIGHTS` · traits + the probe's prior +
noise). All coefficients are in docs/method.md.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from ..hashing import unit_hash
from ..personas.fields import vocabulary
from ..tables import ACTIONS, BLOCK_ITEMS
from .probes import PROBE_IDS
from .respondent import Answer, ProbeRequest, Progress, Respondent
from .schema import LEVELS

TRAITS = ("caution", "urgency", "patience", "trust", "mobility")

TIME_PRESSURE_LEVEL = {"No rush": 0.0, "Moderate": 0.35, "Deadline": 0.8, "Emergency": 1.0}
DECISION_STYLE_CAUTION = {
    "Analytical": 0.7,
    "Deliberative": 0.75,
    "Consensus-driven": 0.55,
    "Intuitive": 0.35,
    "Directive": 0.3,
}

#: item → (intercept, {trait: weight}); value clipped to [0, 1] before noise.
BLOCK_WEIGHTS: dict[str, tuple[float, dict[str, float]]] = {
    "clearance": (0.05, {"caution": 0.55, "trust": -0.25, "mobility": 0.25, "urgency": -0.1}),
    "waiting": (0.15, {"patience": 0.4, "caution": 0.3, "urgency": -0.45, "mobility": 0.1}),
    "yielding": (0.2, {"caution": 0.4, "patience": 0.25, "urgency": -0.45, "trust": 0.05}),
    "gap": (0.35, {"caution": -0.55, "urgency": 0.45, "trust": 0.2, "mobility": -0.25}),
    "detour": (0.3, {"caution": 0.35, "mobility": -0.3, "urgency": -0.15, "patience": 0.1}),
    "trust": (0.0, {"trust": 1.0}),
    "urgency": (0.05, {"urgency": 0.85, "patience": -0.15}),
}
#: action → {trait: weight}; shared by all probes.
ACTION_WEIGHTS: dict[str, dict[str, float]] = {
    "continue": {"urgency": 0.6, "trust": 0.5, "caution": -0.6},
    "slow": {"caution": 0.4, "patience": 0.3, "urgency": -0.3},
    "stop": {"caution": 0.6, "trust": -0.5, "mobility": 0.4, "urgency": -0.5},
    "yield": {"patience": 0.5, "caution": 0.3, "urgency": -0.6},
    "pass": {"urgency": 0.8, "caution": -0.7, "trust": 0.3, "mobility": -0.6},
    "detour": {"caution": 0.3, "trust": -0.3, "mobility": -0.4},
}
#: probe → prior utility per action, in ACTIONS order (continue, slow, stop, yield, pass, detour).
PROBE_PRIORS: dict[str, tuple[float, ...]] = {
    "P1": (-0.2, 0.2, 0.0, 0.3, -0.3, -0.1),  # narrow, head-on, robot keeps course
    "P2": (0.3, 0.0, -0.4, -0.2, 0.1, 0.2),  # wide, head-on
    "P3": (0.0, 0.2, 0.1, 0.2, 0.0, -0.3),  # crossing at a junction
    "P4": (0.1, 0.1, -0.3, -0.1, 0.3, -0.2),  # overtaking a slow robot, narrow
    "P5": (0.0, 0.3, 0.0, 0.1, -0.2, 0.1),  # crowded sidewalk
    "P6": (-0.2, 0.1, 0.1, 0.3, -0.1, 0.0),  # obstruction, shared gap
    "P7": (0.4, 0.0, -0.4, -0.3, 0.3, -0.2),  # robot yields in a bottleneck
    "P8": (0.1, 0.1, 0.0, -0.2, 0.2, 0.1),  # robot stopped, 1 m gap beside a wall
}
BLOCK_NOISE = 0.08  # sd-like half-width of the uniform item noise
ACTION_NOISE = 0.25  # scale of the Gumbel noise on action utilities


def _ordinal(field: str, value: Any, reverse: bool = False) -> float | None:
    """Position of ``value`` in the field's vocabulary mapped to [0, 1] (None if missing)."""
    if value is None or (isinstance(value, float) and value != value):
        return None
    vocab = vocabulary(field)
    x = vocab.index(value) / (len(vocab) - 1)
    return 1.0 - x if reverse else x


def traits(persona: Mapping[str, Any]) -> dict[str, float]:
    """Latent traits in [0, 1] from persona fields (see module docstring)."""
    caution_parts = [
        _ordinal("risk_tolerance", persona.get("risk_tolerance"), reverse=True),
        _ordinal("big5_cautiousness", persona.get("big5_cautiousness"), reverse=True),
        _ordinal(
            "dospert_health_safety_risk_tolerance",
            persona.get("dospert_health_safety_risk_tolerance"),
        ),  # Very high tolerance is first → 0 caution
        DECISION_STYLE_CAUTION.get(str(persona.get("decision_style"))),
    ]
    speed = _ordinal("cog_decision_speed", persona.get("cog_decision_speed"), reverse=True)
    trust_parts = [
        _ordinal("trust_level", persona.get("trust_level"), reverse=True),
        _ordinal("tech_savviness", persona.get("tech_savviness"), reverse=True),
        _ordinal("att_automation", persona.get("att_automation"), reverse=True),
    ]
    mobility = _ordinal("health_mobility", persona.get("health_mobility")) or 0.0
    if persona.get("accessibility_needs") == "Motor":
        mobility = max(mobility, 2 / 3)
    pressure = TIME_PRESSURE_LEVEL[str(persona["time_pressure"])]
    return {
        "caution": float(np.mean([p for p in caution_parts if p is not None])),
        "urgency": 0.75 * pressure + 0.25 * (0.5 if speed is None else speed),
        "patience": _ordinal("cog_patience", persona.get("cog_patience"), reverse=True) or 0.0,
        "trust": float(np.mean([p for p in trust_parts if p is not None])),
        "mobility": mobility,
    }


class RuleRespondent(Respondent):
    """Deterministic surrogate respondent; ``seed`` selects the noise draw.

    Independent samples (``samples: k``) are identical: the noise is keyed by the
    persona and ``seed``, not by the sample, so the audit's test–retest reads perfect
    agreement (what a deterministic respondent should show).

    ``scale`` multiplies every trait weight (a second, documented parameter set
    for respondent-robustness studies uses ``scale != 1`` and another seed).
    """

    name = "rule"

    def __init__(self, seed: int = 0, scale: float = 1.0) -> None:
        self.seed = seed
        self.scale = scale

    @property
    def model(self) -> str:
        return f"rule-v1(seed={self.seed},scale={self.scale:g})"

    def describe(self) -> dict[str, Any]:
        return {
            "respondent": self.name,
            "model": self.model,
            "seed": self.seed,
            "scale": self.scale,
        }

    def answer_one(self, persona_id: str, persona: Mapping[str, Any]) -> dict[str, Any]:
        t = traits(persona)
        block = {}
        for item, (intercept, weights) in BLOCK_WEIGHTS.items():
            x = intercept + self.scale * sum(w * t[k] for k, w in weights.items())
            x += BLOCK_NOISE * (2 * unit_hash("rule", self.seed, persona_id, item) - 1)
            block[item] = LEVELS[int(np.clip(np.rint(4 * np.clip(x, 0, 1)), 0, 4))]
        actions = {}
        for pid in PROBE_IDS:
            utilities = []
            for a, prior in zip(ACTIONS, PROBE_PRIORS[pid], strict=True):
                u = prior + self.scale * sum(w * t[k] for k, w in ACTION_WEIGHTS[a].items())
                h = min(max(unit_hash("rule", self.seed, persona_id, pid, a), 1e-12), 1 - 1e-12)
                utilities.append(u + ACTION_NOISE * -np.log(-np.log(h)))  # Gumbel noise
            actions[pid] = ACTIONS[int(np.argmax(utilities))]
        assert tuple(block) == BLOCK_ITEMS
        return {"actions": actions, "block": block}

    def answer_all(
        self, requests: Sequence[ProbeRequest], progress: Progress | None = None
    ) -> list[Answer]:
        out = []
        for req in requests:
            out.append(
                Answer(
                    req.persona_id, req.variant, answer=self.answer_one(req.persona_id, req.persona)
                )
            )
            if progress:
                progress(1)
        return out

