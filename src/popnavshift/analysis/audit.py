"""Respondent audit, the statistics: does a respondent's answer table follow the persona?

Pure functions over one respondent's tables (``responses``, ``personas``, ``profiles``),
each returning a table; :mod:`.audit_verdict` turns them into a verdict. The persona
population is the ``baseline`` variant (one row per persona); the matched intervention
pairs a persona's ``baseline`` and ``deadline`` rows.

* :func:`spread` — per answer column (8 probe actions, 7 block items): levels used,
  Shannon entropy (bits, and as a share of the column's maximum), modal answer and its
  share, and ``stuck`` (a block item using at most 2 of its 5 levels, a probe answered
  with one action throughout).
* :func:`sensitivity` — how much of each target the persona fields explain: the R² of a
  least-squares fit on every field of :data:`~popnavshift.personas.fields.PERSONA_FIELDS`
  (:func:`persona_design`: an ordered field by its position, a nominal one one-hot). A
  probe's action is its six indicator columns together (the share of its Gini variance
  explained); the action score is q_a, what the mappings read of the actions.
  The null permutes the persona rows (same statistic, the answers' own marginals kept);
  p = (1 + #null ≥ observed) / (1 + permutations).
* :func:`directions` — declared expected directions (:data:`EXPECTATIONS`): Spearman
  between a persona field's vocabulary position and an answer or motion parameter, with
  a percentile bootstrap interval over personas.
* :func:`manipulation` — the matched intervention (time pressure := Deadline): the mean
  paired deadline − baseline shift of each block item with a bootstrap interval, against
  the direction the intervention should move it (:data:`DEADLINE_SIGNS`), and the share
  of probe actions that changed.
* :func:`agreement` — two respondents on the same persona and variant: exact and
  within-one-level agreement, Spearman per item, Cohen's κ per probe, and Pearson r of
  each motion parameter.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd
from scipy.stats import rankdata

from ..personas.fields import PERSONA_FIELDS, vocabulary
from ..profiles.mappings import ACTION_SCORE
from ..tables import ACTION_COLUMNS, ACTIONS, PARAMS, Q_COLUMNS

ANSWER_COLUMNS: tuple[str, ...] = (*ACTION_COLUMNS, *Q_COLUMNS)
N_LEVELS = 5  # the block's five levels, 0, .25, .5, .75, 1
STUCK_LEVELS = 2  # a block item using at most this many levels is stuck
LEVEL = 0.25  # one level of the block, in answer units
ACTION_SCORE_TARGET = "action_score"  # q_a, the mean ordered score of the probe actions
ANSWER_TARGETS = len(ANSWER_COLUMNS) + 1  # the answers audited: every column, the action score


def baseline(responses: pd.DataFrame) -> pd.DataFrame:
    """The persona population: ``baseline`` rows, one per persona, sorted by id."""
    base = responses[responses["variant"] == "baseline"]
    return base.sort_values("persona_id", kind="stable").reset_index(drop=True)


def _entropy(counts: np.ndarray) -> float:
    p = counts[counts > 0] / counts.sum()
    return float(-(p * np.log2(p)).sum()) + 0.0 if len(p) else np.nan  # + 0.0: never -0.0


def rho_text(rho: float, low: float, high: float) -> str:
    """A Spearman ρ with its interval, or a dash when it is undefined (a constant column)."""
    if np.isnan(rho):
        return "– (constant)"
    return f"{rho:+.2f} [{low:+.2f}, {high:+.2f}]"


def spread(responses: pd.DataFrame) -> pd.DataFrame:
    """One row per answer column of the baseline rows: ``kind`` (action, item),
    ``levels`` possible, ``used``, ``entropy_bits``, ``entropy_share`` (of log2 levels),
    ``modal`` answer, ``modal_share`` and ``stuck`` (module docstring)."""
    base = baseline(responses)
    rows = []
    for col in ANSWER_COLUMNS:
        counts = base[col].astype(str).value_counts()
        item = col in Q_COLUMNS
        levels = N_LEVELS if item else len(ACTIONS)
        used = int((counts > 0).sum())
        h = _entropy(counts.to_numpy(float))
        rows.append({"column": col, "kind": "item" if item else "action", "levels": levels,
                     "used": used, "entropy_bits": h, "entropy_share": h / np.log2(levels),
                     "modal": str(counts.index[0]) if used else "",
                     "modal_share": float(counts.iloc[0] / counts.sum()) if used else np.nan,
                     "stuck": used <= (STUCK_LEVELS if item else 1)})
    return pd.DataFrame(rows)


def distinct_rows(responses: pd.DataFrame, personas: pd.DataFrame) -> dict[str, int]:
    """Distinct answer rows among the baseline answers, against the distinct persona
    records (field values, not ids) that were asked: a respondent that follows the
    persona gives about as many distinct rows as there are distinct records."""
    base = baseline(responses)
    asked = personas[personas["persona_id"].isin(base["persona_id"])]
    fields = [f for f in PERSONA_FIELDS if f in asked.columns]
    return {"personas": len(base),
            "answer_rows": len(base[list(ANSWER_COLUMNS)].astype(str).drop_duplicates()),
            "persona_records": len(asked[fields].astype(str).drop_duplicates())}


#: Persona fields whose vocabulary has no order (data/matraix_fields.json): one-hot coded.
NOMINAL_FIELDS: tuple[str, ...] = ("decision_style", "accessibility_needs")


def persona_design(personas: pd.DataFrame) -> np.ndarray:
    """The persona fields as regressors (n × k): an ordered field as its position in its
    vocabulary in [0, 1] (a missing value at the field's mean, with a missing indicator),
    a nominal field (:data:`NOMINAL_FIELDS`) one-hot. One column per ordered field keeps
    the design small enough to test 50 personas (one-hot everything: ~46 columns, whose
    null R² nears 1 at that size); the cost is that a non-monotone dependence on an
    ordered field is seen only through its linear trend."""
    cols = []
    for f in [f for f in PERSONA_FIELDS if f in personas.columns]:
        values = personas[f].astype(object)
        if f in NOMINAL_FIELDS:
            cols.append(pd.get_dummies(values.astype(str), drop_first=True, dtype=float)
                        .to_numpy(float))
            continue
        vocab = vocabulary(f)
        x = np.array([vocab.index(v) / (len(vocab) - 1) if v in vocab else np.nan
                      for v in values], float)
        missing = np.isnan(x)
        if missing.all():
            continue
        cols.append(np.where(missing, np.nanmean(x), x)[:, None])
        if missing.any():
            cols.append(missing[:, None].astype(float))
    return np.concatenate(cols, axis=1) if cols else np.zeros((len(personas), 0))


def persona_basis(personas: pd.DataFrame) -> np.ndarray:
    """An orthonormal basis (n × r) of the centred :func:`persona_design`, rows in the
    order of ``personas``; the fitted values of a centred target are its projection on it."""
    x = persona_design(personas)
    x = x - x.mean(axis=0)
    if x.shape[1] == 0:
        return np.zeros((len(personas), 0))
    u, s, _ = np.linalg.svd(x, full_matrices=False)
    tol = s.max(initial=0.0) * max(x.shape) * np.finfo(float).eps
    return u[:, s > tol]


@dataclass(frozen=True)
class Target:
    """One audited quantity: its name, kind (action, item, parameter) and its columns
    (n × k; a probe's action as k indicator columns)."""

    name: str
    kind: str
    values: np.ndarray


def answer_targets(base: pd.DataFrame) -> list[Target]:
    """The baseline answers as targets: each probe's action (indicators), each item, and
    the action score the mappings read (q_a: the mean ordered score of the 8 actions,
    :data:`~popnavshift.profiles.mappings.ACTION_SCORE`)."""
    out = []
    for col in ACTION_COLUMNS:
        acts = base[col].astype(str).to_numpy()
        out.append(Target(col, "action", np.stack([acts == a for a in ACTIONS], 1).astype(float)))
    out += [Target(col, "item", base[[col]].to_numpy(float)) for col in Q_COLUMNS]
    score = base[list(ACTION_COLUMNS)].astype(str).apply(lambda c: c.map(ACTION_SCORE))
    out.append(Target(ACTION_SCORE_TARGET, "action score", score.mean(axis=1).to_numpy()[:, None]))
    return out


def parameter_targets(profiles: pd.DataFrame) -> list[Target]:
    """The seven motion parameters of ``profiles`` (rows aligned with the personas)."""
    return [Target(p, "parameter", profiles[[p]].to_numpy(float)) for p in PARAMS]


def sensitivity(targets: list[Target], basis: np.ndarray, *, rng: np.random.Generator,
                n_perm: int = 999) -> pd.DataFrame:
    """R² of each target on the persona fields (``basis``: :func:`persona_basis`, rows
    aligned with the targets') against ``n_perm`` persona-row permutations.

    Returns one row per target: ``target``, ``kind``, ``n``, ``columns`` (the basis's
    rank), ``r2`` (NaN for a constant
    target), ``null_mean``, ``null_q95``, ``excess`` (r2 − null_mean) and ``p_value``.
    """
    y = np.concatenate([t.values for t in targets], axis=1)
    y = y - y.mean(axis=0)
    group = np.repeat(np.arange(len(targets)), [t.values.shape[1] for t in targets])
    total = np.bincount(group, (y**2).sum(axis=0), minlength=len(targets))

    def r2(rows: np.ndarray) -> np.ndarray:
        explained = ((basis[rows].T @ y) ** 2).sum(axis=0)
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.bincount(group, explained, minlength=len(targets)) / total

    n = len(y)
    observed = r2(np.arange(n))
    null = np.array([r2(rng.permutation(n)) for _ in range(n_perm)])
    constant = total <= 1e-12 * n
    observed[constant] = np.nan
    above = (null >= observed - 1e-12).sum(axis=0)
    return pd.DataFrame({
        "target": [t.name for t in targets], "kind": [t.kind for t in targets], "n": n,
        "columns": basis.shape[1],
        "r2": observed, "null_mean": null.mean(axis=0), "null_q95": np.quantile(null, 0.95, 0),
        "excess": observed - null.mean(axis=0),
        "p_value": np.where(constant, np.nan, (1 + above) / (1 + n_perm))})


@dataclass(frozen=True)
class Expectation:
    """A direction an attentive respondent's answers must take: Spearman between the
    position of ``field``'s value in its vocabulary (first value = 0) and ``target`` has
    the sign ``sign``."""

    field: str
    target: str
    sign: int
    why: str


#: Declared from the fields' meaning (vocabulary order in data/matraix_fields.json), not
#: fitted to any respondent: one check per block the mappings turn into motion (trust,
#: urgency, waiting, gap acceptance, clearance) and two motion parameters downstream.
EXPECTATIONS: tuple[Expectation, ...] = (
    Expectation("trust_level", "q_trust", -1, "Trusting → Hostile: less robot trust"),
    Expectation("att_automation", "q_trust", -1, "Enthusiast → Opposed: less robot trust"),
    Expectation("time_pressure", "q_urgency", 1, "No rush → Emergency: more urgency"),
    Expectation("cog_patience", "q_waiting", -1, "Very high → no patience: less waiting"),
    Expectation("risk_tolerance", "q_gap", 1, "Risk-averse → Risk-seeking: smaller gaps taken"),
    Expectation("risk_tolerance", "q_clearance", -1, "Risk-averse → Risk-seeking: less "
                "clearance wanted"),
    Expectation("time_pressure", "speed_mps", 1, "No rush → Emergency: faster walking"),
    Expectation("trust_level", "avoidance_gain", 1, "Trusting → Hostile: stronger avoidance"),
)


def _spearman(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Spearman ρ of each row pair of ``x`` and ``y`` (B × n); NaN where one is constant."""
    rx, ry = rankdata(x, axis=-1), rankdata(y, axis=-1)
    rx = rx - rx.mean(axis=-1, keepdims=True)
    ry = ry - ry.mean(axis=-1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        return (rx * ry).sum(-1) / np.sqrt((rx**2).sum(-1) * (ry**2).sum(-1))


def direction_outcome(sign: int, low: float, high: float) -> str:
    """``as expected`` when the interval excludes 0 on the expected side, ``reversed``
    when it excludes 0 on the other, ``flat`` when it holds 0, ``undefined`` (NaN)."""
    if not (np.isfinite(low) and np.isfinite(high)):
        return "undefined"
    if sign * low > 0 and sign * high > 0:
        return "as expected"
    return "reversed" if sign * low < 0 and sign * high < 0 else "flat"


def directions(personas: pd.DataFrame, values: pd.DataFrame, *, rng: np.random.Generator,
               n_boot: int = 1000, expectations: tuple[Expectation, ...] = EXPECTATIONS
               ) -> pd.DataFrame:
    """The expected-direction checks on ``values`` (answers and motion parameters, rows
    aligned with ``personas``): ``rho``, its 95% percentile bootstrap interval over
    personas, and the :func:`direction_outcome`. A check whose field or target is absent
    is left out."""
    rows = []
    for e in expectations:
        if e.field not in personas.columns or e.target not in values.columns:
            continue
        vocab = {v: i for i, v in enumerate(vocabulary(e.field))}
        x = np.array([vocab.get(v, np.nan) for v in personas[e.field].astype(object)], float)
        y = values[e.target].to_numpy(float)
        ok = np.isfinite(x) & np.isfinite(y)
        x, y = x[ok], y[ok]
        rho = float(_spearman(x, y)) if len(x) > 1 else np.nan
        draws = rng.integers(0, max(len(x), 1), (n_boot, len(x)))
        boot = _spearman(x[draws], y[draws])
        boot = boot[np.isfinite(boot)]
        low, high = np.quantile(boot, [0.025, 0.975]) if len(boot) else (np.nan, np.nan)
        if not np.isfinite(rho):
            low = high = np.nan
        rows.append({"field": e.field, "target": e.target, "expected": "+" if e.sign > 0 else "−",
                     "why": e.why, "n": len(x), "rho": rho, "ci_low": float(low),
                     "ci_high": float(high), "outcome": direction_outcome(e.sign, low, high)})
    return pd.DataFrame(rows)


#: How setting time pressure to Deadline should move each block item (SPEC §3: urgency
#: up, waiting and yielding down, small-gap acceptance up); 0 = no declared direction.
DEADLINE_SIGNS: dict[str, int] = {"q_urgency": 1, "q_waiting": -1, "q_yielding": -1, "q_gap": 1,
                                  "q_clearance": 0, "q_detour": 0, "q_trust": 0}


def paired(responses: pd.DataFrame) -> tuple[pd.DataFrame, pd.DataFrame]:
    """(baseline, deadline) rows of the personas asked both, aligned by persona id."""
    asked = responses.groupby("variant")["persona_id"].agg(set)
    ids = sorted(asked.get("baseline", set()) & asked.get("deadline", set()))

    def rows(v: str) -> pd.DataFrame:
        return responses[responses["variant"] == v].set_index("persona_id").loc[ids]

    return rows("baseline"), rows("deadline")


def manipulation(responses: pd.DataFrame, *, rng: np.random.Generator,
                 n_boot: int = 1000) -> pd.DataFrame:
    """The matched intervention's paired shift: one row per block item (``shift``, the
    mean deadline − baseline answer, ``sd`` of the paired shifts, with its 95% bootstrap
    interval over personas,
    ``up`` and ``down`` shares, ``expected`` sign and the :func:`direction_outcome`) and
    one row ``actions`` (``changed``: share of probe answers that changed). Empty
    without matched pairs."""
    base, dead = paired(responses)
    n = len(base)
    if n == 0:
        return pd.DataFrame()
    draws = rng.integers(0, n, (n_boot, n))
    rows = []
    for col in Q_COLUMNS:
        d = dead[col].to_numpy(float) - base[col].to_numpy(float)
        low, high = np.quantile(d[draws].mean(axis=1), [0.025, 0.975])
        sign = DEADLINE_SIGNS[col]
        rows.append({"target": col, "n": n, "shift": float(d.mean()),
                     "sd": float(d.std(ddof=1)) if n > 1 else np.nan, "ci_low": float(low),
                     "ci_high": float(high), "up": float((d > 0).mean()),
                     "down": float((d < 0).mean()),
                     "expected": {1: "+", -1: "−", 0: ""}[sign],
                     "outcome": direction_outcome(sign, low, high) if sign else "",
                     "changed": float((d != 0).mean())})
    acts = list(ACTION_COLUMNS)
    changed = (dead[acts].astype(str).to_numpy() != base[acts].astype(str).to_numpy()).mean()
    rows.append({"target": "actions", "n": n, "changed": float(changed)})
    return pd.DataFrame(rows)


def cohen_kappa(a: np.ndarray, b: np.ndarray) -> float:
    """Cohen's κ of two label arrays (NaN when chance agreement is 1)."""
    labels = np.union1d(a, b)
    pa = np.array([(a == x).mean() for x in labels])
    pb = np.array([(b == x).mean() for x in labels])
    expected = float((pa * pb).sum())
    return np.nan if expected >= 1 else ((a == b).mean() - expected) / (1 - expected)


def agreement(first: pd.DataFrame, second: pd.DataFrame, first_profiles: pd.DataFrame,
              second_profiles: pd.DataFrame) -> pd.DataFrame:
    """Two respondents' answers (and motion parameters) on the records both answered
    (same persona and variant): per probe ``agree`` and Cohen's ``kappa``; per item
    ``agree``, ``within_one`` (level), ``rho`` (Spearman) and ``mean_abs_diff``; per
    motion parameter Pearson ``r``."""
    key = ["persona_id", "variant"]
    m = first.merge(second, on=key, suffixes=("_1", "_2"))
    rows = []
    for col in ACTION_COLUMNS:
        a, b = m[f"{col}_1"].astype(str).to_numpy(), m[f"{col}_2"].astype(str).to_numpy()
        rows.append({"target": col, "kind": "action", "n": len(m), "agree": float((a == b).mean())
                     if len(m) else np.nan, "kappa": cohen_kappa(a, b) if len(m) else np.nan})
    for col in Q_COLUMNS:
        a, b = m[f"{col}_1"].to_numpy(float), m[f"{col}_2"].to_numpy(float)
        rows.append({"target": col, "kind": "item", "n": len(m),
                     "agree": float((a == b).mean()) if len(m) else np.nan,
                     "within_one": float((np.abs(a - b) <= LEVEL + 1e-9).mean())
                     if len(m) else np.nan,
                     "rho": float(_spearman(a, b)) if len(m) > 1 else np.nan,
                     "mean_abs_diff": float(np.abs(a - b).mean()) if len(m) else np.nan})
    if first_profiles.empty or second_profiles.empty:
        return pd.DataFrame(rows)
    p = first_profiles.merge(second_profiles, on=key, suffixes=("_1", "_2"))
    for col in PARAMS:
        a, b = p[f"{col}_1"].to_numpy(float), p[f"{col}_2"].to_numpy(float)
        with np.errstate(invalid="ignore", divide="ignore"):
            r = float(np.corrcoef(a, b)[0, 1]) if len(p) > 1 else np.nan
        rows.append({"target": col, "kind": "parameter", "n": len(p), "r": r})
    return pd.DataFrame(rows)
