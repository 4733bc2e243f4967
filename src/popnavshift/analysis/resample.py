"""The paired episode bootstrap: cell metrics recomputed on resampled episodes.

What is random in a study is the draw of episodes within a cell (start positions,
directions, slot draws); the cells themselves are a fixed grid. A resample
therefore draws, *within each cell*, as many episodes as the cell has, with
replacement, and the draw is shared by every population, controller, backend and
mapping of the cell: a resample is a vector of episode multiplicities
(``episode_weights``), and every comparison computed from one resample is paired
(same episodes under every controller and population).

``Design`` indexes a runs table and its paired delays once (per cell-metric row: its
runs, its per-episode delay sums, its per-episode blocked and record counts, and its
delay records sorted from the largest); ``resampled_metrics`` then evaluates every cell
metric under B weight vectors in numba, without rebuilding tables: each ranked metric by
its declared ``compute`` function (:mod:`popnavshift.analysis.ranked`, where each
says its formula), and ``<outcome>_share``: Σ_e w_e [outcome] / Σ_e w_e, e.g.
``success_share`` in [0, 1].

The same functions with all weights 1 are the cell metrics of
:func:`popnavshift.analysis.delay.cell_metrics`: the point estimate is a resample.
A weight column is an episode.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from ..tables import NO_ROBOT
from .cells import CELL_KEY, episode_cells
from .ranked import CSR, RANKED, RANKED_NAMES, Design, share_resampled

#: Run outcomes whose share per cell the bootstrap can recompute (``<outcome>_share``).
SHARE_OUTCOMES: tuple[str, ...] = ("success", "timeout", "pedestrian_collision",
                                   "world_collision", "controller_error")


def _csr(row: np.ndarray, col: np.ndarray, val: np.ndarray, n_rows: int,
         aux: np.ndarray | None = None) -> CSR:
    """Entries (row, col, val[, aux]) grouped by row, keeping their given order within a row."""
    order = np.argsort(row, kind="stable")
    counts = np.bincount(row, minlength=n_rows)
    ptr = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    return CSR(ptr, col[order].astype(np.int64), val[order].astype(np.float64),
               np.zeros(0) if aux is None else aux[order].astype(np.float64))


def build_design(runs: pd.DataFrame, paired: pd.DataFrame) -> Design:
    """Index the robot runs of ``runs`` and the ``paired`` delays for resampling.

    Rows follow :func:`popnavshift.analysis.delay.cell_metrics` (sorted by CELL_KEY);
    episodes are sorted by (cell, episode).
    """
    eps = episode_cells(runs)[["episode", "cell"]].sort_values(["cell", "episode"])
    eps = eps.reset_index(drop=True).assign(column=lambda d: np.arange(len(d)))
    col_of = dict(zip(eps["episode"], eps["column"], strict=True))
    robot = runs[runs["controller"] != NO_ROBOT].merge(eps[["episode", "cell"]], on="episode")
    key = list(CELL_KEY)
    rows = robot[key].drop_duplicates().sort_values(key).reset_index(drop=True)
    row_index = pd.MultiIndex.from_frame(rows)

    def row_of(df: pd.DataFrame) -> np.ndarray:
        return row_index.get_indexer(pd.MultiIndex.from_frame(df[key]))

    r_row, r_col = row_of(robot), robot["episode"].map(col_of).to_numpy()
    times = _csr(r_row, r_col, robot["robot_time"].to_numpy(float), len(rows))
    outcomes = {f"{o}_share": _csr(r_row, r_col, (robot["outcome"] == o).to_numpy(float),
                                   len(rows)) for o in SHARE_OUTCOMES}
    p = paired.merge(eps[["episode", "cell"]], on="episode")
    p_row, p_col = row_of(p), p["episode"].map(col_of).to_numpy()
    keep = p_row >= 0
    p_row, p_col = p_row[keep], p_col[keep]
    is_blocked = p["blocked"].to_numpy(bool)[keep]
    # blocked: every record (arrived without the robot); val = blocked, aux = records
    per = pd.DataFrame({"row": p_row, "col": p_col, "k": is_blocked.astype(float)}).groupby(
        ["row", "col"], sort=True)["k"].agg(["sum", "size"]).reset_index()
    blocked = _csr(per["row"].to_numpy(), per["col"].to_numpy(), per["sum"].to_numpy(),
                   len(rows), per["size"].to_numpy(float))
    # delays: the paired delays only (arrived in both runs, SPEC §7)
    ok = ~is_blocked
    p_row, p_col, d = p_row[ok], p_col[ok], p["delay"].to_numpy(float)[keep][ok]
    by = pd.DataFrame({"row": p_row, "col": p_col, "d": d}).groupby(["row", "col"], sort=True)
    sums = by["d"].agg(["sum", "size"]).reset_index()
    delays = _csr(sums["row"].to_numpy(), sums["col"].to_numpy(), sums["sum"].to_numpy(),
                  len(rows), sums["size"].to_numpy(float))
    order = np.lexsort((-d, p_row))  # by row, then largest delay first
    records = _csr(p_row[order], p_col[order], d[order], len(rows))
    return Design(rows, eps, times, delays, blocked, records, outcomes)


def episode_weights(design: Design, n_boot: int, rng: np.random.Generator) -> np.ndarray:
    """(n_boot, E) int32 multiplicities: each cell's episodes resampled with replacement.

    Cells are drawn in sorted order from ``rng`` (the only source of randomness), so
    the same generator state gives the same resamples.
    """
    w = np.zeros((n_boot, design.n_columns), dtype=np.int32)
    for _, cols in design.episodes.groupby("cell", sort=True)["column"]:
        c = cols.to_numpy()
        w[:, c] = rng.multinomial(len(c), np.full(len(c), 1.0 / len(c)), size=n_boot)
    return w


def resampled_metrics(design: Design, weights: np.ndarray,
                      metrics: tuple[str, ...] = RANKED_NAMES) -> dict[str, np.ndarray]:
    """Each metric of ``metrics`` per resample and row: (B, R) float32 (its unit).

    ``metrics`` are ranked metrics (:data:`popnavshift.analysis.ranked.RANKED_METRICS`,
    by their ``compute`` function) or ``<outcome>_share`` columns. ``weights`` is
    (B, E) (:func:`episode_weights`); NaN where a row has no run or no paired delay
    under a resample. Stored in float32 to halve the memory of B × R values; the
    point estimate (:func:`popnavshift.analysis.delay.cell_metrics`) keeps float64.
    """
    w = np.ascontiguousarray(weights)
    out: dict[str, np.ndarray] = {}
    for m in metrics:
        if m in RANKED:
            out[m] = RANKED[m].compute(design, w).astype(np.float32)
        elif m in design.outcomes:
            out[m] = share_resampled(design.outcomes[m], w).astype(np.float32)
        else:
            raise KeyError(m)
    return out
