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

Every check that fails is weighed by its power (:mod:`.audit_power`): the smallest
effect it could detect at this number of personas and samples, against the effect a
usable respondent shows. A failure of a check without that power cannot tell a weak
respondent from a usable one asked too few personas: alone, such failures make the
verdict **not enough personas to tell** (needs ≈ N), and "not persona-sensitive" is said
only when the sensitivity test could have seen a usable respondent's dependence.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd

from ..errors import ConfigError
from ..populations.perturb import ProfileSet
from ..profiles.mappings import build_profiles
from ..read.respondent_tables import MAIN_MAPPING, RespondentTables
from ..responses.samples import aggregate_samples, with_samples
from ..tables import PARAMS
from . import audit_power as power
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
    rho_text,
    sensitivity,
    spread,
)
from .audit_power import POWER
from .audit_retest import HOW_TO_MEASURE, identical_share, retest

USABLE, WEAK, NOT_SENSITIVE = "usable", "weak", "not persona-sensitive"
#: a check failed that, at this size, would fail for a usable respondent too
UNDECIDED = "not enough personas to tell"
ALPHA = 0.05  # family-wise level of the sensitivity tests, per family
MIN_EXCESS_R2 = 0.05  # R² the persona fields must explain beyond the shuffled null's mean
MIN_DISTINCT_SHARE = 0.5  # distinct answer rows per distinct persona record, at least
MIN_URGENCY_SHIFT = LEVEL / 2  # deadline − baseline urgency: half a level, at least
#: test–retest ICC below which a block item, the action score or a motion parameter fails:
#: Koo & Li (2016) read ICC < 0.5 as poor reliability
MIN_ICC = 0.5
#: the fewest persona shuffles whose smallest p, 1 / (1 + n), reaches the Bonferroni level
#: of the larger family (16 answers)
MIN_PERMUTATIONS = math.ceil(ANSWER_TARGETS / ALPHA) - 1


@dataclass(frozen=True)
class Failure:
    """A check that failed: ``text`` says how; ``needs`` the size at which it could have
    passed for a usable respondent (:mod:`.audit_power`), None when it could (a failure
    to believe) or when it is a fact that needs no power (a stuck item, a reversal)."""

    text: str
    powered: bool = True
    needs: int | None = None
    unit: str = "personas"


def mark_sensitive(sens: pd.DataFrame) -> pd.DataFrame:
    """``sens`` (:func:`.audit.sensitivity`) with ``family`` (answer, parameter),
    ``sensitive`` (module docstring), the smallest R² the test detects (``mde``), whether
    that is a usable respondent's (``powered``) and the personas it would need (``needs``)."""
    family = np.where(sens["kind"] == "parameter", "parameter", "answer")
    size = pd.Series(family).map(pd.Series(family).value_counts()).to_numpy()
    ok = (sens["p_value"] <= ALPHA / size) & (sens["excess"] >= MIN_EXCESS_R2)
    n, columns = int(sens["n"].iloc[0]), int(sens["columns"].iloc[0])
    mde = {m: power.sensitivity_mde(n, columns, ALPHA / m, MIN_EXCESS_R2) for m in set(size)}
    needs = {m: power.sensitivity_needs(columns, ALPHA / m, MIN_EXCESS_R2) for m in set(size)}
    found = np.array([mde[m] for m in size])
    return sens.assign(family=family, sensitive=ok.fillna(False).astype(bool), mde=found,
                       powered=found <= power.USABLE["sensitivity"],
                       needs=[needs[m] for m in size])


def _signed(x: float) -> str:
    return f"{x:+.2f}"


def mark_directions(dirs: pd.DataFrame) -> pd.DataFrame:
    """``dirs`` with the smallest |ρ| each check detects (``mde``), ``powered``, ``needs``."""
    if dirs.empty:
        return dirs
    mde = np.array([power.rho_mde(int(n)) for n in dirs["n"]])
    return dirs.assign(mde=mde, powered=mde <= power.USABLE["direction"],
                       needs=power.rho_needs())


def mark_manipulation(manip: pd.DataFrame) -> pd.DataFrame:
    """``manip`` with, for the urgency shift the verdict reads, the smallest true shift
    that passes (``mde``), ``powered`` and the matched personas it ``needs``."""
    if manip.empty:
        return manip
    urgency = manip["target"] == "q_urgency"
    mde = [power.shift_mde(sd, int(n), MIN_URGENCY_SHIFT) if u else np.nan
           for u, sd, n in zip(urgency, manip["sd"], manip["n"], strict=True)]
    needs = [power.shift_needs(sd, MIN_URGENCY_SHIFT) if u else None
             for u, sd in zip(urgency, manip["sd"], strict=True)]
    return manip.assign(mde=mde, powered=np.array(mde) <= power.USABLE["manipulation"],
                        needs=needs)


def mark_retest(table: pd.DataFrame) -> pd.DataFrame:
    """``table`` with the smallest true ICC test–retest passes (``mde``), ``powered``,
    and the records it ``needs`` at the same number of samples."""
    if table.empty:
        return table
    n, k = int(table["records"].iloc[0]), int(table["samples"].iloc[0])
    mde = power.icc_mde(n, k, MIN_ICC)
    return table.assign(mde=mde, powered=mde <= power.USABLE["retest"],
                        needs=power.icc_needs(k, MIN_ICC))


def _judged(text: str, row: Any, unit: str = "personas") -> Failure:
    """A failed check's :class:`Failure`: believed when the check was powered."""
    if row["powered"]:
        return Failure(text)
    needs = row["needs"]
    known = needs is not None and np.isfinite(needs)
    return Failure(text, False, int(needs) if known else None, unit)


def failures(spread_: pd.DataFrame, sens: pd.DataFrame, dirs: pd.DataFrame,
             manip: pd.DataFrame, distinct: dict[str, int]) -> list[Failure]:
    """What keeps a persona-sensitive respondent from ``usable``, one per check."""
    out = []
    stuck = spread_[spread_["stuck"]]
    if not stuck.empty:
        out.append(Failure("stuck: " + ", ".join(
            f"{r.column} ({r.used} of {r.levels} used, {r.modal} {100 * r.modal_share:.0f}%)"
            for r in stuck.itertuples())))
    bad = sens[(sens["kind"] != "action") & ~sens["sensitive"]]
    for _, group in bad.groupby("powered", sort=False):
        out.append(_judged("not persona-sensitive: " + ", ".join(group["target"]),
                           group.iloc[0]))
    if distinct["answer_rows"] < MIN_DISTINCT_SHARE * distinct["persona_records"]:
        out.append(Failure(f"{distinct['answer_rows']} distinct answer rows for "
                           f"{distinct['persona_records']} distinct persona records"))
    for _, r in dirs[dirs["outcome"] != "as expected"].iterrows() if not dirs.empty else ():
        text = (f"{r['field']} → {r['target']}: ρ {rho_text(r['rho'], r['ci_low'], r['ci_high'])}"
                f", expected {r['expected']} ({r['outcome']})")
        out.append(_judged(text, r) if r["outcome"] == "flat" else Failure(text))
    if not manip.empty:
        q = manip[manip["target"] != "actions"].set_index("target")
        u = q.loc["q_urgency"]
        if not (u["outcome"] == "as expected" and u["shift"] >= MIN_URGENCY_SHIFT):
            text = (f"the deadline moved urgency by {_signed(u['shift'])} "
                    f"[{_signed(u['ci_low'])}, {_signed(u['ci_high'])}] (needs ≥ "
                    f"{_signed(MIN_URGENCY_SHIFT)}, interval above 0)")
            out.append(Failure(text) if u["outcome"] == "reversed"
                       else _judged(text, u, "matched personas"))
        rev = q.index[q["outcome"] == "reversed"]
        if len(rev):
            out.append(Failure("the deadline moved against its direction: " + ", ".join(rev)))
    return out


def retest_failures(table: pd.DataFrame, identical: float, temperature: object
                    ) -> list[Failure]:
    """What test–retest finds wrong (module docstring); nothing when it was not measured."""
    if table.empty:
        return []
    out = []
    low = table[(table["kind"] != "action") & (table["icc"] < MIN_ICC)]
    if not low.empty:
        out.append(_judged(f"test–retest ICC below {MIN_ICC:g} over "
                           f"{int(table['samples'].iloc[0])} samples: "
                           + ", ".join(f"{r.target} {r.icc:.2f}" for r in low.itertuples()),
                           low.iloc[0], "records"))
    if temperature == 0 and identical < 1:
        out.append(Failure(
            f"server not reproducible: at temperature 0, {1 - identical:.0%} of records "
            f"differ across their {int(table['samples'].iloc[0])} samples (each sent with "
            "its own seed; for llama.cpp set extra_body {cache_prompt: false}, docs/llm.md)"))
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


def _needs_text(f: Failure) -> str:
    return (f"needs ≈ {f.needs:,} {f.unit}" if f.needs is not None
            else f"needs more {f.unit} than can be asked")


def verdict(sens: pd.DataFrame, fails: list[Failure]) -> tuple[str, list[str]]:
    """(verdict, reasons): ``not persona-sensitive`` when no answer is and the test could
    have seen a usable respondent's dependence; ``weak`` with the failures of checks that
    could have passed; ``not enough personas to tell`` when only checks without that
    power failed (each with the size it needs, :mod:`.audit_power`); else ``usable``."""
    answers = sens[sens["family"] == "answer"]
    if not answers["sensitive"].any():
        best = answers["excess"].max()
        if not np.isfinite(best):
            return NOT_SENSITIVE, ["every answer is constant: the populations built from "
                                   "these answers are artifacts"]
        scored = answers[answers["kind"] != "action"].iloc[0]
        seen = (f"no answer follows the persona beyond a persona-shuffled null (0 of "
                f"{len(answers)}; largest R² excess {best:+.3f}); at {int(scored['n'])} "
                f"personas the test sees an R² of {scored['mde']:.2f} or more "
                f"({POWER:.0%} power; a usable respondent's: "
                f"{power.USABLE['sensitivity']:.2f})")
        if not scored["powered"]:
            need = _judged(seen, scored)
            return UNDECIDED, [f"{_needs_text(need)}: {seen}"]
        return NOT_SENSITIVE, [seen + ": the populations built from these answers are "
                               "artifacts"]
    facts = [f.text for f in fails if f.powered]
    unpowered = [f for f in fails if not f.powered]
    told = [f"could not tell ({_needs_text(f)}): {f.text}" for f in unpowered]
    if facts:
        return WEAK, facts + told
    if unpowered:
        worst = max(unpowered, key=lambda f: (f.unit == "personas", f.needs or math.inf))
        return UNDECIDED, [_needs_text(worst), *told]
    return USABLE, []


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
    dirs = mark_directions(directions(who, values, rng=np.random.default_rng(rng_seed),
                                      n_boot=n_boot))
    manip = mark_manipulation(manipulation(responses, rng=np.random.default_rng(rng_seed),
                                           n_boot=n_boot))
    spread_ = spread(samples)
    distinct = distinct_rows(samples[samples["sample"] == 0], personas)
    # the mapping the profiles used (a second respondent's set A~<name>-2 maps with A)
    mapping = (ProfileSet.parse(str(r.profiles["mapping"].iloc[0])).base
               if not r.profiles.empty else MAIN_MAPPING)
    again = mark_retest(retest(samples, lambda one: build_profiles(one, personas, mapping)))
    identical = identical_share(samples)
    unstable = retest_failures(again, identical, r.meta.get("temperature"))
    word, reasons = verdict(sens, failures(spread_, sens, dirs, manip, distinct) + unstable)
    if word in (NOT_SENSITIVE, UNDECIDED):  # said beside it: its own problem
        reasons += [f.text for f in unstable if f.powered]
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
