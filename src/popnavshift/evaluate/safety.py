"""The card's safety verdict: which failure, how often — under one rule for every controller.

A blanket "unsafe" hides which failure it is: a robot that drives into pedestrians and a
robot that scrapes the static obstacle of the ``obstruction`` scene are different findings.
Per failure kind — pedestrian collisions with the robot moving, pedestrians walking into
the standing robot, wall and obstacle contacts, controller errors, and timeouts (the
second and the last reported, never unsafe by themselves) — and per scope (all runs, then
each scene):

* every controller's **rate** over its runs with an exact (Clopper–Pearson) 95 % interval;
* the evaluated controller's **paired difference** to each baseline on the same runs
  (episode, population, backend, mapping: the same starts, goals and pedestrians), with a
  95 % percentile interval from resampling episodes (every population of an episode goes
  with it): context, not the rule;
* the verdict, the same rule for every controller (so that the labels of a leaderboard can
  be ranked): per counted kind (:data:`UNSAFE_KINDS`), **unsafe** when the whole interval of
  its rate is above the threshold (``SAFETY_THRESHOLD``, 1 % of its runs by default: a
  robot that collides in more than one run in a hundred of these everyday scenes would not
  be deployed), **safe** when every counted kind's interval is at or below it, else
  **undecided** (an interval that straddles the threshold: more runs would decide). A
  baseline is judged by the same rule, never against itself.

Who moved into whom: the runs table records the robot's speed at the contact that ended
its run (``contact_speed``); a pedestrian collision with the robot slower than 0.05 m/s is
a pedestrian walking into a standing robot, reported on its own line and never counted
as unsafe.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from ..analysis.verdicts import clopper_pearson

FAILURES: dict[str, str] = {"pedestrian_collision": "pedestrian collisions (robot moving)",
                            "standing_contact": "pedestrians walking into the standing robot",
                            "world_collision": "wall and obstacle contacts",
                            "controller_error": "controller errors",
                            "timeout": "timeouts"}
#: The failure kinds that make a controller unsafe: a timeout is a failure to arrive, and a
#: pedestrian walking into a robot that stands still is the pedestrian's move, not a danger
#: the controller made (both are reported).
UNSAFE_KINDS: tuple[str, ...] = ("pedestrian_collision", "world_collision", "controller_error")
#: Slower than this at the contact, the robot was standing [m/s] (the stop threshold of
#: robot_stop_time).
STANDING = 0.05


def failure(runs: pd.DataFrame) -> pd.Series:
    """Each run's failure kind (its outcome, with a pedestrian collision at a robot speed
    under ``STANDING`` as ``standing_contact``; tables without ``contact_speed`` count every
    collision as the robot's move)."""
    kind = runs["outcome"].astype(str)
    if "contact_speed" in runs:
        standing = (kind == "pedestrian_collision") & (runs["contact_speed"] < STANDING)
        kind = kind.where(~standing, "standing_contact")
    return kind
RUN_KEY = ["episode", "population", "backend", "mapping"]
LEVEL = 0.95
N_BOOT = 1000


def failure_rates(runs: pd.DataFrame, controllers: list[str]) -> pd.DataFrame:
    """Per (kind, scope ∈ {all, <scene>}, controller): ``runs``, ``failures``, ``rate`` and
    its Clopper–Pearson ``low``/``high``; robot runs only."""
    r = runs[runs["controller"].isin(controllers)].assign(failure=failure)
    rows = []
    for scope, sub in [("all", r), *sorted(r.groupby("scene"), key=lambda x: str(x[0]))]:
        for ctrl in controllers:
            own = sub[sub["controller"] == ctrl]
            for kind in FAILURES:
                k, n = int((own["failure"] == kind).sum()), len(own)
                low, high = clopper_pearson(k, n, LEVEL)
                rows.append({"kind": kind, "scope": str(scope), "controller": ctrl, "runs": n,
                             "failures": k, "rate": k / n if n else np.nan, "low": low,
                             "high": high})
    return pd.DataFrame(rows)


def paired_differences(runs: pd.DataFrame, controller: str, baselines: list[str], *,
                       rng: np.random.Generator, n_boot: int = N_BOOT) -> pd.DataFrame:
    """Per (kind, scope, baseline): the evaluated controller's failure rate minus the
    baseline's on the runs both have (``pairs``), with a 95 % percentile interval over
    episode resamples (the same resamples for every kind and baseline)."""
    wide = runs[runs["controller"].isin([controller, *baselines])].assign(
        failure=failure).pivot_table(index=RUN_KEY, columns="controller", values="failure",
                                     aggfunc="first")
    scene = runs.drop_duplicates("episode").set_index("episode")["scene"]
    episodes = wide.index.get_level_values("episode")
    codes, uniq = pd.factorize(episodes)
    weights = rng.multinomial(len(uniq), np.full(len(uniq), 1 / len(uniq)), size=n_boot)
    rows = []
    for b in baselines:
        if b not in wide:
            continue
        both = wide[controller].notna() & wide[b].notna()
        for kind in FAILURES:
            d = ((wide[controller] == kind).astype(float) - (wide[b] == kind).astype(float))
            for scope in ["all", *sorted(scene.unique())]:
                sel = both & (True if scope == "all" else scene.reindex(episodes).eq(scope)
                              .to_numpy())
                rows.append(_difference(d[sel].to_numpy(), codes[sel.to_numpy()], weights,
                                        kind=kind, scope=scope, baseline=b))
    return pd.DataFrame(rows)


def _difference(d: np.ndarray, codes: np.ndarray, weights: np.ndarray, **key) -> dict:
    """Mean of the paired differences ``d`` and its percentile interval: each resample
    weighs every episode's pairs by its multiplicity (``weights``: B × episodes)."""
    if d.size == 0:
        return {**key, "pairs": 0, "difference": np.nan, "low": np.nan, "high": np.nan}
    n_ep = weights.shape[1]
    sums = np.bincount(codes, weights=d, minlength=n_ep)
    counts = np.bincount(codes, minlength=n_ep).astype(float)
    with np.errstate(invalid="ignore"):
        boot = (weights @ sums) / (weights @ counts)
    a = (1 - LEVEL) / 2
    low, high = np.nanquantile(boot, [a, 1 - a])
    return {**key, "pairs": int(d.size), "difference": float(d.mean()), "low": float(low),
            "high": float(high)}


SAFETY_THRESHOLD = 0.01  # default share of its runs a counted failure must stay under
SAFE, UNSAFE, UNDECIDED = "safe", "unsafe", "undecided"


@dataclass
class SafetyVerdict:
    """The safety label, its sentence, one finding per counted kind above the threshold
    (each names its failure, rate, interval and where it is highest) and the threshold."""

    label: str
    text: str
    findings: list[str]
    threshold: float


def safety_verdict(rates: pd.DataFrame, controller: str,
                   threshold: float = SAFETY_THRESHOLD) -> SafetyVerdict:
    """The controller's safety verdict under the one rule of the module doc, from its
    failure ``rates`` (:func:`failure_rates`)."""
    overall = rates[rates["scope"] == "all"].set_index(["kind", "controller"])
    findings, open_kinds = [], []
    for kind in UNSAFE_KINDS:
        own = overall.loc[(kind, controller)]
        span = (f"{100 * own['rate']:.1f}% of its {int(own['runs']):,} runs "
                f"[{100 * own['low']:.1f}, {100 * own['high']:.1f}]")
        if own["low"] > threshold:
            scenes = rates[(rates["kind"] == kind) & (rates["controller"] == controller)
                           & (rates["scope"] != "all")]
            top = scenes.loc[scenes["rate"].idxmax()] if len(scenes) else None
            where = (f"; highest in {top['scope']} ({100 * top['rate']:.1f}% of its runs there)"
                     if top is not None and top["failures"] else "")
            findings.append(f"{FAILURES[kind]} in {span}{where}")
        elif own["high"] > threshold:
            open_kinds.append(f"{FAILURES[kind]} {span}")
    limit = f"{100 * threshold:g}% of its runs"
    if findings:
        return SafetyVerdict(UNSAFE, f"Above {limit}: " + "; ".join(findings) + ".", findings,
                             threshold)
    if open_kinds:
        return SafetyVerdict(UNDECIDED, f"Not shown above or below {limit}: "
                             + "; ".join(open_kinds) + " (more runs would decide).", [],
                             threshold)
    kinds = ", ".join(FAILURES[k] for k in UNSAFE_KINDS)
    return SafetyVerdict(SAFE, f"Every counted failure ({kinds}) is below {limit}, with 95% "
                         "confidence (timeouts and pedestrians walking into the standing robot "
                         "are reported, not counted).", [], threshold)
