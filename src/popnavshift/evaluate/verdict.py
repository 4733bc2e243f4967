"""The card's two verdicts and the main part's evidence behind its tables.

**Robustness** (:mod:`.robustness`): do the controller's orderings against the baselines
reverse with the population more often than under its own null runs — population-sensitive,
robust (an excess of 5 pp ruled out) or undecided (with what would decide it); a controller
that reaches the goal in none of its runs *fails every run*, and its rankings mean nothing.
**Safety** (:mod:`.safety`): one absolute rule for every controller. The two are never one
label: a safe controller can be population-sensitive, an unsafe one robust.

The main part's evidence, shown beside them (pure: runs + pedestrians → the paired episode
bootstrap, :mod:`popnavshift.analysis.resample` → per metric, every controller ordering
with its interval, :func:`popnavshift.analysis.significance.orderings`):

* **ranks**: its rank per population among the compared controllers, with the rank
  interval over resamples (:func:`popnavshift.analysis.evidence.controller_ranks`);
* **wins / losses**: per (population, baseline, metric), the cells where it is
  significantly better (lower), significantly worse, or tied;
* **crossovers**: per (cell, baseline, metric), the paired intersection–union test of a
  qualitative interaction across the populations, Holm-adjusted over the card's table,
  with the crossover size each could detect (a table of the card, not its verdict: it
  has no power at the main part's 3 variants per cell, where the null-based rates do).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from ..analysis.delay import cell_metrics, paired_delays
from ..analysis.evidence import controller_ranks
from ..analysis.interaction import CHANGES
from ..analysis.resample import build_design, episode_weights, resampled_metrics
from ..analysis.reversals import METRICS
from ..analysis.significance import (
    ALPHA,
    LEVEL,
    crossover_tests,
    detectable_crossover,
    holm,
    orderings,
)
from ..populations.build import population_order
from .robustness import UNDECIDED_LABEL, Robustness
from .safety import SafetyVerdict

#: The card's one metric set, the paper's three: the evidence tables and figure use it.
VERDICT_METRICS: tuple[str, ...] = METRICS
FAILS = "fails every run"


@dataclass
class Verdict:
    """The card's robustness verdict (label, sentence, and what would decide it when
    undecided) and its safety verdict."""

    robustness: str
    robustness_text: str
    safety: SafetyVerdict
    decide: str = ""
    #: the robustness table's row that carries the label (:func:`.robustness.deciding_row`)
    row: dict = field(default_factory=dict)
    #: the second question: do its differences from the baselines change with the
    #: population beyond its null (:func:`.robustness.interaction_sentence`)
    interaction: str = ""
    #: its rows showing a change beyond the null, and its rows tested
    interaction_rows: tuple[int, int] = (0, 0)


@dataclass
class Evidence:
    """The main part's evidence tables (see the module doc)."""

    ranks: pd.DataFrame  # metric, population, controller, value, rank, rank_low, rank_high, …
    wins: pd.DataFrame  # metric, baseline, population, better, worse, tied
    crossovers: pd.DataFrame  # metric, baseline, cell…, p, p_adj (Holm over the table), crossover


def _oriented(table: pd.DataFrame, controller: str) -> pd.DataFrame:
    """Rows comparing ``controller`` with another, with diff/sig/sign as controller − other."""
    mine = (table["ctrl_1"] == controller) | (table["ctrl_2"] == controller)
    t = table[mine].copy()
    flip = (t["ctrl_2"] == controller).to_numpy()
    t["baseline"] = np.where(flip, t["ctrl_1"], t["ctrl_2"])
    for col in ("diff", "sig", "sign"):
        t[col] = np.where(flip, -t[col], t[col])
    return t


def card_evidence(runs: pd.DataFrame, pedestrians: pd.DataFrame, controller: str,
                  baselines: tuple[str, ...], *, rng: np.random.Generator, n_boot: int = 1000,
                  level: float = LEVEL) -> Evidence:
    """Ranks, wins/losses and crossover tests of ``controller`` (module doc)."""
    paired = paired_delays(pedestrians)
    cells = cell_metrics(runs, paired)
    design = build_design(runs, paired)
    weights = episode_weights(design, n_boot, rng)
    pops = population_order(cells["population"].unique())
    ranks, wins, cross = [], [], []
    for metric in VERDICT_METRICS:
        boot = resampled_metrics(design, weights, (metric,))
        o = orderings(cells, design, boot, metric, level=level, populations=pops)
        t = _oriented(o.table(), controller)
        t = t[t["baseline"].isin(baselines) & t["diff"].notna()]
        ranks.append(controller_ranks(cells, boot[metric], metric, pops, level=level))
        g = t.groupby(["baseline", "population"], sort=False)["sig"]
        w = pd.DataFrame({"better": g.apply(lambda s: int((s == -1).sum())),
                          "worse": g.apply(lambda s: int((s == 1).sum())),
                          "tied": g.apply(lambda s: int((s == 0).sum()))}).reset_index()
        wins.append(w.assign(metric=metric))
        c = crossover_tests(o, pops)
        mine = (c["ctrl_1"] == controller) | (c["ctrl_2"] == controller)
        c = c[mine].assign(metric=metric, baseline=np.where(c.loc[mine, "ctrl_1"] == controller,
                                                            c.loc[mine, "ctrl_2"],
                                                            c.loc[mine, "ctrl_1"]))
        cross.append(c[c["baseline"].isin(baselines)])
    tests = pd.concat(cross, ignore_index=True)
    tests["p_adj"] = holm(tests["p"].to_numpy(float))  # over the card's whole table
    tests["crossover"] = tests["p_adj"] <= ALPHA
    tests["detectable"] = detectable_crossover(  # at the card's table size
        tests["se"].to_numpy(float), tests["n_episodes"].to_numpy(float),
        tests["n_populations"].to_numpy(float), int(tests["p"].notna().sum()))
    return Evidence(pd.concat(ranks, ignore_index=True), pd.concat(wins, ignore_index=True),
                    tests)


def card_verdict(runs: pd.DataFrame, controller: str, robustness: Robustness,
                 safety: SafetyVerdict, decide: str = "") -> Verdict:
    """The card's two verdicts (module doc): the robustness verdict against its own null
    runs (*fails every run* when it reached the goal in none of ``runs``, its runs on the
    main part) and the safety verdict; ``decide``: what would decide an undecided
    robustness verdict (a command with its runs and minutes)."""
    own = runs[runs["controller"] == controller]
    if len(own) == 0 or not (own["outcome"] == "success").any():
        return Verdict(FAILS, f"It reached the goal in none of its {len(own)} runs: its "
                       "rankings mean nothing.", safety)
    return Verdict(robustness.label, robustness.text, safety,
                   decide if robustness.label == UNDECIDED_LABEL else "", robustness.row,
                   robustness.interaction_text, interaction_counts(robustness.interaction))


def interaction_counts(inter: pd.DataFrame) -> tuple[int, int]:
    """(rows whose differences change beyond the null, rows tested) of a card's interaction
    table."""
    if inter.empty:
        return 0, 0
    tested = inter[inter["verdict"] != "descriptive"]
    return int((tested["verdict"] == CHANGES).sum()), len(tested)
