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

import numpy as np
import pandas as pd

from ..populations.identity import MATCHED_PAIR
from ..tables import NO_ROBOT
from .cells import CELL_KEY, episode_cells
from .delay import cell_metrics, paired_delays
from .findings import CLAIM_BY_KEY, CLAIMS, WIDTH_SCENES, controller_needs
from .nulls import centred_interval
from .resample import build_design, episode_weights, resampled_metrics
from .significance import LEVEL
from .verdicts import ABOVE, BELOW, SMALL

METRICS_NEEDED = ("mean_delay", "worst_decile", "success_share", "timeout_share")


def _inputs_present(cells: pd.DataFrame) -> set[str]:
    """The :attr:`.findings.Claim.needs` the cell table can serve an interval for."""
    ctrls, pops = set(cells["controller"]), set(cells["population"])
    have = {"pairs", "delays", *controller_needs(ctrls)}
    if set(MATCHED_PAIR) <= pops:
        have.add("matched")
    if len(pops) >= 2 and cells["scene"].isin(WIDTH_SCENES).any():
        have.add("width:pooled")
    return have


def surviving_findings(runs: pd.DataFrame, pedestrians: pd.DataFrame, *,
                       rng: np.random.Generator, n_boot: int = 1000,
                       level: float = LEVEL) -> pd.DataFrame:
    """The paper's findings that have an :class:`.findings.Interval`, with intervals.

    One row per finding (per controller for a per-controller one): ``finding`` (its
    ``Claim.key``), ``controller`` (or empty), ``statement``, ``statistic`` (what is
    estimated), ``estimate``, ``ci_low``, ``ci_high``, ``holds`` (the estimate is in the
    claim's band) and ``survives`` (the whole interval is). Findings whose inputs are
    absent are left out.
    """
    paired = paired_delays(pedestrians)
    cells = cell_metrics(runs, paired)
    design = build_design(runs, paired)
    boot = resampled_metrics(design, episode_weights(design, n_boot, rng), METRICS_NEEDED)
    cells = cells.assign(timeout_share=design_share(runs, cells, "timeout"))
    point = {m: cells[m].to_numpy(float) for m in METRICS_NEEDED}
    have, ctrls = _inputs_present(cells), set(cells["controller"])
    n_episodes = float(design.episodes.groupby("cell").size().median())
    rows = []
    for claim in CLAIMS:
        iv = claim.interval
        if iv is None or not claim.needs <= have:
            continue
        for ctrl in (None,) if iv.per_controller is None else iv.per_controller(ctrls):
            with warnings.catch_warnings():  # empty selections give NaN: a finding not decided
                warnings.simplefilter("ignore", RuntimeWarning)
                est = float(iv.value(cells, point, ctrl))
                b = np.asarray(iv.value(cells, boot, ctrl), dtype=float)
            b = b[np.isfinite(b)]
            ci = centred_interval(est, b, level, n_episodes)
            lo, hi = iv.band(ctrl)
            rows.append({"finding": claim.key, "controller": ctrl or "",
                         "statement": claim.statement, "statistic": iv.statistic,
                         "estimate": est, "ci_low": float(ci[0]), "ci_high": float(ci[1]),
                         "holds": bool(lo < est < hi),
                         "survives": bool(lo < ci[0] and ci[1] < hi)})
    return pd.DataFrame(rows, columns=["finding", "controller", "statement", "statistic",
                                       "estimate", "ci_low", "ci_high", "holds", "survives"])


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
        claim = CLAIM_BY_KEY.get(key)
        comp = claim.null if claim is not None else None
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
                           evidence="; ".join(f"{x.controller + ': ' if x.controller else ''}"
                                              f"{x.statistic} = {x.estimate:.2f} "
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
