"""The card's safety verdict: which failure, how often, and against the baselines.

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
  with it);
* the verdict: the controller is **less safe than the baselines** on a kind when its paired
  difference to the least safe baseline on that kind (the most lenient reference) has its
  whole interval above 0. An absolute threshold on the share of runs is an explicit option
  (``threshold``), off by default; without baselines it is the only rule.

Who moved into whom: the runs table records the robot's speed at the contact that ended
its run (``contact_speed``); a pedestrian collision with the robot slower than 0.05 m/s is
a pedestrian walking into a standing robot, reported on its own line and never counted
as unsafe.
"""

from __future__ import annotations

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


def safety_findings(rates: pd.DataFrame, diffs: pd.DataFrame, controller: str,
                    baselines: list[str], threshold: float | None = None) -> list[str]:
    """One sentence per unsafe finding (empty when safe): the kind, its rate and interval,
    the baselines' rates, the difference to the least safe baseline with its interval, and
    the scene where it is highest. Module doc for the rule."""
    out = []
    overall = rates[rates["scope"] == "all"].set_index(["kind", "controller"])
    for kind in UNSAFE_KINDS:
        own = overall.loc[(kind, controller)]
        base = {b: overall.loc[(kind, b)] for b in baselines if (kind, b) in overall.index}
        reason = ""
        if base:
            worst = max(base, key=lambda b: base[b]["rate"])
            d = diffs[(diffs["kind"] == kind) & (diffs["scope"] == "all")
                      & (diffs["baseline"] == worst)]
            if not d.empty and d["low"].iloc[0] > 0:
                r = d.iloc[0]
                reason = (f"+{100 * r['difference']:.1f} pp [{100 * r['low']:+.1f}, "
                          f"{100 * r['high']:+.1f}] over the least safe baseline, {worst}, on "
                          f"the same {r['pairs']:,} runs")
        if not reason and threshold is not None and own["rate"] > threshold:
            reason = f"above the threshold of {100 * threshold:.0f}% of its runs"
        if not reason:
            continue
        scenes = rates[(rates["kind"] == kind) & (rates["controller"] == controller)
                       & (rates["scope"] != "all")]
        top = scenes.loc[scenes["rate"].idxmax()] if len(scenes) else None
        where = (f"; highest in {top['scope']} ({100 * top['rate']:.1f}% of its runs there)"
                 if top is not None and top["failures"] else "")
        beside = ", ".join(f"{b} {100 * v['rate']:.1f}%" for b, v in base.items())
        out.append(f"{FAILURES[kind]} in {100 * own['rate']:.1f}% of its {int(own['runs']):,} "
                   f"runs [{100 * own['low']:.1f}, {100 * own['high']:.1f}]"
                   + (f" (baselines: {beside})" if beside else "") + f": {reason}{where}")
    return out
