"""Paired significance of controller orderings, significant reversals and crossover tests.

Pipeline: cell metrics + their paired episode bootstrap (:mod:`.resample`) →
``orderings`` (per metric: every controller pair in every unit and population,
its difference D = m(c₁) − m(c₂), a percentile interval and a significant sign)
→ ``pair_counts`` (raw and significant reversals between population pairs, for
the point estimate and every resample) and ``crossover_tests`` (an
intersection–union test of a qualitative interaction across populations, valid for
populations that share episodes and personas, with Holm or BH control and the
crossover size each test could detect).

* **Significant ordering**: the bootstrap interval of D at ``level`` (default 90 %)
  excludes 0; otherwise the ordering counts as tied. With n episodes in the cell,
  the interval is the wider of (a) Hesterberg's *expanded percentile* interval
  (tails at Φ(−√(n/(n−1)) · t_{n−1, 1−α/2}) instead of α/2) and (b) the t-interval
  D ± t_{n−1, 1−α/2} · √(n/(n−1)) · SE_boot. Both undo the plug-in variance's
  (n−1)/n bias; (b) is what keeps small cells honest — with the paper's 3 variants
  per cell a percentile interval spans only the 3 episodes and calls an ordering
  significant whenever they agree in sign (25 % of the time under no difference);
  (a) keeps the skew of tail metrics where n is large. One episode: no interval.
* **Significant reversal**: two significant orderings of opposite sign under two
  populations. The **significant rate** is significant reversals / comparisons
  significant under both populations. The paper's **raw rate** (tie tolerance,
  includes near-ties) is always reported beside it.
* In resample b, an ordering is significant when the interval shifted to D_b,
  [D_b − (D − lo), D_b + (hi − D)], excludes 0 (the interval's width is taken as
  pivotal): intervals of rates then need one level of resampling, not two.

Definitions, reasons and references: ``docs/analysis.md`` §6.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from dataclasses import dataclass, replace
from itertools import combinations

import numpy as np
import pandas as pd
from scipy import optimize, stats

from .cells import CELL_KEY, UNIT
from .ranked import TOLERANCES, Design
from .reversals import tie_sign

LEVEL = 0.90  # coverage of an ordering's interval
ALPHA = 0.05  # family-wise / false-discovery level of the crossover tests
POWER = 0.80  # the power at which a crossover test states the size it can detect


@dataclass
class Orderings:
    """Controller orderings of one metric on a (population × unit × controller pair) grid.

    Point arrays are (P, U, C); ``boot`` is (B, P, U, C) float32 (the resampled
    differences, every resample shared by all populations and controllers).
    """

    metric: str
    populations: list[str]
    units: pd.DataFrame  # UNIT columns (backend, mapping, cell), U rows
    pairs: list[tuple[str, str]]  # controller pairs (sorted names), C of them
    diff: np.ndarray
    low: np.ndarray
    high: np.ndarray
    se: np.ndarray
    sig: np.ndarray  # ±1 significant, 0 tied, NaN missing
    boot: np.ndarray
    level: float
    tolerance: float
    n_episodes: np.ndarray  # (U,) episodes in each unit's cell (the bootstrap's sample size)

    def index(self, population: str) -> int:
        return self.populations.index(population)

    def involving(self, controller: str, other: str | None = None) -> Orderings:
        """These orderings restricted to the controller pairs of ``controller`` (with
        ``other`` only, when given): a card's rates count only its controller's orderings
        against the baselines, never the baselines' among themselves."""
        keep = [i for i, pair in enumerate(self.pairs) if controller in pair
                and (other is None or other in pair)]
        return replace(self, pairs=[self.pairs[i] for i in keep], diff=self.diff[..., keep],
                       low=self.low[..., keep], high=self.high[..., keep],
                       se=self.se[..., keep], sig=self.sig[..., keep],
                       boot=self.boot[..., keep])

    def table(self) -> pd.DataFrame:
        """One row per (population, unit, controller pair): ``diff, low, high, se, sig,
        sign`` (``sign`` = the paper's tolerance sign)."""
        n_p, n_u, n_c = self.diff.shape
        frame = self.units.iloc[np.tile(np.repeat(np.arange(n_u), n_c), n_p)]
        out = frame.reset_index(drop=True)
        out.insert(0, "metric", self.metric)
        out["population"] = np.repeat(self.populations, n_u * n_c)
        out["ctrl_1"] = [self.pairs[i][0] for i in np.tile(np.arange(n_c), n_p * n_u)]
        out["ctrl_2"] = [self.pairs[i][1] for i in np.tile(np.arange(n_c), n_p * n_u)]
        for name in ("diff", "low", "high", "se", "sig"):
            out[name] = getattr(self, name).ravel()
        out["sign"] = tie_sign(out["diff"].to_numpy(float), self.tolerance)
        return out


def _grid(rows: pd.DataFrame, populations: list[str], units: pd.DataFrame,
          controllers: list[str]) -> np.ndarray:
    """(P, U, K) row index of each (population, unit, controller) in ``rows``; −1 if absent."""
    pos = np.full((len(populations), len(units), len(controllers)), -1, dtype=np.int64)
    u_index = pd.MultiIndex.from_frame(units)
    u = u_index.get_indexer(pd.MultiIndex.from_frame(rows[list(UNIT)]))
    p = pd.Index(populations).get_indexer(rows["population"])
    k = pd.Index(controllers).get_indexer(rows["controller"])
    ok = (u >= 0) & (p >= 0) & (k >= 0)
    pos[p[ok], u[ok], k[ok]] = np.flatnonzero(ok)
    return pos


def orderings(cells: pd.DataFrame, design: Design, boot: dict[str, np.ndarray], metric: str, *,
              level: float = LEVEL, tolerance: float | None = None,
              populations: Sequence[str] | None = None) -> Orderings:
    """Every controller ordering of ``metric`` with its paired-bootstrap interval.

    Args:
      cells: cell metrics (the point estimates), rows aligned with ``design.rows``.
      design, boot: the design and :func:`popnavshift.analysis.resample.resampled_metrics`
        under B resamples (B ≥ 2).
      level: interval coverage; an ordering is significant when its interval
        excludes 0.
      tolerance: the paper's tie tolerance for the raw sign (default: TOLERANCES).
      populations: the populations to lay out (default: all in ``cells``, sorted).
    """
    key = list(CELL_KEY)
    if len(cells) != len(design.rows) or not (
            cells[key].to_numpy() == design.rows[key].to_numpy()).all():
        raise ValueError("cells and design rows differ: build both from the same runs")
    pops = sorted(cells["population"].unique()) if populations is None else list(populations)
    ctrl = sorted(cells["controller"].unique())
    units = cells[list(UNIT)].drop_duplicates().sort_values(list(UNIT)).reset_index(drop=True)
    pos = _grid(cells, pops, units, ctrl)
    pairs = list(combinations(range(len(ctrl)), 2))
    point = np.append(cells[metric].to_numpy(float), np.nan)  # index −1 → NaN
    resampled = boot[metric]  # (B, R) float32; index −1 (absent) is masked by _take: a
    # padded float64 copy of it was the largest array of a design with many null replicates
    i1 = pos[:, :, [a for a, _ in pairs]]
    i2 = pos[:, :, [b for _, b in pairs]]
    diff = point[i1] - point[i2]
    n_b = resampled.shape[0]
    d_boot = np.empty((n_b, *diff.shape), dtype=np.float32)
    low, high, se = (np.full(diff.shape, np.nan) for _ in range(3))
    per_cell = design.episodes.groupby("cell").size()
    n_eps = units["cell"].map(per_cell).fillna(0).to_numpy(np.int64)
    for p in range(len(pops)):  # one population at a time bounds the temporaries
        d = _take(resampled, i1[p]) - _take(resampled, i2[p])
        d_boot[:, p] = d
        with np.errstate(all="ignore"), warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN slices → NaN
            se[p] = np.nanstd(d, axis=0, dtype=np.float64)
        for n in np.unique(n_eps):
            u = n_eps == n
            if n < 2:
                continue  # one episode: no interval, never significant
            tail = expanded_tail(level, int(n))
            lo, hi = nan_quantiles(d[:, u], (tail, 1 - tail))
            half = stats.t.ppf(0.5 + level / 2, n - 1) * np.sqrt(n / (n - 1)) * se[p][u]
            low[p][u] = np.fmin(lo, diff[p][u] - half)
            high[p][u] = np.fmax(hi, diff[p][u] + half)
    sig = np.where(low > 0, 1.0, np.where(high < 0, -1.0, 0.0))
    sig[np.isnan(diff) | np.isnan(low)] = np.nan
    tol = TOLERANCES[metric] if tolerance is None else tolerance
    return Orderings(metric, pops, units, [(ctrl[a], ctrl[b]) for a, b in pairs], diff,
                     low, high, se, sig, d_boot, level, tol, n_eps)


def _take(resampled: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """``resampled[:, idx]`` in float64 (the differences and their spread are taken in
    float64), NaN where ``idx`` is −1 (a row absent from the cells)."""
    out = resampled[:, np.maximum(idx, 0)].astype(np.float64)
    out[:, idx < 0] = np.nan
    return out


def expanded_tail(level: float, n: int) -> float:
    """The lower tail probability of Hesterberg's expanded percentile interval at ``level``
    for a sample of ``n`` ≥ 2 (Hesterberg 2015, §5): Φ(−√(n/(n−1)) · t_{n−1, (1+level)/2})."""
    t = stats.t.ppf(0.5 + level / 2, n - 1)
    return float(stats.norm.cdf(-np.sqrt(n / (n - 1)) * t))


def nan_quantiles(x: np.ndarray, qs: Sequence[float]) -> list[np.ndarray]:
    """Quantiles along axis 0 ignoring NaN (numpy's default linear interpolation), as
    ``np.nanquantile`` but one sort for all columns; NaN for an all-NaN column."""
    s = np.sort(x, axis=0)  # NaN last
    n = np.isfinite(s).sum(axis=0)
    out = []
    for q in qs:
        pos = q * np.maximum(n - 1, 0)
        lo = np.floor(pos).astype(np.int64)
        hi = np.minimum(lo + 1, np.maximum(n - 1, 0))
        frac = pos - lo
        a = np.take_along_axis(s, lo[None], axis=0)[0].astype(np.float64)
        b = np.take_along_axis(s, hi[None], axis=0)[0].astype(np.float64)
        v = a + frac * (b - a)
        out.append(np.where(n > 0, v, np.nan))
    return out


# --- reversals between population pairs -----------------------------------------------------


@dataclass(frozen=True)
class PairCounts:
    """Reversal counts over a set of population pairs.

    Point counts are per unit (U,) so they can be pooled or clustered; resampled
    counts are per resample (B,), summed over units and pairs.
    """

    raw_reversals: np.ndarray
    raw_comparable: np.ndarray
    sig_reversals: np.ndarray
    sig_comparable: np.ndarray
    boot_raw_reversals: np.ndarray
    boot_raw_comparable: np.ndarray
    boot_sig_reversals: np.ndarray
    boot_sig_comparable: np.ndarray

    def rate(self, rule: str) -> float:
        """Pooled rate Σ reversals / Σ comparable of ``rule`` ("raw" or "sig")."""
        r, c = getattr(self, f"{rule}_reversals").sum(), getattr(self, f"{rule}_comparable").sum()
        return float(r / c) if c > 0 else float("nan")

    def boot_rate(self, rule: str) -> np.ndarray:
        """(B,) the pooled rate in every resample (NaN without a comparable comparison)."""
        r = getattr(self, f"boot_{rule}_reversals").astype(float)
        c = getattr(self, f"boot_{rule}_comparable").astype(float)
        return np.divide(r, c, out=np.full_like(r, np.nan), where=c > 0)


def _boot_sig(o: Orderings, i: int) -> np.ndarray:
    """(B, U, C) significant signs of population ``i`` in every resample (pivot rule)."""
    d = o.boot[:, i]
    up = d > (o.diff[i] - o.low[i])
    down = d < (o.diff[i] - o.high[i])
    s = np.where(up, 1, np.where(down, -1, 0)).astype(np.int8)
    s[:, np.isnan(o.sig[i])] = 0
    return s


def _boot_raw(o: Orderings, i: int) -> np.ndarray:
    d = o.boot[:, i].astype(float)
    s = tie_sign(d, o.tolerance)
    return np.nan_to_num(s, nan=0.0).astype(np.int8)


def pair_counts(o: Orderings, pairs: Sequence[tuple[str, str]]) -> PairCounts:
    """Raw and significant reversal counts of ``o`` between each population pair in
    ``pairs``, pooled over the pairs: per unit (point) and per resample."""
    n_b, _, n_u, _ = o.boot.shape
    point = {k: np.zeros(n_u, np.int64) for k in ("rr", "rc", "sr", "sc")}
    boot = {k: np.zeros(n_b, np.int64) for k in ("rr", "rc", "sr", "sc")}
    raw = tie_sign(o.diff, o.tolerance)
    cache: dict[tuple[str, int], np.ndarray] = {}

    def signs(kind: str, i: int) -> np.ndarray:
        if (kind, i) not in cache:
            cache[(kind, i)] = _boot_sig(o, i) if kind == "sig" else _boot_raw(o, i)
        return cache[(kind, i)]

    for a, b in pairs:
        ia, ib = o.index(a), o.index(b)
        for kind, point_signs, rk, ck in (("raw", raw, "rr", "rc"), ("sig", o.sig, "sr", "sc")):
            prod = point_signs[ia] * point_signs[ib]
            point[rk] += (prod == -1).sum(axis=1)
            point[ck] += (np.abs(prod) == 1).sum(axis=1)
            bprod = signs(kind, ia).astype(np.int16) * signs(kind, ib)
            boot[rk] += (bprod == -1).sum(axis=(1, 2))
            boot[ck] += (bprod != 0).sum(axis=(1, 2))
    return PairCounts(point["rr"], point["rc"], point["sr"], point["sc"],
                      boot["rr"], boot["rc"], boot["sr"], boot["sc"])


# --- crossover (qualitative interaction) tests ---------------------------------------------


def one_sided_p(diff: np.ndarray, se: np.ndarray, n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(p of D > 0, p of D < 0) per entry: t = D / (√(n/(n−1)) · SE) on n − 1 degrees of
    freedom (the bootstrap SE's plug-in bias undone); NaN where n < 2, D or SE is missing,
    or SE is 0 (every resample the same: no spread to judge a sign by)."""
    d, s = np.asarray(diff, float), np.asarray(se, float)
    n = np.broadcast_to(np.asarray(n, float), d.shape)
    ok = np.isfinite(d) & np.isfinite(s) & (s > 0) & (n >= 2)
    with np.errstate(divide="ignore", invalid="ignore"):
        scaled = s * np.sqrt(n / (n - 1))
        t = np.where(d == 0, 0.0, d / scaled)
        df = np.maximum(n - 1, 1)
        up = np.where(ok, stats.t.sf(t, df), np.nan)
        down = np.where(ok, stats.t.cdf(t, df), np.nan)
    return up, down


def crossover_p(diff: np.ndarray, se: np.ndarray, n: np.ndarray) -> np.ndarray:
    """The intersection–union p-value of a crossover, per row of ``diff``/``se`` (m, q): one
    controller difference under q populations, n (m,) episodes behind each row.

    A crossover is one population where D > 0 and another where D < 0, both beyond noise.
    p₊ = min(1, q′ · min_j p_j(D > 0)) and p₋ likewise, q′ the populations with a value
    (Bonferroni over the populations: valid whatever their dependence — they share every
    episode, and cohorts share personas); p = max(p₊, p₋). NaN with fewer than 2 values.
    """
    up, down = one_sided_p(diff, se, np.asarray(n, float)[:, None])
    q = np.isfinite(up).sum(axis=1)
    with np.errstate(invalid="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        p_up = np.minimum(1.0, q * np.nanmin(up, axis=1))
        p_down = np.minimum(1.0, q * np.nanmin(down, axis=1))
    return np.where(q >= 2, np.maximum(p_up, p_down), np.nan)


def detectable_crossover(se: np.ndarray, n: np.ndarray, q: np.ndarray, m: int, *,
                         alpha: float = ALPHA, power: float = POWER) -> np.ndarray:
    """The crossover the test of each row would find with probability ``power``: ±Y (metric
    units) under two of its q populations, Y returned per row (m rows, SE the median over its
    populations, n episodes). A single crossover among m rows survives the table's control
    when its p ≤ α/m (Holm with one discovery is Bonferroni), so each side needs
    its one-sided p ≤ α/(m q): per side the noncentrality λ with
    P(t_{n−1}(λ) > t_{n−1, 1−α/(mq)}) = 1 − (1 − power)/2 (so both sides succeed together
    with probability ≥ power, whatever their dependence), and Y = λ · √(n/(n−1)) · SE. NaN
    where n < 2."""
    se, n, q = (np.asarray(x, float) for x in (se, n, q))
    out = np.full(se.shape, np.nan)
    ok = np.isfinite(se) & (n >= 2) & (q >= 2)
    side = 1 - (1 - power) / 2  # both sides together ≥ power, whatever their dependence
    for nn, qq in {(a, b) for a, b in zip(n[ok], q[ok], strict=True)}:
        rows = ok & (n == nn) & (q == qq)
        df = nn - 1
        crit = stats.t.isf(alpha / (max(m, 1) * qq), df)
        lam = optimize.brentq(lambda x, c=crit, d=df: stats.nct.sf(c, d, x) - side,
                              0.0, 10 * crit + 50)
        out[rows] = lam * np.sqrt(nn / (nn - 1)) * se[rows]
    return out


def holm(p: np.ndarray) -> np.ndarray:
    """Holm's step-down adjusted p-values (family-wise error control); NaN kept."""
    p = np.asarray(p, float)
    out = np.full_like(p, np.nan)
    ok = np.flatnonzero(np.isfinite(p))
    order = ok[np.argsort(p[ok], kind="stable")]
    m = len(order)
    adj = np.maximum.accumulate((m - np.arange(m)) * p[order])
    out[order] = np.minimum(adj, 1.0)
    return out


def bh(p: np.ndarray) -> np.ndarray:
    """Benjamini–Hochberg adjusted p-values (false-discovery-rate control); NaN kept."""
    p = np.asarray(p, float)
    out = np.full_like(p, np.nan)
    ok = np.isfinite(p)
    if ok.any():
        out[ok] = stats.false_discovery_control(p[ok], method="bh")
    return out


ADJUST = {"holm": holm, "bh": bh}


def crossover_tests(o: Orderings, populations: Sequence[str], *, method: str = "holm",
                    alpha: float = ALPHA) -> pd.DataFrame:
    """The crossover test (:func:`crossover_p`) per (unit, controller pair) across
    ``populations``, adjusted over the table's rows with ``method`` (``"holm"``, valid whatever
    the dependence between rows, the default; or ``"bh"``, which assumes positive
    dependence).

    Returns one row per (unit, controller pair): UNIT columns, ``ctrl_1, ctrl_2``,
    ``n_populations``, ``p``, ``p_adj``, ``crossover`` (p_adj ≤ ``alpha``), ``se`` (the
    median SE over the populations), ``n_episodes`` and ``detectable``
    (:func:`detectable_crossover`: the ±size this row could see with 80 % power at this
    table's level; metric units).
    """
    idx = [o.index(p) for p in populations]
    d = np.moveaxis(o.diff[idx], 0, -1).reshape(-1, len(idx))
    s = np.moveaxis(o.se[idx], 0, -1).reshape(-1, len(idx))
    n_u, n_c = o.diff.shape[1:]
    n = np.repeat(o.n_episodes, n_c).astype(float)  # episodes behind each row's estimates
    p = crossover_p(d, s, n)
    out = o.units.iloc[np.repeat(np.arange(n_u), n_c)].reset_index(drop=True)
    out["ctrl_1"] = [o.pairs[i][0] for i in np.tile(np.arange(n_c), n_u)]
    out["ctrl_2"] = [o.pairs[i][1] for i in np.tile(np.arange(n_c), n_u)]
    out["n_populations"] = (np.isfinite(d) & np.isfinite(s)).sum(axis=1)
    out["p"] = p
    out["p_adj"] = ADJUST[method](p)
    out["crossover"] = out["p_adj"] <= alpha
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        out["se"] = np.nanmedian(np.where(np.isfinite(d), s, np.nan), axis=1)
    out["n_episodes"] = n
    out["detectable"] = detectable_crossover(out["se"].to_numpy(), n,
                                             out["n_populations"].to_numpy(),
                                             int(np.isfinite(p).sum()), alpha=alpha)
    return out
