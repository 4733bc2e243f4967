"""The report's tables, declared once: what ``popnavshift.results`` returns.

Each table of a study's report (``STUDY/report/tables/<name>.csv``) is one
:class:`ResultTable`: its name, the id of the report section that shows it (or whose
figures and sentences are drawn from it), what one row is, the columns that identify a
row and, for the tables read most, what its other columns hold. ``analysis/`` computes
them under these names (and says why one is absent under its name, ``Analysis.missing``),
the report writes and links them by :func:`csv_path`, a section shows only tables declared
with it, :func:`popnavshift.read.access.results` reads the declared tables back and the data
dictionary (``docs/data.md``) lists them. Writing a table that is not declared here is an
error (:func:`check_declared`).
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import NamedTuple

from .errors import UnknownNameError

#: the report's folder of tables, relative to its index.html
TABLES_DIR = "tables"


class ResultTable(NamedTuple):
    """A table of the report: ``name`` (its CSV is ``tables/<name>.csv``), ``section`` (the
    id of the report section that shows it), ``doc`` ("one row per …"), ``key`` (the
    columns that identify a row) and ``columns`` (what the others hold; may be empty)."""

    name: str
    section: str
    doc: str
    key: tuple[str, ...]
    columns: str = ""


_COMPARISON = "comparison (matched: the matched pair; all_pairs: every pair of the main part)"
_RULE = "rule (raw: the paper's reversal rate; sig: orderings significant under both)"

#: Every table of the report, in the order of its sections.
RESULT_TABLES: tuple[ResultTable, ...] = (
    ResultTable("evidence_headline", "answer",
                f"one headline rate against its null, per {_COMPARISON}, metric and {_RULE}",
                ("comparison", "metric", "rule"),
                "observed rate and its reversals/comparable; null_mean, null_sd, null_min, "
                "null_max over the null replicates (n_null, of kind `null`); excess = observed "
                "− null_mean with its simultaneous interval ci_low–ci_high (level, over a "
                "family of m rates), the verdict and the test it rests on (p_t, p_value, "
                "p_adj; against recombined designs also its one-sided p_above, p_below and "
                "p_small, the p_below of the rate less 5 pp); episode_ci_low–high: the "
                "episode-only interval (no test)"),
    ResultTable("evidence_interaction", "answer",
                "one interaction test — do controller differences change with the population "
                "more than under the null? — per comparison and metric",
                ("comparison", "metric"),
                "statistic (rankz: the mean over (pair, cell, controller pair) of the rank of "
                "|dD/SE| among the designs compared), reference (`recombined designs`: the "
                "exact randomization test over designs recombined unit by unit from the "
                "observed and its n_null replicates — null_mean, null_sd their T, t the "
                "standardized excess, df empty, p_t = p_value the randomization p; `prediction "
                "t`, a comparison of one unit: null_mean, null_sd of the n_null replicates' T, "
                "t on df, its one-sided p_t, p_value the exact permutation p), T, terms; p_adj "
                "(× family), alpha_row (the level each row is decided at), verdict"),
    ResultTable("evidence_null_rates", "answer",
                "one null replicate's rate, per comparison, metric and rule",
                ("comparison", "metric", "rule", "replicate"),
                "rate, reversals, comparable; episode_excludes_zero: the replicate as a "
                "placebo, whether the episode-only interval of its excess excludes 0; where "
                "the raw rule is decided against recombined designs, the placebo's one-sided "
                "randomization p-values placebo_p_above, placebo_p_below (and at +5 pp, "
                "+10 pp)"),
    ResultTable("evidence_burden", "answer",
                "one test of 'burden reverses more than robot time' against the null, per "
                "comparison, rule and burden metric", ("comparison", "rule", "metric"),
                "observed_difference and null_difference of rate(burden) − rate(robot time), "
                "their excess with its interval and verdict"),
    ResultTable("evidence_orderings", "answer",
                "one controller ordering of an observed population in a cell, with its "
                "paired-bootstrap interval",
                ("comparison", "metric", "backend", "mapping", "cell", "population", "ctrl_1",
                 "ctrl_2")),
    ResultTable("evidence_crossovers", "answer",
                "one crossover test of a controller pair in a cell across the observed "
                "populations (BH-adjusted), with the size it could detect",
                ("comparison", "metric", "backend", "mapping", "cell", "ctrl_1", "ctrl_2")),
    ResultTable("evidence_ranks", "ranks",
                "one controller's rank in one population, with its rank interval",
                ("comparison", "metric", "population", "controller"),
                "value: its grid mean; rank_low–rank_high: the 90% range over episode "
                "resamples; p_first: the share of resamples it ranks first"),
    ResultTable("evidence_pairs", "pairs",
                "one population pair of the all-pairs comparison and metric: its raw rate "
                "against the same pair in every null replicate", ("metric", "pair"),
                "observed with reversals/comparable; null_mean, null_sd (n_null replicates); "
                "excess, prediction t on df, p_t; p_holm (Holm over the table's family of "
                "rows), claim (above / below the null, or not shown); carries (the pair has a "
                "time-pressure population); null_mean_self (a pair with homogeneous: its null "
                "with homogeneous itself instead of one random member of mixed)"),
    ResultTable("evidence_pair_groups", "pairs",
                "one group of population pairs (with: a time-pressure population in the pair; "
                "others; difference: with − others) and metric, pooled against the same "
                "pooling of every null replicate", ("metric", "group"),
                "as evidence_pairs (Holm over this table's rows)"),
    ResultTable("evidence_pair_placebos", "pairs",
                "one rule of the pair tables (pairs, groups) on the study's placebos (each "
                "null replicate as the observed against the others)", ("rule",),
                "placebos, tables_with_claim, rate with its Clopper–Pearson interval "
                "ci_low–ci_high against the nominal level, rows tested, false_claims"),
    ResultTable("evidence_cohorts", "pairs",
                "one motion parameter of one cohort: its SD against random subsets of mixed "
                "of the cohort's size (the size-matched null's construction)",
                ("mapping", "cohort", "parameter"),
                "n, in_source (share of members whose profile is one of mixed), sd, random_sd "
                "(mean over draws subsets), sd_ratio, share_below (subsets at or below sd)"),
    ResultTable("evidence_cohort_overlaps", "pairs",
                "one pair of cohorts judged against size-matched subsets: the personas they "
                "share against two independent random subsets of their sizes",
                ("mapping", "cohort_a", "cohort_b"),
                "n_a, n_b, n_source, shared, expected, expected_sd (hypergeometric), p_low = "
                "P(overlap ≤ shared), p_high = P(overlap ≥ shared)"),
    ResultTable("evidence_curve", "replicates",
                "one headline rate on the first k seed sets", ("comparison", "metric", "rule",
                                                             "seed_sets")),
    ResultTable("evidence_replicability", "replicates",
                "one comparison's reversals seen in one seed set and whether they recur in "
                "another", ("comparison", "kind", "metric")),
    ResultTable("evidence_power", "replicates",
                "one headline rate and what would decide it: its row of evidence_headline with "
                "the seed sets and null replicates it needs at 80% power, and their cost",
                ("comparison", "metric", "rule"),
                "seed_sets_needed, nulls_needed, runs_needed, minutes_needed (from the "
                "study's measured speed), limit (what bounds it), sd_exponent (b: the null's "
                "SD falls as seed sets^−b)"),
    ResultTable("evidence_calibration", "calibration",
                "one claim of a verdict rule measured on the study's placebos, per comparison "
                "(all: pooled; table: the headline table as a whole)",
                ("comparison", "test", "rule", "claim"),
                "placebos, claims, rate with its Clopper–Pearson interval cp_low–cp_high, the "
                "nominal level, within and status (within, above nominal, too few placebos "
                "to tell)"),
    ResultTable("evidence_interaction_nulls", "calibration",
                "one null replicate's interaction statistic, per comparison and metric",
                ("comparison", "metric", "replicate"),
                "T (ranked among the observed and every replicate); placebo_t, placebo_p_t: "
                "the replicate as the observed against the others, by the row's reference"),
    ResultTable("evidence_placebo_crossovers", "calibration",
                "one crossover test on one null replicate's populations (a placebo)",
                ("comparison", "metric", "replicate")),
    ResultTable("audit_verdict", "audit", "one respondent's audit verdict with its figures",
                ("respondent",)),
    ResultTable("audit_spread", "audit",
                "one answer column of one respondent: the levels it uses and its entropy",
                ("respondent", "column")),
    ResultTable("audit_sensitivity", "audit",
                "one answer or motion parameter of one respondent: its R² on the persona "
                "fields against shuffled personas", ("respondent", "target")),
    ResultTable("audit_directions", "audit",
                "one expected direction (persona field → answer) of one respondent",
                ("respondent", "field", "target")),
    ResultTable("audit_manipulation", "audit",
                "one answer of one respondent under the matched intervention (deadline − "
                "baseline, paired)", ("respondent", "target")),
    ResultTable("audit_retest", "audit",
                "one answer or motion parameter of one respondent across its samples "
                "(test–retest)", ("respondent", "target")),
    ResultTable("audit_agreement", "audit",
                "one answer or motion parameter: agreement of the two respondents",
                ("target",)),
    ResultTable("no_robot_checks", "checks",
                "one population's pedestrians in the no-robot runs: arrivals and speeds",
                ("population",)),
    ResultTable("paired_share", "checks",
                "one controller's pedestrian records and the share with a paired delay",
                ("controller",),
                "n_paired: records with a paired delay (arrived with and without the robot), "
                "share = n_paired / n_records; n_blocked: arrived without the robot but not "
                "with it (no delay), blocked_share = n_blocked / (n_paired + n_blocked)"),
    ResultTable("findings", "summary",
                "one qualitative finding of the paper checked on this study's point estimates",
                ("key",), "holds; numbers: the figures it was checked on (JSON)"),
    ResultTable("evidence_findings", "summary",
                "one finding of the paper judged beyond noise: its statistic's interval",
                ("finding", "controller")),
    ResultTable("reversals", "table1",
                "one reversal rate of Table I, per comparison, cells (all or completed) and "
                "metric", ("comparison", "cells", "metric"),
                "reversals of comparisons, rate with its 95% cluster-bootstrap interval, "
                "paper_rate (the paper's), null_rate (its null's raw rate, where the study "
                "ran one)"),
    ResultTable("cell_metrics", "table1",
                "one controller in one population and cell of the main part: its metrics",
                ("backend", "mapping", "cell", "population", "controller"),
                "mean_delay, worst_decile, cvar90 [s] over the n_paired paired delays "
                "(pedestrians that arrived in both runs); blocked_pct [%] = 100 · n_blocked / "
                "(n_paired + n_blocked), the pedestrians that arrived without the robot but "
                "not with it"),
    ResultTable("noise_floor", "noise",
                "one reversal rate between two random halves of one population",
                ("population", "cells", "metric")),
    ResultTable("controller_outcomes", "table2", "one controller's outcomes (Table II)",
                ("controller",),
                "outcome shares [%] of its runs; robot_time [s]; mean_delay, worst_decile [s] "
                "and blocked_pct [%]: the mean of the cell_metrics column over (cell, "
                "population) rows"),
    ResultTable("delay_change", "change",
                "one controller's change in delay from a reference population (Fig. 2)",
                ("metric", "population", "reference", "controller")),
    ResultTable("sensitivity_by_width", "sensitivity",
                "one population sensitivity at one width, per scenes, cells and controller "
                "(pooled: all controllers)", ("scenes", "cells", "controller", "width")),
    ResultTable("population_sensitivity", "sensitivity",
                "one controller's range of mean delay across populations in one cell",
                ("backend", "mapping", "cell", "controller")),
    ResultTable("kendall_tau", "tau",
                "one pair of populations: the mean Kendall τ-b between their controller "
                "rankings",
                ("metric", "pop_a", "pop_b")),
    ResultTable("tradeoff", "tradeoff", "one controller's outcomes in one population",
                ("population", "controller")),
    ResultTable("robust_mapping", "mapping", "one reversal rate per mapping (Table III)",
                ("metric", "backend", "mapping")),
    ResultTable("robust_agreement", "mapping",
                "one mapping's share of controller orderings it shares with Mapping A",
                ("metric", "mapping")),
    ResultTable("robust_structure", "structure", "one reversal rate per perturbed profile set",
                ("metric", "backend", "mapping")),
    ResultTable("robust_backend", "backend", "one reversal rate per pedestrian backend",
                ("metric", "backend")),
    ResultTable("robust_respondent", "respondent",
                "one reversal rate of the matched pair per respondent's profile set",
                ("metric", "backend", "mapping")),
    ResultTable("robust_seeds", "seeds", "one reversal rate of a part on one seed set",
                ("part", "seed_set", "metric", "backend", "mapping")),
    ResultTable("replays", "replays", "one re-simulated run of an illustrative case",
                ("case", "index", "population", "controller"),
                "file: its replay page; reproduced: whether it matches its stored rows bit "
                "for bit (differences: the columns that do not)"),
)
#: the declaration by name
RESULTS: dict[str, ResultTable] = {t.name: t for t in RESULT_TABLES}


def result_table(name: str) -> ResultTable:
    """The declared report table ``name``; an :class:`UnknownNameError` otherwise."""
    if name not in RESULTS:
        raise UnknownNameError("report table", name, RESULTS)
    return RESULTS[name]


def csv_path(name: str) -> str:
    """The path of the declared table ``name``'s CSV relative to the report's index.html."""
    return f"{TABLES_DIR}/{result_table(name).name}.csv"


def check_declared(names: Iterable[str], what: str) -> None:
    """A ValueError naming every one of ``names`` (tables, or the keys of why tables are
    missing: ``what``) that :data:`RESULT_TABLES` does not declare."""
    undeclared = sorted(set(names) - set(RESULTS))
    if undeclared:
        raise ValueError(f"{what} not declared in popnavshift/result_tables.py: "
                         f"{', '.join(undeclared)}")


def section_tables(section: str) -> tuple[str, ...]:
    """The tables declared with report section ``section``, in declaration order."""
    return tuple(t.name for t in RESULT_TABLES if t.section == section)
