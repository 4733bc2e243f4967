"""The statistics the paper's findings are judged by, on the cell-metrics rows.

Each function takes the cell table (:func:`popnavshift.analysis.delay.cell_metrics`:
one row per cell, controller and population) and a metric's values aligned with its
rows: shape ``(R,)`` for the point estimate or ``(B, R)`` for ``B`` bootstrap resamples
(:mod:`.resample`). It returns the statistic, a scalar or ``(B,)``. The findings that use
them are declared in :mod:`.findings` (``CLAIMS``); :mod:`.surviving` resamples them.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from ..populations.identity import MATCHED_PAIR


def controller_means(cells: pd.DataFrame, values: np.ndarray) -> dict[str, np.ndarray]:
    """Per controller: the mean over its (cell, population) rows of ``values``; NaN-skipping."""
    out = {}
    for ctrl, idx in cells.groupby("controller").indices.items():
        with np.errstate(all="ignore"):
            out[ctrl] = np.nanmean(values[..., idx], axis=-1)
    return out


def extreme_gap(cells: pd.DataFrame, values: np.ndarray, controller: str, *,
                highest: bool, among: tuple[str, ...] | None = None) -> np.ndarray:
    """How far ``controller``'s mean leads the best of the others (``among``, default all):
    its mean minus the highest other (``highest``), or the lowest other minus its mean;
    positive when it is the extreme."""
    means = controller_means(cells, values)
    others = [v for c, v in means.items() if c != controller and (among is None or c in among)]
    rest = (np.nanmax if highest else np.nanmin)(np.stack(others), axis=0)
    return means[controller] - rest if highest else rest - means[controller]


def width_gap(cells: pd.DataFrame, values: np.ndarray, scenes: tuple[str, ...]) -> np.ndarray:
    """Mean population range at the narrowest minus the widest width, over the
    (cell, controller) rows of ``scenes`` where every population has a value."""
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


def matched_change(cells: pd.DataFrame, values: np.ndarray, controller: str) -> np.ndarray:
    """Mean over units of the matched pair's deadline − base value for ``controller``."""
    sub = cells[cells["controller"] == controller]
    pos = sub.assign(i=sub.index).pivot(index=["backend", "mapping", "cell"],
                                        columns="population", values="i")
    pos = pos.reindex(columns=list(MATCHED_PAIR)).dropna().to_numpy(np.int64)
    with np.errstate(all="ignore"):
        return np.nanmean(values[..., pos[:, 1]] - values[..., pos[:, 0]], axis=-1)


def tail_to_mean(cells: pd.DataFrame, worst: np.ndarray, mean: np.ndarray,
                 controller: str) -> np.ndarray:
    """``controller``'s mean worst-decile delay over its mean delay."""
    return controller_means(cells, worst)[controller] / controller_means(cells, mean)[controller]
