"""Stage 7: analysis — runs and pedestrians tables → paired delays, cell metrics,
ranking reversals, bootstrap intervals and study summaries (SPEC §7, paper §IV-B, §V).

Pure functions over DataFrames; no file I/O, no plotting. Definitions and the
choices the paper leaves open are in ``docs/analysis.md``.
"""

from .bootstrap import bootstrap_ratio, percentile_interval, rate_intervals, resample_weights
from .cells import cell_key, episode_cells
from .delay import cell_metrics, paired_delays, worst_decile
from .findings import Finding, paper_findings
from .ranked import RANKED_METRICS, TOLERANCES, RankedMetric, tail_count
from .reversals import (
    METRICS,
    cluster_counts,
    comparisons,
    completed_units,
    kendall_tau_b,
    population_pairs,
    ranking_tau,
    reversal_rates,
    safe_ratio,
    tau_b_from_signs,
    tie_sign,
)
from .summary import (
    controller_outcomes,
    delay_change,
    no_robot_checks,
    noise_floor,
    paired_share,
    population_sensitivity,
    reversal_table,
    sensitivity_by_width,
)

__all__ = [
    "METRICS",
    "RANKED_METRICS",
    "TOLERANCES",
    "Finding",
    "RankedMetric",
    "bootstrap_ratio",
    "cell_key",
    "cell_metrics",
    "cluster_counts",
    "comparisons",
    "completed_units",
    "controller_outcomes",
    "delay_change",
    "episode_cells",
    "kendall_tau_b",
    "no_robot_checks",
    "noise_floor",
    "paired_delays",
    "paired_share",
    "paper_findings",
    "percentile_interval",
    "population_pairs",
    "population_sensitivity",
    "ranking_tau",
    "rate_intervals",
    "resample_weights",
    "reversal_rates",
    "reversal_table",
    "safe_ratio",
    "sensitivity_by_width",
    "tail_count",
    "tau_b_from_signs",
    "tie_sign",
    "worst_decile",
]
