"""Respondent audit, the verdict: every respondent of a study → its audit tables and a
verdict, ``usable``, ``weak`` (with what fails) or ``not persona-sensitive``.

The statistics are in :mod:`.audit`; the thresholds are here, each with its reason
(docs/llm.md, "Respondent audit"):

* an answer or motion parameter is **persona-sensitive** when its R² on the persona fields
  beats the persona-shuffled null at p ≤ :data:`ALPHA` / (targets of its family:
  16 answers — 8 probe actions, 7 block items, the action score — and 7 parameters;
  Bonferroni) *and* exceeds the null's mean by at least :data:`MIN_EXCESS_R2` — with
  hundreds of personas a trace of dependence is significant, and a trace does not make
  populations;
* **not persona-sensitive** — no answer is: the answers carry no more of the persona
  than a shuffle, so the populations built from them are artifacts (motion parameters
  are not asked: the mobility speed caps give speed a persona dependence whatever the
  respondent says);
* **weak** — persona-sensitive, but something fails: a stuck answer column, a block
  item, the action score or a motion parameter that is not persona-sensitive (what the
  mappings read; a single probe's action is shown but not required: the mappings read
  the actions only through their score), fewer distinct answer rows than
  :data:`MIN_DISTINCT_SHARE` of the distinct persona records, an expected direction
  that is flat or reversed, or a matched intervention that does not raise urgency by
  :data:`MIN_URGENCY_SHIFT` (its interval above 0) or reverses a declared direction;
* **weak** too when test–retest (:mod:`.audit_retest`, with 2 or more samples per
  persona) finds a block item, the action score or a motion parameter with an ICC below
  :data:`MIN_ICC` (what a persona is made of changes from one asking to the next more
  than between personas), or a server at temperature 0 whose samples differ (**not
  reproducible**); with one sample, test–retest is *not measured*, and the verdict says
  how to measure it;
* **usable** — nothing fails.

With several samples per persona, every statistic but the spread (all samples pooled)
and the distinct rows (sample 0) reads the per-persona aggregate the profiles were built
from (:func:`popnavshift.responses.samples.aggregate_samples`).

With so few personas that a shuffle alone explains :data:`MAX_NULL_R2` of any answer,
a respondent without a persona-sensitive answer reads **weak** ("too few personas"),
not "not persona-sensitive": the test could not have seen it.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from ..errors import ConfigError
from ..populations.perturb import ProfileSet
from ..profiles.mappings import build_profiles
from ..read.respondent_tables import MAIN_MAPPING, RespondentTables
from ..responses.samples import aggregate_samples, with_samples
from ..tables import PARAMS
from .audit import (
    ANSWER_TARGETS,
    LEVEL,
    agreement,
    answer_targets,
    baseline,
    directions,
    distinct_rows,
    manipulation,
    parameter_targets,
    persona_basis,
    sensitivity,
    spread,
)
from .audit_retest import HOW_TO_MEASURE, identical_share, retest

USABLE, WEAK, NOT_SENSITIVE = "usable", "weak", "not persona-sensitive"
ALPHA = 0.05  # family-wise level of the sensitivity tests, per family
MIN_EXCESS_R2 = 0.05  # R² the persona fields must explain beyond the shuffled null's mean
MIN_DISTINCT_SHARE = 0.5  # distinct answer rows per distinct persona record, at least
MIN_URGENCY_SHIFT = LEVEL / 2  # deadline − baseline urgency: half a level, at least
#: test–retest ICC below which a block item, the action score or a motion parameter fails:
#: Koo & Li (2016) read ICC < 0.5 as poor reliability
MIN_ICC = 0.5
#: below this many personas per persona-field column the test cannot see a dependence:
#: the shuffled null's expected R², columns / (n − 1), would reach this share
MAX_NULL_R2 = 0.5
#: the fewest persona shuffles whose smallest p, 1 / (1 + n), reaches the Bonferroni level
#: of the larger family (16 answers)
MIN_PERMUTATIONS = math.ceil(ANSWER_TARGETS / ALPHA) - 1


def mark_sensitive(sens: pd.DataFrame) -> pd.DataFrame:
    """``sens`` (:func:`.audit.sensitivity`) with ``family`` (answer, parameter) and
    ``sensitive`` (module docstring)."""
    family = np.where(sens["kind"] == "parameter", "parameter", "answer")
    size = pd.Series(family).map(pd.Series(family).value_counts()).to_numpy()
    ok = (sens["p_value"] <= ALPHA / size) & (sens["excess"] >= MIN_EXCESS_R2)
    return sens.assign(family=family, sensitive=ok.fillna(False).astype(bool))


def _signed(x: float) -> str:
    return f"{x:+.2f}"


def failures(spread_: pd.DataFrame, sens: pd.DataFrame, dirs: pd.DataFrame,
             manip: pd.DataFrame, distinct: dict[str, int]) -> list[str]:
    """What keeps a persona-sensitive respondent from ``usable``, one phrase per check."""
    out = []
    stuck = spread_[spread_["stuck"]]
    if not stuck.empty:
        out.append("stuck: " + ", ".join(f"{r.column} ({r.used} of {r.levels} used, "
                                         f"{r.modal} {100 * r.modal_share:.0f}%)"
                                         for r in stuck.itertuples()))
    bad = sens[(sens["kind"] != "action") & ~sens["sensitive"]]
    if not bad.empty:
        out.append("not persona-sensitive: " + ", ".join(bad["target"]))
    if distinct["answer_rows"] < MIN_DISTINCT_SHARE * distinct["persona_records"]:
        out.append(f"{distinct['answer_rows']} distinct answer rows for "
                   f"{distinct['persona_records']} distinct persona records")
    for r in dirs[dirs["outcome"] != "as expected"].itertuples() if not dirs.empty else ():
        out.append(f"{r.field} → {r.target}: ρ {_signed(r.rho)} [{_signed(r.ci_low)}, "
                   f"{_signed(r.ci_high)}], expected {r.expected} ({r.outcome})")
    if not manip.empty:
        q = manip[manip["target"] != "actions"].set_index("target")
        u = q.loc["q_urgency"]
        if not (u["outcome"] == "as expected" and u["shift"] >= MIN_URGENCY_SHIFT):
            out.append(f"the deadline moved urgency by {_signed(u['shift'])} "
                       f"[{_signed(u['ci_low'])}, {_signed(u['ci_high'])}] (needs ≥ "
                       f"{_signed(MIN_URGENCY_SHIFT)}, interval above 0)")
        rev = q.index[q["outcome"] == "reversed"]
        if len(rev):
            out.append("the deadline moved against its direction: " + ", ".join(rev))
    return out


def retest_failures(table: pd.DataFrame, identical: float, temperature: object) -> list[str]:
    """What test–retest finds wrong (module docstring); nothing when it was not measured."""
    if table.empty:
        return []
    out = []
    low = table[(table["kind"] != "action") & (table["icc"] < MIN_ICC)]
    if not low.empty:
        out.append(f"test–retest ICC below {MIN_ICC:g} over {int(table['samples'].iloc[0])} "
                   "samples: " + ", ".join(f"{r.target} {r.icc:.2f}" for r in low.itertuples()))
    if temperature == 0 and identical < 1:
        out.append(f"server not reproducible: at temperature 0, {1 - identical:.0%} of "
                   f"records differ across their {int(table['samples'].iloc[0])} samples "
                   "(each sent with its own seed; for llama.cpp set extra_body "
                   "{cache_prompt: false}, docs/llm.md)")
    return out


def retest_summary(table: pd.DataFrame, identical: float) -> str:
    """One phrase for the verdict row: how test–retest came out, or how to measure it."""
    if table.empty:
        return f"not measured (one sample per persona; {HOW_TO_MEASURE})"
    scored = table[table["kind"] != "action"]
    worst = scored.loc[scored["icc"].idxmin()] if scored["icc"].notna().any() else None
    lowest = "" if worst is None else f", lowest ICC {worst['icc']:.2f} ({worst['target']})"
    return (f"{int(table['samples'].iloc[0])} samples of {int(table['records'].iloc[0])} "
            f"records, {identical:.0%} identical{lowest}")


def verdict(sens: pd.DataFrame, fails: list[str]) -> tuple[str, list[str]]:
    """(verdict, reasons): ``not persona-sensitive`` when no answer is, else ``weak``
    with ``fails``, else ``usable``; ``weak`` too, saying so, when no answer is and the
    personas are too few for the test (:data:`MAX_NULL_R2`)."""
    answers = sens[sens["family"] == "answer"]
    n, columns = int(answers["n"].iloc[0]), int(answers["columns"].iloc[0])
    if not answers["sensitive"].any() and answers["r2"].notna().any() and (
            columns >= MAX_NULL_R2 * (n - 1)):
        return WEAK, [f"too few personas to test persona sensitivity: {n} personas for "
                      f"{columns} persona-field columns (a shuffle alone explains about "
                      f"{columns / max(n - 1, 1):.0%} of any answer; ask at least "
                      f"{math.floor(columns / MAX_NULL_R2) + 2})", *fails]
    if not answers["sensitive"].any():
        best = answers["excess"].max()
        why = (f"no answer follows the persona beyond a persona-shuffled null (0 of "
               f"{len(answers)}; largest R² excess {best:+.3f})" if np.isfinite(best) else
               "every answer is constant")
        return NOT_SENSITIVE, [why + ": the populations built from these answers are "
                               "artifacts"]
    return (WEAK, fails) if fails else (USABLE, [])


def audit_respondent(personas: pd.DataFrame, r: RespondentTables, *, rng_seed: int = 0,
                     n_perm: int = 999, n_boot: int = 1000) -> dict[str, pd.DataFrame]:
    """One respondent's tables (``spread``, ``sensitivity``, ``directions``,
    ``manipulation``, ``verdict``), each with a ``respondent`` column (its role).

    The persona population is the respondent's baseline answers; its motion parameters
    are the profiles' baseline rows of the same personas (all seven are left out when
    one of these personas has no profile). ``rng_seed`` seeds the permutations and
    bootstraps (fresh generators). With several samples per persona the statistics read
    their aggregate, and test–retest (``retest``) compares them (module docstring)."""
    samples = with_samples(r.responses)
    responses = aggregate_samples(samples)
    base = baseline(responses)
    who = personas.set_index("persona_id").reindex(base["persona_id"]).reset_index()
    prof = pd.DataFrame()
    if not r.profiles.empty:
        p = r.profiles[r.profiles["variant"] == "baseline"].set_index("persona_id")
        prof = p.reindex(base["persona_id"]).reset_index()
        prof = prof if prof[list(PARAMS)].notna().all().all() else pd.DataFrame()
    targets = answer_targets(base) + (parameter_targets(prof) if not prof.empty else [])
    sens = mark_sensitive(sensitivity(targets, persona_basis(who),
                                      rng=np.random.default_rng(rng_seed), n_perm=n_perm))
    values = pd.concat([base, prof[list(PARAMS)]], axis=1) if not prof.empty else base
    dirs = directions(who, values, rng=np.random.default_rng(rng_seed), n_boot=n_boot)
    manip = manipulation(responses, rng=np.random.default_rng(rng_seed), n_boot=n_boot)
    spread_ = spread(samples)
    distinct = distinct_rows(samples[samples["sample"] == 0], personas)
    # the mapping the profiles used (a second respondent's set A~<name>-2 maps with A)
    mapping = (ProfileSet.parse(str(r.profiles["mapping"].iloc[0])).base
               if not r.profiles.empty else MAIN_MAPPING)
    again = retest(samples, lambda one: build_profiles(one, personas, mapping))
    identical = identical_share(samples)
    unstable = retest_failures(again, identical, r.meta.get("temperature"))
    word, reasons = verdict(sens, failures(spread_, sens, dirs, manip, distinct) + unstable)
    if word == NOT_SENSITIVE:  # said beside it: an unreproducible server is its own problem
        reasons += unstable
    urgency = manip.set_index("target")["shift"].get("q_urgency", np.nan) if not manip.empty \
        else np.nan
    summary = pd.DataFrame([{
        "respondent": r.role, "name": str(r.responses["respondent"].iloc[0]),
        "model": str(r.responses["model"].iloc[0]), **distinct,
        "sensitive_answers": int(sens.loc[sens["family"] == "answer", "sensitive"].sum()),
        "answers": int((sens["family"] == "answer").sum()),
        "sensitive_parameters": int(sens.loc[sens["family"] == "parameter", "sensitive"].sum()),
        "parameters": int((sens["family"] == "parameter").sum()),
        "directions_as_expected": int((dirs["outcome"] == "as expected").sum())
        if not dirs.empty else 0,
        "directions": len(dirs), "urgency_shift": urgency,
        "samples": int(samples.groupby(["persona_id", "variant"])["sample"].nunique().max()),
        "retest": retest_summary(again, identical), "verdict": word,
        "reasons": "; ".join(reasons)}])
    tables = {"spread": spread_, "sensitivity": sens, "directions": dirs,
              "manipulation": manip, "retest": again, "verdict": summary}
    return {k: v.assign(respondent=r.role) if not v.empty else v for k, v in tables.items()}


def audit_tables(personas: pd.DataFrame, respondents: list[RespondentTables], *,
                 rng_seed: int = 0, n_perm: int = 999, n_boot: int = 1000
                 ) -> dict[str, pd.DataFrame]:
    """The audit of every respondent as report tables ``audit_<name>`` (rows of all
    respondents stacked), and ``audit_agreement`` when there are two.

    Raises ConfigError when ``n_perm`` is below :data:`MIN_PERMUTATIONS`."""
    if n_perm < MIN_PERMUTATIONS:
        raise ConfigError(f"n_perm={n_perm}: so few persona shuffles cannot reach p ≤ "
                          f"{ALPHA / ANSWER_TARGETS:.4f}; expected at least {MIN_PERMUTATIONS}")
    per = [audit_respondent(personas, r, rng_seed=rng_seed, n_perm=n_perm, n_boot=n_boot)
           for r in respondents]
    out = {}
    for name in ("verdict", "spread", "sensitivity", "directions", "manipulation", "retest"):
        frames = [t[name] for t in per if not t[name].empty]
        if frames:
            out[f"audit_{name}"] = pd.concat(frames, ignore_index=True)
    if len(respondents) == 2:
        a, b = respondents
        out["audit_agreement"] = agreement(aggregate_samples(with_samples(a.responses)),
                                           aggregate_samples(with_samples(b.responses)),
                                           a.profiles, b.profiles)
    return out
