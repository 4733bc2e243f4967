"""Analysis figures of the report: each a pure function from tables to a matplotlib figure.

Reversal rates (Table I, with the paper's values), change in delay (Fig. 2),
population sensitivity by width (Fig. 4), Kendall τ between population rankings,
and the robot-time vs pedestrian-delay trade-off per population. ``write_figures``
saves the ones an :class:`~popnavshift.analysis.study.Analysis` can draw, as PNG and SVG;
``profile_figures`` brings in the population stage's Fig. 3.
"""

from __future__ import annotations

import shutil
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import matplotlib

matplotlib.use("Agg")
matplotlib.rcParams["text.parse_math"] = False  # a label is data: "$" is no math
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
from matplotlib.patches import Rectangle  # noqa: E402

from ..analysis import METRICS, RANKED_METRICS  # noqa: E402
from ..analysis.paper_reference import WIDTH_SENSITIVITY  # noqa: E402
from ..analysis.reversals import COMPARISONS  # noqa: E402
from ..analysis.study import CHANGE_METRICS  # noqa: E402
from ..analysis.summary import controller_order  # noqa: E402
from ..populations.build import POPULATION_GROUPS, population_order  # noqa: E402
from ..populations.figures import save_figure, write_profile_figures  # noqa: E402
from ..populations.identity import MATCHED_PAIR  # noqa: E402
from ..viz.style import controller_label, controller_style  # noqa: E402

if TYPE_CHECKING:
    from ..analysis.study import Analysis

METRIC_LABELS = {m.name: m.title for m in RANKED_METRICS}
#: Fig. 2 row groups, top to bottom: matched pair, source-field cohorts, mixed, probe cohorts.
CHANGE_GROUPS: tuple[tuple[str, ...], ...] = (
    (MATCHED_PAIR[1],), POPULATION_GROUPS["source-field"], ("mixed",),
    POPULATION_GROUPS["probe-defined"])


def pop_label(name: str) -> str:
    return name.replace("_", " ")


# --- Table I as bars ---------------------------------------------------------------------------


def plot_reversal_rates(table: pd.DataFrame) -> plt.Figure:
    """Reversal rate per metric with its bootstrap interval, all vs completed cells; the paper's
    value as a black diamond and, where the study ran one, the null's rate as a red line.
    One panel per comparison (matched pair, all pairs)."""
    comps = [c for c in COMPARISONS if (table["comparison"] == c).any()]
    fig, axes = plt.subplots(1, len(comps), figsize=(5.2 * len(comps), 3.6), squeeze=False,
                             sharey=True)
    x = np.arange(len(METRICS))
    for ax, comp in zip(axes[0], comps, strict=True):
        for k, (scope, colour) in enumerate((("all", "#4C72B0"), ("completed", "#8FB3DE"))):
            t = table[(table["comparison"] == comp) & (table["cells"] == scope)]
            t = t.set_index("metric").reindex(list(METRICS))
            rate = t["rate"].to_numpy(float) * 100
            err = np.abs(np.vstack([t["ci_low"], t["ci_high"]]) * 100 - rate)
            xs = x + (k - 0.5) * 0.38
            ax.bar(xs, rate, 0.36, color=colour, label=f"ours, {scope} cells")
            ax.errorbar(xs, rate, yerr=np.nan_to_num(err), fmt="none", ecolor="#333", capsize=3)
            paper = t["paper_rate"].to_numpy(float) * 100
            ax.scatter(xs, paper, marker="D", color="black", zorder=3,
                       label="paper" if k == 0 else None)
            if "null_rate" in t and t["null_rate"].notna().any():
                null = t["null_rate"].to_numpy(float) * 100
                ax.hlines(null, xs - 0.2, xs + 0.2, color="#C44E52", lw=2.5, zorder=4,
                          label="null at the same design")
        ax.set_xticks(x, [METRIC_LABELS[m] for m in METRICS], fontsize=8)
        ax.set_title(COMPARISONS[comp].short, fontsize=10)
        ax.grid(axis="y", alpha=0.3)
    axes[0][0].set_ylabel("ranking reversals (% of comparable)")
    axes[0][-1].legend(fontsize=7, loc="upper left")
    fig.tight_layout()
    return fig


# --- Fig. 2: change in delay -------------------------------------------------------------------


def change_rows(populations: Sequence[str]) -> tuple[list[str], list[int]]:
    """Fig. 2 row order of the populations present, and the row indices after which a group ends."""
    rows: list[str] = []
    breaks: list[int] = []
    for group in CHANGE_GROUPS:
        got = [p for p in group if p in populations]
        if got and rows:
            breaks.append(len(rows))
        rows += got
    extra = sorted(set(populations) - set(rows))
    if extra and rows:
        breaks.append(len(rows))
    return rows + extra, breaks


def plot_delay_change(change: pd.DataFrame) -> plt.Figure:
    """Heatmap population × controller of shifted − reference delay [s], one panel per metric.

    The matched row (deadline − base, same personas) is outlined; white lines
    separate the matched pair, source-field cohorts, mixed and probe cohorts.
    """
    metrics = [m for m in CHANGE_METRICS if (change["metric"] == m).any()]
    rows, breaks = change_rows(sorted(change["population"].unique()))
    ctrls = controller_order(change["controller"].unique())
    vmax = float(np.nanmax(np.abs(change["change"].to_numpy(float)))) or 1.0
    fig, axes = plt.subplots(1, len(metrics), figsize=(4.2 * len(metrics) + 1.5,
                                                       0.55 * len(rows) + 1.6), squeeze=False)
    im = None
    for ax, metric in zip(axes[0], metrics, strict=True):
        c = change[change["metric"] == metric]
        grid = c.pivot(index="population", columns="controller", values="change")
        grid = grid.reindex(index=rows, columns=ctrls)
        refs = c.drop_duplicates("population").set_index("population")["reference"]
        im = ax.imshow(grid.to_numpy(float), cmap="RdBu_r", vmin=-vmax, vmax=vmax, aspect="auto")
        for i, j in np.ndindex(grid.shape):
            v = grid.iat[i, j]
            ax.text(j, i, "–" if np.isnan(v) else f"{v:+.2f}", ha="center", va="center",
                    fontsize=8, color="white" if abs(v) > 0.6 * vmax else "black")
        for b in breaks:
            ax.axhline(b - 0.5, color="white", lw=4)
        if MATCHED_PAIR[1] in rows:
            i = rows.index(MATCHED_PAIR[1])
            ax.add_patch(Rectangle((-0.5, i - 0.5), len(ctrls), 1, fill=False, lw=2.5,
                                   edgecolor="black"))
        ax.set_xticks(range(len(ctrls)), [controller_label(k) for k in ctrls], fontsize=8)
        labels = [f"{pop_label(p)} − {pop_label(refs.get(p, '?'))}" for p in rows]
        ax.set_yticks(range(len(rows)), labels if ax is axes[0][0] else [], fontsize=8)
        ax.set_title(METRIC_LABELS[metric], fontsize=10)
    if im is not None:
        fig.colorbar(im, ax=axes[0].tolist(), label="shifted − reference delay (s)", shrink=0.9)
    return fig


# --- Fig. 4: population sensitivity by width -------------------------------------------------


def plot_width_sensitivity(by_width: pd.DataFrame) -> plt.Figure:
    """Mean range of mean delay across populations per width [s]: (a) sidewalks, (b) bottlenecks.

    ``by_width`` is the report's ``sensitivity_by_width`` table (all cells are
    drawn, completed cells dotted); the paper's pooled end points are black stars.
    """
    scenes = [s for s in ("sidewalk", "bottleneck") if (by_width["scenes"] == s).any()]
    fig, axes = plt.subplots(1, len(scenes), figsize=(5.0 * len(scenes), 3.6), squeeze=False,
                             sharey=True)
    ctrls = [*controller_order(sorted(set(by_width["controller"]) - {"pooled"})), "pooled"]
    for ax, scene, tag in zip(axes[0], scenes, "ab", strict=False):
        s = by_width[by_width["scenes"] == scene]
        for c in ctrls:
            look = controller_style(c)
            for cells, style in (("all", "-"), ("completed", ":")):
                d = s[(s["controller"] == c) & (s["cells"] == cells)].sort_values("width")
                if d.empty:
                    continue
                ax.plot(d["width"], d["sensitivity"], style, marker=look.marker, ms=4,
                        lw=2.2 if c == "pooled" else 1.4, color=look.colour,
                        label=f"{controller_label(c)}" if cells == "all" else None)
        ws = sorted(WIDTH_SENSITIVITY)
        ax.scatter(ws, [WIDTH_SENSITIVITY[w] for w in ws], marker="*", s=120,
                   color="black", zorder=4, label="paper (pooled, both scenes)")
        ax.set_title(f"({tag}) {scene}s", fontsize=10)
        ax.set_xlabel("width (m)")
        ax.grid(alpha=0.3)
    axes[0][0].set_ylabel("population sensitivity of mean delay (s)")
    axes[0][-1].legend(fontsize=7, title="solid: all cells, dotted: completed", title_fontsize=7)
    fig.tight_layout()
    return fig


# --- Kendall τ ---------------------------------------------------------------------------------


def tau_matrix(tau: pd.DataFrame, metric: str) -> pd.DataFrame:
    """Symmetric population × population mean τ-b for ``metric`` (diagonal 1)."""
    t = tau[tau["metric"] == metric]
    pops = population_order(set(t["pop_a"]) | set(t["pop_b"]))
    m = pd.DataFrame(np.eye(len(pops)), index=pops, columns=pops)
    for r in t.itertuples(index=False):
        m.loc[r.pop_a, r.pop_b] = m.loc[r.pop_b, r.pop_a] = r.tau
    return m


def plot_tau(tau: pd.DataFrame) -> plt.Figure:
    """Mean Kendall τ-b between the controller rankings of two populations, one panel per metric."""
    metrics = [m for m in METRICS if (tau["metric"] == m).any()]
    n = len(tau_matrix(tau, metrics[0]))
    fig, axes = plt.subplots(1, len(metrics), figsize=(0.55 * n * len(metrics) + 3, 0.55 * n + 1.8),
                             squeeze=False)
    im = None
    for ax, metric in zip(axes[0], metrics, strict=True):
        m = tau_matrix(tau, metric)
        im = ax.imshow(m.to_numpy(float), cmap="RdBu", vmin=-1, vmax=1)
        for i, j in np.ndindex(m.shape):
            ax.text(j, i, f"{m.iat[i, j]:.2f}", ha="center", va="center", fontsize=7)
        labels = [pop_label(p) for p in m.index]
        ax.set_xticks(range(len(m)), labels, rotation=45, ha="right", fontsize=7)
        ax.set_yticks(range(len(m)), labels if ax is axes[0][0] else [], fontsize=7)
        ax.set_title(METRIC_LABELS[metric], fontsize=10)
    if im is not None:
        fig.colorbar(im, ax=axes[0].tolist(), label="mean Kendall τ-b over cells", shrink=0.8)
    return fig


# --- Trade-off per population ----------------------------------------------------------------


def plot_tradeoff(tradeoff: pd.DataFrame) -> plt.Figure:
    """Per population: robot travel time [s] vs mean (●) and worst-decile (▲) delay [s]."""
    pops = population_order(tradeoff["population"])
    ncol = min(4, len(pops))
    nrow = -(-len(pops) // ncol)
    fig, axes = plt.subplots(nrow, ncol, figsize=(3.2 * ncol, 2.6 * nrow + 0.6), squeeze=False,
                             sharex=True, sharey=True)
    ctrls = controller_order(tradeoff["controller"].unique())
    for ax, pop in zip(axes.flat, pops, strict=False):
        t = tradeoff[tradeoff["population"] == pop].set_index("controller")
        for c in ctrls:
            if c not in t.index:
                continue
            x, lo, hi = t.at[c, "robot_time"], t.at[c, "mean_delay"], t.at[c, "worst_decile"]
            col = controller_style(c).colour  # markers say the metric here: ● mean, ▲ tail
            ax.plot([x, x], [lo, hi], color=col, lw=1, alpha=0.6)
            ax.scatter([x], [lo], color=col, marker="o", label=controller_label(c))
            ax.scatter([x], [hi], color=col, marker="^")
        ax.set_title(pop_label(pop), fontsize=9)
        ax.grid(alpha=0.3)
    for ax in axes.flat[len(pops):]:
        ax.set_visible(False)
    fig.supylabel("pedestrian delay (s): ● mean, ▲ worst decile", fontsize=9)
    fig.supxlabel("robot travel time (s)", fontsize=9)
    axes.flat[0].legend(fontsize=7)
    fig.tight_layout()
    return fig


# --- Writing -----------------------------------------------------------------------------------

PROFILE_FIGURES = ("fig3a_profiles", "fig3b_matched_shift")


def profile_figures(src: Path, populations: pd.DataFrame | None,
                    out: Path) -> tuple[dict[str, Path], str]:
    """Fig. 3 (profiles) into ``out``: copied from the study's ``src`` folder, else redrawn
    from the populations table (Mapping A). Returns name → PNG path, and why they are
    missing when they are."""
    out.mkdir(parents=True, exist_ok=True)
    if (src / f"{PROFILE_FIGURES[0]}.png").exists():
        for path in (src / f"{n}.{ext}" for n in PROFILE_FIGURES for ext in ("png", "svg")):
            if path.exists():
                shutil.copyfile(path, out / path.name)
    elif populations is not None:
        mapping_a = populations[populations["mapping"] == "A"]
        write_profile_figures(mapping_a if len(mapping_a) else populations, out)
    else:
        return {}, "the folder has neither figures/ nor populations.parquet"
    return {n: out / f"{n}.png" for n in PROFILE_FIGURES if (out / f"{n}.png").exists()}, ""


def write_figures(a: Analysis, out: Path) -> dict[str, Path]:
    """Draw every figure ``a`` has the tables for into ``out`` (PNG + SVG); name → PNG path."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    plots = {
        "reversal_rates": ("reversals", plot_reversal_rates),
        "fig2_delay_change": ("delay_change", plot_delay_change),
        "fig4_width_sensitivity": ("sensitivity_by_width", plot_width_sensitivity),
        "kendall_tau": ("kendall_tau", plot_tau),
        "tradeoff": ("tradeoff", plot_tradeoff),
    }
    paths = {}
    for name, (table, plot) in plots.items():
        if table in a.tables and not a.tables[table].empty:
            paths[name] = save_figure(plot(a.tables[table]), out / name)[0]
    return paths
