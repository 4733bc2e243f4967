"""The ranked cell metrics, declared once (docs/analysis.md §"Cell metrics").

A ranked metric is a per-cell statistic on which controllers are ranked and
reversals counted. Each is one :class:`RankedMetric`: its name (the cell-metrics
column), words, unit, tie tolerance, and one function, passed rather than named
(as rliable passes its aggregate functions):

* ``compute(design, weights) -> (B, R) array``: the metric of every cell-metric row
  under B episode weight vectors, in numba, from the indexed robot runs and paired
  delays (:class:`Design`, :func:`popnavshift.analysis.resample.build_design`).

The point estimate is the call with unit weights
(:func:`popnavshift.analysis.delay.cell_metrics`) and every bootstrap resample a call
with its multiplicities (:func:`popnavshift.analysis.resample.resampled_metrics`): one
function, so the two cannot drift apart. The cell table, the bootstrap, the verdicts,
the card, the comparison page, the report and the tolerance table of docs/analysis.md
iterate :data:`RANKED_METRICS`; adding a metric is one entry here and its function.
Lower is better for all.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal

import numba
import numpy as np
import pandas as pd

from ..errors import UnknownNameError

TAIL_SHARE = 0.1  # the upper tail of the worst-decile and CVaR-90 delay statistics


def tail_count(n: int | np.ndarray) -> int | np.ndarray:
    """⌈0.1 n⌉ = ⌈n / 10⌉ in integer arithmetic (exact for any n; 0 for n = 0)."""
    return -(-n // 10)


@dataclass(frozen=True)
class CSR:
    """Entries grouped by row: row r owns ``ptr[r]:ptr[r+1]`` of ``col`` and ``val``."""

    ptr: np.ndarray  # (R + 1,) int64
    col: np.ndarray  # (n,) int64: the weight column (episode) of each entry
    val: np.ndarray  # (n,) float64
    aux: np.ndarray  # (n,) float64: a second value (delay counts), or empty


@dataclass(frozen=True)
class Design:
    """Rows (the cell-metric key), episodes (weight columns) and each metric's entries.

    A record is a pedestrian of a robot run that arrived without the robot; it has a
    paired delay when it arrived with the robot too, and is ``blocked`` otherwise
    (:func:`popnavshift.analysis.delay.paired_delays`). The delay entries hold the paired
    delays only (SPEC §7); ``blocked`` counts every record."""

    rows: pd.DataFrame  # CELL_KEY columns, one row per cell metric, sorted
    episodes: pd.DataFrame  # episode, cell, column (0 … E−1)
    times: CSR  # robot time of each run: val = robot_time
    delays: CSR  # per (row, episode): val = Σ paired delay, aux = count of paired delays
    blocked: CSR  # per (row, episode): val = blocked records, aux = all records
    records: CSR  # every paired delay, largest first within a row
    outcomes: dict[str, CSR]  # per run, 1.0 when the run ended in the outcome

    @property
    def n_columns(self) -> int:
        return len(self.episodes)


@dataclass(frozen=True)
class RankedMetric:
    """One ranked cell metric. ``aspect``: ``robot`` (from the robot's runs) or
    ``burden`` (from the paired pedestrian records). ``label`` is the metric in words,
    ``title`` its heading in the report's tables and figures. ``paper``: one of the
    paper's three (Table I). ``summary``: shown where one figure per aspect summarises
    (the comparison page's ranks, burden beyond robot time); the worst decile is not,
    as it rests on 1–3 records per cell. ``compute(design, weights)``: (B, E) episode
    weights → (B, R) float64, the metric of each design row under each weight vector (NaN
    where a row has nothing to average); unit weights give the point estimate."""

    name: str
    label: str
    title: str
    unit: str
    tolerance: float  # tie tolerance [unit]: |Δ| ≤ tolerance is a tie
    aspect: Literal["robot", "burden"]
    paper: bool
    summary: bool
    compute: Callable[[Design, np.ndarray], np.ndarray]

    @property
    def axis_label(self) -> str:
        """``mean delay [s]``."""
        return f"{self.label} [{self.unit}]"


@numba.njit(cache=True)
def _ratio(w, ptr, col, num, den, use_den):  # pragma: no cover - numba
    n_b, n_r = w.shape[0], ptr.size - 1
    out = np.full((n_b, n_r), np.nan)
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
def _tail_kernel(w, cnt_ptr, cnt_col, cnt_n, rec_ptr, rec_col, rec_val, share, fractional):
    # pragma: no cover - numba
    n_b, n_r = w.shape[0], rec_ptr.size - 1
    out = np.full((n_b, n_r), np.nan)
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


def share_resampled(c: CSR, w: np.ndarray) -> np.ndarray:
    """Σ_e w_e v_e / Σ_e w_e over a row's entries (robot times, outcome indicators)."""
    return _ratio(w, c.ptr, c.col, c.val, c.val, False)


def robot_time_rows(d: Design, w: np.ndarray) -> np.ndarray:
    """Mean robot time of the row's runs, Σ_e w_e t_e / Σ_e w_e [s] (45 s for a failed run)."""
    return share_resampled(d.times, w)


def mean_delay_rows(d: Design, w: np.ndarray) -> np.ndarray:
    """Mean of the row's paired delays, Σ_e w_e S_e / Σ_e w_e n_e, S_e and n_e the delay sum
    and count of episode e [s]; NaN without a record."""
    return _ratio(w, d.delays.ptr, d.delays.col, d.delays.val, d.delays.aux, True)


def _tail(d: Design, w: np.ndarray, fractional: bool) -> np.ndarray:
    return _tail_kernel(w, d.delays.ptr, d.delays.col, d.delays.aux, d.records.ptr,
                        d.records.col, d.records.val, TAIL_SHARE, fractional)


def worst_decile_rows(d: Design, w: np.ndarray) -> np.ndarray:
    """Mean of the largest ⌈N/10⌉ of N = Σ_e w_e n_e records, each counted w_e times [s]
    (the paper's; with unit weights :func:`popnavshift.analysis.delay.worst_decile`)."""
    return _tail(d, w, False)


def cvar90_rows(d: Design, w: np.ndarray) -> np.ndarray:
    """CVaR at 90 %: the mean of the upper tenth of N = Σ_e w_e n_e records, t = max(0.1 N, 1)
    of them, the boundary one counted fractionally [s] (with unit weights
    :func:`popnavshift.analysis.delay.cvar`)."""
    return _tail(d, w, True)


def blocked_pct_rows(d: Design, w: np.ndarray) -> np.ndarray:
    """Pedestrians blocked: 100 · Σ_e w_e k_e / Σ_e w_e n_e [%], k_e of the n_e records of
    episode e (pedestrians that arrived without the robot) not arrived with it; NaN
    without a record."""
    return 100.0 * _ratio(w, d.blocked.ptr, d.blocked.col, d.blocked.val, d.blocked.aux, True)


RANKED_METRICS: tuple[RankedMetric, ...] = (
    RankedMetric("robot_time", "robot time", "Robot travel time", "s", 0.05, "robot",
                 paper=True, summary=True, compute=robot_time_rows),
    RankedMetric("mean_delay", "mean delay", "Mean pedestrian delay", "s", 0.02, "burden",
                 paper=True, summary=True, compute=mean_delay_rows),
    RankedMetric("worst_decile", "worst-decile delay", "Worst-decile delay", "s", 0.02,
                 "burden", paper=True, summary=False, compute=worst_decile_rows),
    RankedMetric("cvar90", "CVaR-90 delay", "CVaR-90 delay", "s", 0.02, "burden",
                 paper=False, summary=True, compute=cvar90_rows),
    # a share of whole pedestrians: any difference is one pedestrian or more (tolerance 0)
    RankedMetric("blocked_pct", "blocked pedestrians", "Pedestrians blocked", "%", 0.0,
                 "burden", paper=False, summary=False, compute=blocked_pct_rows),
)
RANKED: dict[str, RankedMetric] = {m.name: m for m in RANKED_METRICS}
#: every ranked metric's name, in declaration order
RANKED_NAMES: tuple[str, ...] = tuple(RANKED)
#: tie tolerance per ranked metric [its unit]
TOLERANCES: dict[str, float] = {m.name: m.tolerance for m in RANKED_METRICS}


def ranked_metric(name: str) -> RankedMetric:
    """The declared metric ``name``; an :class:`UnknownNameError` with the known names."""
    if name not in RANKED:
        raise UnknownNameError("ranked metric", name, RANKED_NAMES)
    return RANKED[name]


def names(aspect: str | None = None, *, paper: bool | None = None,
          summary: bool | None = None) -> tuple[str, ...]:
    """Declared metric names, in order, filtered by aspect, paper and summary."""
    return tuple(m.name for m in RANKED_METRICS
                 if (aspect is None or m.aspect == aspect)
                 and (paper is None or m.paper == paper)
                 and (summary is None or m.summary == summary))


def metrics_markdown() -> str:
    """The declaration as the Markdown table of docs/analysis.md §3 (a test compares)."""
    rows = ["| metric | column | unit | tie tolerance | aspect | paper (Table I) |",
            "|---|---|---|---|---|---|"]
    rows += [f"| {m.label} | `{m.name}` | {m.unit} | {m.tolerance:g} | {m.aspect} | "
             f"{'yes' if m.paper else 'no'} |" for m in RANKED_METRICS]
    return "\n".join(rows) + "\n"
