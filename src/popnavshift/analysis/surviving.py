"""The paper's findings under the significance rule: which survive the episode noise?

:func:`popnavshift.analysis.findings.paper_findings` checks each qualitative claim
of the paper on point estimates. Here each claim that is a comparison of grid
statistics is re-checked on the paired episode bootstrap (:mod:`.resample`): its
statistic (a difference that is positive when the claim holds, or a ratio that
must lie in a band) gets an interval at ``level`` — centred on the estimate, its width
from the resamples (:func:`.nulls.centred_interval`: a resample that repeats an episode
shifts tail statistics, so percentile intervals can miss the estimate) — and the claim
**survives** when the whole interval agrees with it. The reversal-rate claims ("burden reverses more
than robot time") are checked against their nulls in :mod:`.nulls`
(:func:`burden_beyond_time`), because every null reproduces that ordering too.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from functools import partial

import numpy as np
import pandas as pd

from ..paper import PAPER_CONTROLLERS
from ..populations.identity import MATCHED_PAIR
from ..tables import NO_ROBOT
from .delay import CELL_KEY, cell_metrics, episode_cells, paired_delays
from .findings import TAIL_BAND, WIDTH_SCENES
from .nulls import centred_interval
from .paper_reference import MATCHED_CHANGE_SIGN
from .resample import build_design, episode_weights, resampled_metrics
from .significance import LEVEL
from .verdicts import ABOVE, BELOW, SMALL

METRICS_NEEDED = ("mean_delay", "worst_decile", "success_share", "timeout_share")


def _controller_means(cells: pd.DataFrame, values: np.ndarray) -> dict[str, np.ndarray]:
    """Per controller: the mean over its (cell, population) rows of ``values``, (R,) for
    the point estimate or (B, R) for the resamples; NaN-skipping."""
    out = {}
    for ctrl, idx in cells.groupby("controller").indices.items():
        with np.errstate(all="ignore"):
            out[ctrl] = np.nanmean(values[..., idx], axis=-1)
    return out


def _width_gap(cells: pd.DataFrame, values: np.ndarray, scenes: tuple[str, ...]) -> np.ndarray:
    """Mean population range of mean delay at the narrowest minus the widest width [s],
    over the (cell, controller) rows of ``scenes`` where every population has a value."""
    sel = cells["scene"].isin(scenes).to_numpy()
    sub = cells[sel].reset_index(drop=True).assign(i=np.flatnonzero(sel))
    pos = sub.pivot(index=["backend", "mapping", "cell", "controller"], columns="population",
                    values="i")
    widths = sub.drop_duplicates(["backend", "mapping", "cell"]).set_index(
        ["backend", "mapping", "cell"])["width"]
    pos = pos.dropna()
    w = widths.reindex(pos.index.droplevel("controller")).to_numpy(float)
    idx = pos.to_numpy(np.int64)
    v = values[..., idx]  # (..., rows, populations)
    with np.errstate(all="ignore"):
        rng = np.nanmax(v, axis=-1) - np.nanmin(v, axis=-1)
        rng = np.where(np.isnan(v).any(axis=-1), np.nan, rng)
        lo, hi = w.min(), w.max()
        return np.nanmean(rng[..., w == lo], axis=-1) - np.nanmean(rng[..., w == hi], axis=-1)


def _matched_change(cells: pd.DataFrame, values: np.ndarray, controller: str) -> np.ndarray:
    """Mean over units of deadline − base mean delay for ``controller`` [s]."""
    sub = cells[cells["controller"] == controller]
    pos = sub.assign(i=sub.index).pivot(index=["backend", "mapping", "cell"],
                                        columns="population", values="i")
    pos = pos.reindex(columns=list(MATCHED_PAIR)).dropna().to_numpy(np.int64)
    with np.errstate(all="ignore"):
        return np.nanmean(values[..., pos[:, 1]] - values[..., pos[:, 0]], axis=-1)


def _matched_change_of(cells: pd.DataFrame, controller: str, vals: dict) -> np.ndarray:
    return _matched_change(cells, vals["mean_delay"], controller)


def _tail_ratio_of(cells: pd.DataFrame, controller: str, vals: dict) -> np.ndarray:
    worst = _controller_means(cells, vals["worst_decile"])[controller]
    return worst / _controller_means(cells, vals["mean_delay"])[controller]


def surviving_findings(runs: pd.DataFrame, pedestrians: pd.DataFrame, *,
                       rng: np.random.Generator, n_boot: int = 1000,
                       level: float = LEVEL) -> pd.DataFrame:
    """The paper's controller, width, tail and matched-direction findings with intervals.

    One row per finding: ``finding`` (the key of the paper's finding it checks, as
    :class:`popnavshift.analysis.findings.Finding`), ``statement``, ``statistic`` (what
    is estimated),
    ``estimate``, ``ci_low``, ``ci_high``, ``holds`` (on the point estimate, as in
    :func:`popnavshift.analysis.findings.paper_findings`) and ``survives`` (the whole
    interval agrees). Findings whose inputs are absent are left out.
    """
    paired = paired_delays(pedestrians)
    cells = cell_metrics(runs, paired)
    design = build_design(runs, paired)
    boot = resampled_metrics(design, episode_weights(design, n_boot, rng), METRICS_NEEDED)
    cells = cells.assign(timeout_share=design_share(runs, cells, "timeout"))
    point = {m: cells[m].to_numpy(float) for m in METRICS_NEEDED}
    checks: list[tuple[str, str, Callable[[dict], np.ndarray], tuple[float, float], str]] = []
    ctrls = set(cells["controller"])

    def extreme(column: str, ctrl: str, highest: bool) -> Callable[[dict], np.ndarray]:
        def f(vals: dict) -> np.ndarray:
            means = _controller_means(cells, vals[column])
            others = np.nanmax if highest else np.nanmin
            rest = others(np.stack([v for c, v in means.items() if c != ctrl]), axis=0)
            return means[ctrl] - rest if highest else rest - means[ctrl]
        return f

    if set(PAPER_CONTROLLERS) <= ctrls:
        checks += [
            ("Reactive has the highest success rate", "success share gap to the next [pp]",
             lambda v: 100 * extreme("success_share", "reactive", True)(v), (0, np.inf),
             "extreme:reactive:success_pct"),
            ("Early yielding has the highest timeout rate", "timeout share gap [pp]",
             lambda v: 100 * extreme("timeout_share", "early_yield", True)(v), (0, np.inf),
             "extreme:early_yield:timeout_pct"),
            ("Robot-ORCA has the lowest mean delay", "next lowest minus Robot-ORCA [s]",
             extreme("mean_delay", "robot_orca", False), (0, np.inf),
             "extreme:robot_orca:mean_delay"),
            ("Robot-ORCA has the lowest worst-decile delay", "next lowest minus Robot-ORCA [s]",
             extreme("worst_decile", "robot_orca", False), (0, np.inf),
             "extreme:robot_orca:worst_decile"),
            ("Early yielding has a lower mean delay than reactive", "reactive − early yield [s]",
             lambda v: (lambda m: m["reactive"] - m["early_yield"])(
                 _controller_means(cells, v["mean_delay"])), (0, np.inf),
             "extreme:early_yield:mean_delay"),
        ]
    for ctrl, sign in MATCHED_CHANGE_SIGN.items():
        if ctrl in ctrls and set(MATCHED_PAIR) <= set(cells["population"]):
            word = "lowers" if sign < 0 else "raises"
            checks.append((f"The matched deadline shift {word} {ctrl}'s mean delay",
                           "deadline − base mean delay [s]",
                           partial(_matched_change_of, cells, ctrl),
                           (-np.inf, 0) if sign < 0 else (0, np.inf), "matched_direction"))
    if cells["population"].nunique() >= 2 and cells["scene"].isin(WIDTH_SCENES).any():
        checks.append(("Population sensitivity is larger at the narrowest width (sidewalks and "
                       "bottlenecks)", "sensitivity at narrowest − widest width [s]",
                       lambda v: _width_gap(cells, v["mean_delay"], WIDTH_SCENES), (0, np.inf),
                       "width:pooled"))
    for ctrl in sorted(ctrls):
        checks.append((f"Worst-decile delay is about 4× the mean delay ({ctrl})",
                       "worst decile / mean delay",
                       partial(_tail_ratio_of, cells, ctrl), TAIL_BAND, "tail_ratio"))
    n_episodes = float(design.episodes.groupby("cell").size().median())
    rows = []
    for statement, statistic, f, (lo, hi), key in checks:
        with warnings.catch_warnings():  # empty selections give NaN: a finding not decided
            warnings.simplefilter("ignore", RuntimeWarning)
            est = float(f(point))
            b = np.asarray(f(boot), dtype=float)
        b = b[np.isfinite(b)]
        ci = centred_interval(est, b, level, n_episodes)
        rows.append({"finding": key, "statement": statement, "statistic": statistic,
                     "estimate": est,
                     "ci_low": float(ci[0]), "ci_high": float(ci[1]),
                     "holds": bool(lo < est < hi),
                     "survives": bool(lo < ci[0] and ci[1] < hi)})
    return pd.DataFrame(rows)


#: A reversal finding's label (:func:`.findings.burden_exceeds_time`) → the headline
#: comparison whose null tests it (:func:`.nulls.burden_beyond_time`).
BURDEN_COMPARISON = {"matched, all cells": "matched", "all pairs, all cells": "all_pairs"}


def findings_list(findings: pd.DataFrame, surviving: pd.DataFrame | None,
                  burden: pd.DataFrame | None) -> pd.DataFrame:
    """The paper's findings, each once (the point-estimate table of :mod:`.findings`, with
    its ``key``): ``holds`` on the point estimate and, where it can be judged beyond noise,
    ``judged_by`` (its paired-bootstrap interval, or its null for a reversal finding),
    ``survives`` (True / False; NaN when undecided or not judged) and ``evidence``."""
    rows = []
    for f in findings.itertuples(index=False):
        key = str(getattr(f, "key", "") or "")
        row = {"statement": f.statement, "holds": bool(f.holds), "judged_by": "point estimate only",
               "survives": np.nan, "evidence": ""}
        kind, _, label = key.partition(":")
        comp = BURDEN_COMPARISON.get(label) if kind == "burden_vs_time" else None
        if comp and burden is not None and not burden.empty:
            b = burden[(burden["comparison"] == comp) & (burden["rule"] == "raw")
                       & (burden["metric"] == "mean_delay")]
            if not b.empty:
                r = b.iloc[0]
                row.update(judged_by="its null (burden − robot-time rate over the null's)",
                           survives={ABOVE: True, BELOW: False, SMALL: False}.get(r["verdict"],
                                                                                   np.nan),
                           evidence=f"excess {100 * r['excess']:+.1f} pp [{100 * r['ci_low']:+.1f},"
                                    f" {100 * r['ci_high']:+.1f}]: {r['verdict']}")
        elif surviving is not None and not surviving.empty and "finding" in surviving:
            sv = surviving[surviving["finding"] == key]
            if not sv.empty:
                row.update(judged_by="its 90% paired-bootstrap interval",
                           survives=bool(sv["survives"].all()),
                           evidence="; ".join(f"{x.statistic} = {x.estimate:.2f} "
                                              f"[{x.ci_low:.2f}, {x.ci_high:.2f}]"
                                              for x in sv.itertuples()))
        rows.append(row)
    return pd.DataFrame(rows, columns=["statement", "holds", "judged_by", "survives", "evidence"])


def design_share(runs: pd.DataFrame, cells: pd.DataFrame, outcome: str) -> np.ndarray:
    """Per cell-metrics row, the share of its runs ending in ``outcome`` (aligned)."""
    eps = episode_cells(runs)[["episode", "cell"]]
    r = runs[runs["controller"] != NO_ROBOT].merge(eps, on="episode")
    share = (r.assign(x=(r["outcome"] == outcome).astype(float))
             .groupby(list(CELL_KEY))["x"].mean())
    return share.reindex(pd.MultiIndex.from_frame(cells[list(CELL_KEY)])).to_numpy(float)
