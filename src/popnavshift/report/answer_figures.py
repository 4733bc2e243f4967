"""The answer's figures: observed rates against every null replicate, and rates against
seed sets. Pure functions of the ``evidence_*`` tables."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
matplotlib.rcParams["text.parse_math"] = False  # a label is data: "$" is no math
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from ..analysis.ranked import RANKED_NAMES  # noqa: E402
from ..analysis.reversals import COMPARISONS  # noqa: E402
from ..populations.figures import save_figure  # noqa: E402
from .plain import LABELS  # noqa: E402

METRICS: tuple[str, ...] = RANKED_NAMES
RULE_TITLES = {"raw": "raw rule (decides)", "sig": "significant rule"}


def plot_nulls(head: pd.DataFrame, null_rates: pd.DataFrame) -> plt.Figure:
    """Per comparison (columns) and rule (rows, the deciding raw rule first): observed rate
    per metric (red diamond), every null replicate (grey dots) and the null mean (line);
    rates in % of comparable comparisons."""
    comps = [c for c in COMPARISONS if (head["comparison"] == c).any()]
    metrics = [m for m in METRICS if m in set(head["metric"])]
    fig, axes = plt.subplots(2, len(comps), figsize=(5.0 * len(comps), 6.0), squeeze=False)
    x = np.arange(len(metrics))
    for j, comp in enumerate(comps):
        for i, rule in enumerate(("raw", "sig")):
            ax = axes[i][j]
            shown = False
            for k, m in enumerate(metrics):
                sel = null_rates[(null_rates["comparison"] == comp) & (null_rates["metric"] == m)
                                 & (null_rates["rule"] == rule)]
                nr = sel["rate"].to_numpy(float) * 100
                shown |= bool(np.isfinite(nr).any())
                jitter = np.linspace(-0.15, 0.15, max(len(nr), 1))[: len(nr)]
                ax.scatter(k + jitter, nr, s=9, color="#999999", zorder=2,
                           label="null replicates" if k == 0 else None)
                if np.isfinite(nr).any():
                    ax.hlines(np.nanmean(nr), k - 0.3, k + 0.3, color="#555555", lw=2,
                              label="null mean" if k == 0 else None)
                obs = head[(head["comparison"] == comp) & (head["metric"] == m)
                           & (head["rule"] == rule)]
                if not obs.empty and np.isfinite(obs["observed"].iloc[0]):
                    shown = True
                    ax.scatter([k], [100 * obs["observed"].iloc[0]], marker="D", s=40,
                               color="#C44E52", zorder=3, label="observed" if k == 0 else None)
            ax.set_xticks(x, [LABELS[m] for m in metrics], fontsize=8)
            ax.set_xlim(-0.6, len(metrics) - 0.4)
            ax.set_title(f"{COMPARISONS[comp].short} — {RULE_TITLES[rule]}", fontsize=9)
            ax.grid(axis="y", alpha=0.3)
            ax.set_ylabel("reversals (% of comparable)", fontsize=8)
            if not shown:  # an empty axis would read as rates of 0 ± 0.04
                ax.set_yticks([])
                ax.text(0.5, 0.5, "no rate: no ordering could be compared\nunder this rule "
                        "(see the table)", ha="center", va="center", transform=ax.transAxes,
                        fontsize=8, color="#555555")
    axes[0][0].legend(fontsize=7)
    fig.tight_layout()
    return fig


def plot_curve(curve: pd.DataFrame) -> plt.Figure:
    """Raw reversal rate (the deciding rule) against variants per cell, observed vs the
    null's mean and range, one row per comparison run on several seed sets."""
    comps = [c for c in COMPARISONS if (curve["comparison"] == c).any()]
    metrics = [m for m in METRICS if m in set(curve["metric"])]
    fig, axes = plt.subplots(len(comps), len(metrics), figsize=(3.4 * len(metrics),
                                                                 3.0 * len(comps)),
                             squeeze=False, sharey="row")
    for i, comp in enumerate(comps):
        for ax, m in zip(axes[i], metrics, strict=True):
            c = curve[(curve["comparison"] == comp) & (curve["metric"] == m)
                      & (curve["rule"] == "raw")].sort_values("seed_sets")
            v = c["variants_per_cell"].to_numpy()
            ax.plot(v, 100 * c["observed"], marker="o", color="#C44E52", label="observed")
            ax.plot(v, 100 * c["null_mean"], ls="--", marker=".", color="#555555",
                    label="null mean")
            ax.fill_between(v, 100 * c["null_min"], 100 * c["null_max"], color="#999999",
                            alpha=0.25, label="null range")
            ax.set_title(f"{COMPARISONS[comp].short}: {LABELS[m]}", fontsize=8)
            ax.set_xlabel("variants per cell (3 per seed set)", fontsize=8)
            ax.set_xticks(v)
            ax.grid(alpha=0.3)
        axes[i][0].set_ylabel("raw reversals (%)", fontsize=8)
    axes[0][0].legend(fontsize=7)
    fig.tight_layout()
    return fig


def write_answer_figures(tables: dict[str, pd.DataFrame], out: Path) -> dict[str, Path]:
    """The evidence figures the tables allow, as PNG + SVG in ``out``; name → PNG path."""
    paths = {}
    head, nulls = tables.get("evidence_headline"), tables.get("evidence_null_rates")
    if head is not None and nulls is not None and not head.empty:
        paths["evidence_nulls"] = save_figure(plot_nulls(head, nulls), out / "evidence_nulls")[0]
    curve = tables.get("evidence_curve")
    if curve is not None and not curve.empty and curve["seed_sets"].nunique() > 1:
        paths["evidence_curve"] = save_figure(plot_curve(curve), out / "evidence_curve")[0]
    return paths
