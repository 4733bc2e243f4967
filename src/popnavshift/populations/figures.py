"""Profile figures like the paper's Fig. 3.

(a) median position of each parameter within its physical range, per population
(labels give cohort sizes); (b) base vs deadline distributions of each parameter
for the same matched personas. Written as PNG and SVG.
"""

from __future__ import annotations

from functools import partial
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
matplotlib.rcParams["text.parse_math"] = False  # a label is data: "$" is no math
import matplotlib.pyplot as plt  # noqa: E402
import pandas as pd  # noqa: E402

from ..io import write_atomic  # noqa: E402
from ..tables import PARAM_RANGES, PARAMS  # noqa: E402
from .build import POPULATION_GROUPS, POPULATIONS, population_sizes  # noqa: E402
from .identity import MATCHED_PAIR  # noqa: E402

PARAM_LABELS = {
    "speed_mps": "speed v",
    "clearance_m": "clearance d",
    "avoidance_gain": "avoidance a",
    "yield_fraction": "yielding y",
    "reaction_delay_s": "reaction τ",
    "detour_distance_m": "detour L",
    "gap_acceptance": "gap accept. g",
}


def median_positions(populations: pd.DataFrame) -> pd.DataFrame:
    """Population × parameter: median position within the parameter's range, in [0, 1]."""
    med = populations.groupby("population")[list(PARAMS)].median()
    for p in PARAMS:
        lo, hi = PARAM_RANGES[p]
        med[p] = (med[p] - lo) / (hi - lo)
    return med.reindex([p for p in POPULATIONS if p in med.index])


def save_figure(fig: plt.Figure, stem: Path) -> list[Path]:
    """Save ``fig`` as ``stem``.png and ``stem``.svg atomically; close it."""
    out = []
    for ext in ("png", "svg"):
        path = stem.with_suffix(f".{ext}")
        write_atomic(path, partial(fig.savefig, format=ext, dpi=150, bbox_inches="tight"))
        out.append(path)
    plt.close(fig)
    return out


def plot_median_positions(populations: pd.DataFrame) -> plt.Figure:
    med = median_positions(populations)
    sizes = population_sizes(populations)
    fig, ax = plt.subplots(figsize=(7.5, 4.2))
    im = ax.imshow(med.to_numpy(), cmap="viridis", vmin=0, vmax=1, aspect="auto")
    ax.set_xticks(range(len(PARAMS)), [PARAM_LABELS[p] for p in PARAMS], rotation=30, ha="right")
    ax.set_yticks(range(len(med)), [f"{p.replace('_', ' ')} (n={sizes[p]})" for p in med.index])
    for i in range(med.shape[0]):
        for j in range(med.shape[1]):
            val = med.iat[i, j]
            ax.text(
                j,
                i,
                f"{val:.2f}",
                ha="center",
                va="center",
                fontsize=7,
                color="white" if val < 0.6 else "black",
            )
    boundary = 0
    for group in POPULATION_GROUPS.values():
        boundary += sum(1 for p in group if p in med.index)
        if boundary < len(med):
            ax.axhline(boundary - 0.5, color="white", lw=3)
    fig.colorbar(im, ax=ax, label="median position within range")
    ax.set_title("(a) Motion profiles across population conditions")
    return fig


def plot_matched_shift(populations: pd.DataFrame) -> plt.Figure:
    base = populations[populations["population"] == MATCHED_PAIR[0]].set_index("persona_id")
    dead = populations[populations["population"] == MATCHED_PAIR[1]].set_index("persona_id")
    dead = dead.loc[base.index]
    fig, axes = plt.subplots(1, len(PARAMS), figsize=(12, 3.0))
    for ax, p in zip(axes, PARAMS, strict=True):
        data = [base[p].to_numpy(), dead[p].to_numpy()]
        parts = ax.violinplot(data, showmedians=True)
        for body, color in zip(parts["bodies"], ("#4C72B0", "#DD8452"), strict=True):
            body.set_facecolor(color)
            body.set_alpha(0.6)
        ax.set_xticks([1, 2], ["base", "deadline"], fontsize=8)
        ax.set_title(PARAM_LABELS[p], fontsize=9)
        ax.set_ylim(*PARAM_RANGES[p])
        ax.tick_params(labelsize=7)
    fig.suptitle(
        f"(b) Same {len(base)} personas before and after time pressure := Deadline", fontsize=10
    )
    fig.tight_layout()
    return fig


def write_profile_figures(populations: pd.DataFrame, folder: Path) -> list[Path]:
    """Write fig3a/fig3b PNG+SVG into ``folder``; returns the paths."""
    folder = Path(folder)
    paths = save_figure(plot_median_positions(populations), folder / "fig3a_profiles")
    if set(MATCHED_PAIR) <= set(populations["population"]):
        paths += save_figure(plot_matched_shift(populations), folder / "fig3b_matched_shift")
    return paths
