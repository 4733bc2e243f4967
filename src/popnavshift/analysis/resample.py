"""The paired episode bootstrap: cell metrics recomputed on resampled episodes.

What is random in a study is the draw of episodes within a cell (start positions,
directions, slot draws); the cells themselves are a fixed grid. A resample
therefore draws, *within each cell*, as many episodes as the cell has, with
replacement, and the draw is shared by every population, controller, backend and
mapping of the cell: a resample is a vector of episode multiplicities
(``episode_weights``), and every comparison computed from one resample is paired
(same episodes under every controller and population).

``Design`` indexes a runs table and its paired delays once (per cell-metric row:
its runs, its per-episode delay sums and its delay records sorted from the
largest); ``resampled_metrics`` then evaluates every cell metric under B weight
vectors in numba, without rebuilding tables:

* ``robot_time``: Σ_e w_e t_e / Σ_e w_e over the row's runs [s];
* ``mean_delay``: Σ_e w_e S_e / Σ_e w_e n_e, S_e and n_e the sum and count of
  the episode's paired delays [s];
* ``worst_decile``: mean of the largest ⌈N/10⌉ records, N = Σ_e w_e n_e, each
  record counted w_e times [s] (the paper's statistic);
* ``cvar90``: CVaR at 90 %, the mean of the upper tenth, N/10 records with the
  boundary record counted fractionally [s] (see :func:`popnavshift.analysis.delay.cvar`);
* ``<outcome>_share``: Σ_e w_e [outcome] / Σ_e w_e, e.g. ``success_share`` in [0, 1].

With all weights 1 each equals the cell metric of
:func:`popnavshift.analysis.delay.cell_metrics` (up to the order of float sums).
A weight column is an episode.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np
import pandas as pd

from ..tables import NO_ROBOT
from .delay import CELL_KEY, episode_cells

#: Cell metrics the bootstrap recomputes (lower is better for all).
BOOT_METRICS: tuple[str, ...] = ("robot_time", "mean_delay", "worst_decile", "cvar90")
TAIL_SHARE = 0.1  # the worst decile / CVaR tail
#: Run outcomes whose share per cell the bootstrap can recompute (``<outcome>_share``).
SHARE_OUTCOMES: tuple[str, ...] = ("success", "timeout", "pedestrian_collision",
                                   "world_collision", "controller_error")


@dataclass(frozen=True)
class CSR:
    """Entries grouped by row: row r owns ``ptr[r]:ptr[r+1]`` of ``col`` and ``val``."""

    ptr: np.ndarray  # (R + 1,) int64
    col: np.ndarray  # (n,) int64: the weight column (episode) of each entry
    val: np.ndarray  # (n,) float64
    aux: np.ndarray  # (n,) float64: a second value (delay counts), or empty


@dataclass(frozen=True)
class Design:
    """Rows (the cell-metric key), episodes (weight columns) and each metric's entries."""

    rows: pd.DataFrame  # CELL_KEY columns, one row per cell metric, sorted
    episodes: pd.DataFrame  # episode, cell, column (0 … E−1)
    times: CSR  # robot time of each run: val = robot_time
    delays: CSR  # per (row, episode): val = Σ delay, aux = count
    records: CSR  # every paired delay, largest first within a row
    outcomes: dict[str, CSR]  # per run, 1.0 when the run ended in the outcome

    @property
    def n_columns(self) -> int:
        return len(self.episodes)


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
    p_row, p_col, d = p_row[keep], p_col[keep], p["delay"].to_numpy(float)[keep]
    by = pd.DataFrame({"row": p_row, "col": p_col, "d": d}).groupby(["row", "col"], sort=True)
    sums = by["d"].agg(["sum", "size"]).reset_index()
    delays = _csr(sums["row"].to_numpy(), sums["col"].to_numpy(), sums["sum"].to_numpy(),
                  len(rows), sums["size"].to_numpy(float))
    order = np.lexsort((-d, p_row))  # by row, then largest delay first
    records = _csr(p_row[order], p_col[order], d[order], len(rows))
    return Design(rows, eps, times, delays, records, outcomes)


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


@numba.njit(cache=True)
def _ratio(w, ptr, col, num, den, use_den):  # pragma: no cover - numba
    n_b, n_r = w.shape[0], ptr.size - 1
    out = np.full((n_b, n_r), np.nan, dtype=np.float32)
    for r in range(n_r):
        for b in range(n_b):
            s = 0.0
            d = 0.0
            for j in range(ptr[r], ptr[r + 1]):
                wj = w[b, col[j]]
                s += wj * num[j]
                d += wj * (den[j] if use_den else 1.0)
            if d > 0:
                out[b, r] = s / d
    return out


@numba.njit(cache=True)
def _tail(w, cnt_ptr, cnt_col, cnt_n, rec_ptr, rec_col, rec_val, share, fractional):
    # pragma: no cover - numba
    n_b, n_r = w.shape[0], rec_ptr.size - 1
    out = np.full((n_b, n_r), np.nan, dtype=np.float32)
    for r in range(n_r):
        for b in range(n_b):
            n = 0.0
            for j in range(cnt_ptr[r], cnt_ptr[r + 1]):
                n += w[b, cnt_col[j]] * cnt_n[j]
            if n <= 0:
                continue
            want = share * n if fractional else np.ceil(np.round(share * n, 9))
            if fractional and want < 1.0:
                want = 1.0  # fewer than 10 records: the tail is the largest one
            left = want
            s = 0.0
            for j in range(rec_ptr[r], rec_ptr[r + 1]):
                take = min(float(w[b, rec_col[j]]), left)
                s += take * rec_val[j]
                left -= take
                if left <= 0:
                    break
            out[b, r] = s / want
    return out


def resampled_metrics(design: Design, weights: np.ndarray,
                      metrics: tuple[str, ...] = BOOT_METRICS) -> dict[str, np.ndarray]:
    """Each metric of ``metrics`` per resample and row: (B, R) float64 [s].

    ``weights`` is (B, E) (:func:`episode_weights`, or ones for the point estimate);
    NaN where a row has no run or no paired delay under a resample.
    """
    w = np.ascontiguousarray(weights)
    t, d, rec = design.times, design.delays, design.records
    out: dict[str, np.ndarray] = {}
    for m in metrics:
        if m == "robot_time" or m in design.outcomes:
            c = t if m == "robot_time" else design.outcomes[m]
            out[m] = _ratio(w, c.ptr, c.col, c.val, c.val, False)
        elif m == "mean_delay":
            out[m] = _ratio(w, d.ptr, d.col, d.val, d.aux, True)
        elif m in ("worst_decile", "cvar90"):
            out[m] = _tail(w, d.ptr, d.col, d.aux, rec.ptr, rec.col, rec.val, TAIL_SHARE,
                           m == "cvar90")
        else:
            raise KeyError(m)
    return out
