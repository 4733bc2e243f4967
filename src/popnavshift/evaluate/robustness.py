"""The card's robustness verdict: does the controller's standing against each baseline
change with the population beyond the null — decided against its own null runs.

The controller runs wherever the study's headline comparisons and their nulls run
(:mod:`.runs`), so each of its orderings against a baseline is tested exactly as the
study's headline is (:func:`popnavshift.analysis.evidence.test_comparisons`): per
comparison design (the matched pair against the swap permutations of its personas'
profiles, on every seed set the study ran them; the population pairs against the
size-matched subsets of mixed, on the main grid), per baseline b and ranked metric, the
rate at which the (controller, b) ordering reverses between the observed populations,
against the same rate on every null replicate — the same episodes, slots and
controllers, only the population label carries no information. The raw rule's verdict
rests on the prediction t between replicates, the significant rule's on the exact
permutation p (:mod:`popnavshift.analysis.verdicts`); every rate of the card's table is
decided at α/m (Bonferroni over its m rates per rule,
:func:`popnavshift.analysis.nulls.family_verdicts`), so its claims hold together.

The card's label, from the raw rule (whose rates the power advice and the calibration
measure): **population-sensitive** when some (design, baseline, metric) rate is above
its null (the rows that carry it are named); **robust** when every rate's simultaneous
interval rules out an excess of 5 pp (``MIN_EFFECT``); **undecided** otherwise, with what
would decide it. The false-positive rate of each rule on this controller's own placebos
(a null replicate taken as the observed against the others) is the card's calibration
(:func:`popnavshift.analysis.calibrate.calibration_table`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd

from ..analysis.calibrate import calibration_table
from ..analysis.evidence import complete_design, test_comparisons
from ..analysis.nulls import design_populations, family_verdicts, headline_designs
from ..analysis.replicates import seed_sets
from ..analysis.verdicts import ABOVE, ALPHA, BELOW, MIN_EFFECT, SMALL
from ..populations.identity import PopulationSpec, spec_of
from ..tables import NO_ROBOT

SENSITIVE, ROBUST, UNDECIDED_LABEL = "population-sensitive", "robust", "undecided"
#: the columns of the card's robustness table, in order
COLUMNS = ("design", "baseline", "metric", "rule", "observed", "null_mean", "excess", "ci_low",
           "ci_high", "t", "df", "p_t", "p_value", "p_adj", "n_null", "verdict", "family",
           "level", "seed_sets", "null")


@dataclass
class Robustness:
    """The card's robustness tables: ``headline`` (one row per design, baseline, metric and
    rule, decided over the card's table), ``null_rates`` (every replicate's rate),
    ``calibration`` (each rule's false-positive rate on the card's own placebos), the
    ``label`` and its ``text``; ``missing`` says why a design could not be tested."""

    headline: pd.DataFrame
    null_rates: pd.DataFrame
    calibration: pd.DataFrame
    label: str
    text: str
    missing: dict[str, str]


def comparison_key(design: str, baseline: str) -> str:
    """The comparison label of one (design, baseline) in the card's tables."""
    return f"{design} vs {baseline}"


def robustness_tables(runs: pd.DataFrame, peds: pd.DataFrame, controller: str,
                      baselines: Sequence[str], specs: Mapping[str, PopulationSpec],
                      observed: Sequence[str], *, rng_seed: int = 0, n_boot: int = 1000
                      ) -> Robustness:
    """The card's robustness verdict (module doc) from the evaluation parts' ``runs`` and
    ``peds`` (the controller, the baselines and no robot); ``specs``: the study's
    populations by name; ``observed``: the main part's populations."""
    present = [spec_of(specs, p) for p in runs["population"].unique()]
    conditions = {s.name for s in present if s.role == "observed"}
    designs = headline_designs(present, [p for p in observed if p in conditions])
    heads, nulls, missing = [], [], {}
    for i, (label, design) in enumerate(designs.items()):
        if not design.nulls:
            missing[label] = f"the study ran no null of the {label} comparison"
            continue
        pops = design_populations(design)
        for j, base in enumerate(baselines):
            keep = [controller, base, NO_ROBOT]
            r, p = complete_design(runs[runs["controller"].isin(keep)],
                                   peds[peds["controller"].isin(keep)], pops)
            if r.empty or not {controller, base} <= set(r["controller"]):
                missing[comparison_key(label, base)] = "no episode holds both controllers"
                continue
            key = comparison_key(label, base)
            obs_pops = list(dict.fromkeys(x for pair in design.observed for x in pair))
            tested = test_comparisons(r, p, {key: design}, obs_pops,
                                      rng=np.random.default_rng([rng_seed, i, j]),
                                      n_boot=n_boot, rates_only=True)
            heads.append(tested.headline.assign(
                design=label, baseline=base, seed_sets=int(seed_sets(r).nunique()),
                null=design.null))
            nulls.append(tested.null_rates.assign(design=label, baseline=base))
    if not heads:
        return Robustness(pd.DataFrame(columns=COLUMNS), pd.DataFrame(), pd.DataFrame(),
                          UNDECIDED_LABEL, "no null design to decide against: "
                          + "; ".join(missing.values()), missing)
    null_rates = pd.concat(nulls, ignore_index=True)
    head = family_verdicts(pd.concat(heads, ignore_index=True), null_rates)
    family = int(head.loc[head["rule"] == "raw", "family"].max())
    calibration = calibration_table(null_rates, family=family)
    label, text = robustness_label(head, controller)
    return Robustness(head[[c for c in COLUMNS if c in head]], null_rates, calibration, label,
                      text, missing)


def robustness_label(head: pd.DataFrame, controller: str) -> tuple[str, str]:
    """The card's label and its sentence from the raw rule's decided rows (module doc)."""
    raw = head[head["rule"] == "raw"]
    level = f"{100 * (1 - ALPHA):.0f}% simultaneous intervals over {len(raw)} rates"
    above = raw[raw["verdict"] == ABOVE]
    if len(above):
        where = "; ".join(f"{r.metric} against {r.baseline} ({r.design}: "
                          f"{100 * r.excess:+.1f} pp [{100 * r.ci_low:+.1f}, "
                          f"{100 * r.ci_high:+.1f}])" for r in above.itertuples())
        return SENSITIVE, (f"{controller}'s orderings reverse with the population more often "
                           f"than under its own null runs: {where} ({level}).")
    settled = raw["verdict"].isin([SMALL, BELOW])
    if len(raw) and settled.all():
        worst = float(raw["ci_high"].max())
        return ROBUST, (f"No excess of {100 * MIN_EFFECT:.0f} pp over the null in any of its "
                        f"{len(raw)} reversal rates (largest upper end {100 * worst:+.1f} pp; "
                        f"{level}).")
    open_rows = raw[~settled]
    where = ", ".join(f"{r.metric} vs {r.baseline} ({r.design})"
                      for r in open_rows.itertuples())
    return UNDECIDED_LABEL, (f"Neither an excess over the null nor its absence (< "
                             f"{100 * MIN_EFFECT:.0f} pp) is shown for {where} ({level}).")
