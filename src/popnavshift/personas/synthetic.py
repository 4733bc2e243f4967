"""Seeded synthetic persona records (the embedded default source, SPEC §2a).

Each persona has four latent traits, standard normal with correlation matrix R:

==========  ===================================================  ===========================
latent      meaning (higher =)                                   correlations
==========  ===================================================  ===========================
caution     more careful, safety-minded                          urgency −0.20, tech −0.15
urgency     more hurried                                         caution −0.20
tech        more at ease with technology and automation          caution −0.15, mobility −0.20
mobility    more physically limited                              tech −0.20
==========  ===================================================  ===========================

Every field except ``accessibility_needs`` is an *ordered threshold* model: a score
``s = w · latents + σ ε`` with ε ~ N(0, 1) of its own and σ = sqrt(1 − wᵀRw), so that
s ~ N(0, 1) exactly; s is cut at the standard-normal quantiles of the target marginal.
The expected marginals are therefore the listed probabilities whatever the loadings;
the loadings only set how fields co-vary. Levels run from low to high score.

===================  ===========================  ==============================================
field                loadings w (c, u, t, m)      levels (low → high score) : probabilities
===================  ===========================  ==============================================
time_pressure        −0.15, +0.75,  0,     0      No rush .42, Moderate .50, Deadline .06,
                                                  Emergency .02
risk_tolerance       −0.75, +0.15,  0,     0      Risk-averse .12, Cautious .26, Balanced .34,
                                                  Risk-tolerant .20, Risk-seeking .08
decision_style       +0.55, −0.35,  0,     0      Directive .14, Intuitive .22,
                                                  Consensus-driven .20, Analytical .28,
                                                  Deliberative .16
trust_level          +0.25,  0,    −0.55,  0      Trusting .24, Verifying .42, Skeptical .27,
                                                  Hostile .07
tech_savviness        0,     0,    −0.80, +0.15   Digital native .18, Comfortable .36,
                                                  Cautious adopter .26, Reluctant .13, Avoidant .07
att_automation       +0.20,  0,    −0.65,  0      Enthusiast .10, Positive .28, Neutral .36,
                                                  Skeptical .18, Opposed .08
cog_patience         −0.25, +0.60,  0,     0      Very high .10, High .27, Moderate .40, Low .19,
                                                  None .04
health_mobility       0,     0,     0,    +0.85   Full .80, Mild limitation .145,
                                                  Moderate limitation .035, Uses mobility aid .02
big5_cautiousness    −0.80, +0.10,  0,     0      Very high .08, High .24, Average .36, Low .24,
                                                  Very low .08
dospert_health_...   +0.70, −0.10,  0,     0      Very high .05, High .18, Average .37, Low .28,
                                                  Very low .12
cog_decision_speed   +0.45, −0.45,  0,     0      Snap decisions .07, Quick .25, Balanced .38,
                                                  Deliberate .22, Agonizes .08
===================  ===========================  ==============================================

``accessibility_needs`` is nominal: it is ``Motor`` when a motor score
(w = 0, 0, 0, +0.75) lies in its top 3 %; otherwise an independent standard normal is
cut into None .85, Visual .03, Hearing .03, Cognitive / neurodivergent .03,
Language barrier .03 (renormalised over the non-Motor 97 %). Expected shares:
Deadline/Emergency 8 %; mobility support (health_mobility ∈ {Moderate limitation,
Uses mobility aid} or Motor) about 7 % (5.5 % + 3 % with overlap, the two scores
correlating at 0.64).

All randomness is one ``rng.standard_normal((n, k))`` draw with
``rng = np.random.default_rng(seed)``; row i holds persona i's draws, so the first
m personas of ``n`` records equal those of ``m`` records (prefix stability).
"""

from __future__ import annotations

from dataclasses import dataclass
from statistics import NormalDist

import numpy as np
import pandas as pd

from ..errors import ConfigError
from .table import PERSONAS

LATENTS: tuple[str, ...] = ("caution", "urgency", "tech", "mobility")
LATENT_CORRELATION = np.array(
    [
        [1.00, -0.20, -0.15, 0.00],
        [-0.20, 1.00, 0.00, 0.00],
        [-0.15, 0.00, 1.00, -0.20],
        [0.00, 0.00, -0.20, 1.00],
    ]
)


@dataclass(frozen=True)
class OrderedField:
    """A field drawn by cutting a unit-variance latent score at marginal quantiles."""

    loadings: tuple[float, float, float, float]  # on (caution, urgency, tech, mobility)
    levels: tuple[str, ...]  # low → high score
    probs: tuple[float, ...]


ORDERED_FIELDS: dict[str, OrderedField] = {
    "time_pressure": OrderedField(
        (-0.15, 0.75, 0, 0),
        ("No rush", "Moderate", "Deadline", "Emergency"),
        (0.42, 0.50, 0.06, 0.02),
    ),
    "risk_tolerance": OrderedField(
        (-0.75, 0.15, 0, 0),
        ("Risk-averse", "Cautious", "Balanced", "Risk-tolerant", "Risk-seeking"),
        (0.12, 0.26, 0.34, 0.20, 0.08),
    ),
    "decision_style": OrderedField(
        (0.55, -0.35, 0, 0),
        ("Directive", "Intuitive", "Consensus-driven", "Analytical", "Deliberative"),
        (0.14, 0.22, 0.20, 0.28, 0.16),
    ),
    "trust_level": OrderedField(
        (0.25, 0, -0.55, 0),
        ("Trusting", "Verifying", "Skeptical", "Hostile"),
        (0.24, 0.42, 0.27, 0.07),
    ),
    "tech_savviness": OrderedField(
        (0, 0, -0.80, 0.15),
        ("Digital native", "Comfortable", "Cautious adopter", "Reluctant", "Avoidant"),
        (0.18, 0.36, 0.26, 0.13, 0.07),
    ),
    "att_automation": OrderedField(
        (0.20, 0, -0.65, 0),
        ("Enthusiast", "Positive", "Neutral", "Skeptical", "Opposed"),
        (0.10, 0.28, 0.36, 0.18, 0.08),
    ),
    "cog_patience": OrderedField(
        (-0.25, 0.60, 0, 0),
        ("Very high", "High", "Moderate", "Low", "None"),
        (0.10, 0.27, 0.40, 0.19, 0.04),
    ),
    "health_mobility": OrderedField(
        (0, 0, 0, 0.85),
        ("Full", "Mild limitation", "Moderate limitation", "Uses mobility aid"),
        (0.80, 0.145, 0.035, 0.02),
    ),
    "big5_cautiousness": OrderedField(
        (-0.80, 0.10, 0, 0),
        ("Very high", "High", "Average", "Low", "Very low"),
        (0.08, 0.24, 0.36, 0.24, 0.08),
    ),
    "dospert_health_safety_risk_tolerance": OrderedField(
        (0.70, -0.10, 0, 0),
        ("Very high", "High", "Average", "Low", "Very low"),
        (0.05, 0.18, 0.37, 0.28, 0.12),
    ),
    "cog_decision_speed": OrderedField(
        (0.45, -0.45, 0, 0),
        ("Snap decisions", "Quick", "Balanced", "Deliberate", "Agonizes"),
        (0.07, 0.25, 0.38, 0.22, 0.08),
    ),
}

MOTOR_LOADINGS = (0.0, 0.0, 0.0, 0.75)
MOTOR_SHARE = 0.03
OTHER_ACCESSIBILITY: tuple[tuple[str, float], ...] = (
    ("None", 0.85),
    ("Visual", 0.03),
    ("Hearing", 0.03),
    ("Cognitive / neurodivergent", 0.03),
    ("Language barrier", 0.03),
)
ID_PREFIX = "syn-"
SOURCE = "synthetic"


def generate_personas(n: int = 600, seed: int = 0) -> pd.DataFrame:
    """``n`` synthetic persona records, a ``personas`` table sorted by ``persona_id``.

    Ids are ``syn-000000`` … (zero-padded to at least six digits, so string order
    is numeric order); ``source`` is ``"synthetic"``; optional fields are filled.
    """
    if isinstance(n, bool) or not isinstance(n, int | np.integer) or n < 1:
        raise ConfigError(f"n must be a positive integer, got {n!r}")
    rng = np.random.default_rng(seed)
    n_scores = len(ORDERED_FIELDS) + 2  # + motor score + non-Motor accessibility draw
    draws = rng.standard_normal((n, len(LATENTS) + n_scores))
    latents = draws[:, : len(LATENTS)] @ np.linalg.cholesky(LATENT_CORRELATION).T
    noise = draws[:, len(LATENTS) :]

    width = max(6, len(str(n - 1)))
    columns: dict[str, np.ndarray] = {
        "persona_id": np.array([f"{ID_PREFIX}{i:0{width}d}" for i in range(n)], dtype=object),
        "source": np.full(n, SOURCE, dtype=object),
    }
    for j, (field, spec) in enumerate(ORDERED_FIELDS.items()):
        score = _unit_score(latents, spec.loadings, noise[:, j])
        columns[field] = _cut(score, spec.levels, spec.probs)
    columns["accessibility_needs"] = _accessibility(latents, noise[:, -2], noise[:, -1])
    return pd.DataFrame({name: columns[name] for name in PERSONAS.names})


def _unit_score(latents: np.ndarray, loadings, eps: np.ndarray) -> np.ndarray:
    """w · latents + σ ε with σ chosen so the score has unit variance; shape (n,)."""
    w = np.asarray(loadings, dtype=float)
    explained = float(w @ LATENT_CORRELATION @ w)
    return latents @ w + np.sqrt(1.0 - explained) * eps


def _cut(score: np.ndarray, levels: tuple[str, ...], probs: tuple[float, ...]) -> np.ndarray:
    """Map standard-normal ``score`` to ``levels`` so level k has probability ``probs[k]``."""
    cumulative = np.cumsum(probs)[:-1]
    cuts = np.array([NormalDist().inv_cdf(float(p)) for p in cumulative])
    return np.asarray(levels, dtype=object)[np.searchsorted(cuts, score)]


def _accessibility(latents: np.ndarray, motor_eps: np.ndarray, other: np.ndarray) -> np.ndarray:
    motor = _unit_score(latents, MOTOR_LOADINGS, motor_eps) > NormalDist().inv_cdf(
        1.0 - MOTOR_SHARE
    )
    levels, probs = zip(*OTHER_ACCESSIBILITY, strict=True)
    values = _cut(other, levels, tuple(np.asarray(probs) / sum(probs)))
    values[motor] = "Motor"
    return values
