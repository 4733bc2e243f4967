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
rests on the prediction t between replicates (across the population pairs, as the
headline's, on the exact randomization test over designs recombined from them,
:mod:`popnavshift.analysis.recombine`), the significant rule's on the exact
permutation p (:mod:`popnavshift.analysis.verdicts`); every rate of the card's table is
decided at α/m (Bonferroni over its m rates per rule,
:func:`popnavshift.analysis.nulls.family_verdicts`), so its claims hold together.

Its second question, as the study's (:mod:`popnavshift.analysis.interaction`): do the
controller's differences from the baselines change with the population more than under its
null runs — the rankz interaction test on the controller's pairs only, per design and
metric, one-sided (across the population pairs the exact test over recombined designs,
under the matched shift the prediction t), decided over the card's interaction rows (α/m),
with its placebos in the card's calibration. It says nothing of orderings crossing; the
label does.

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
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd

from ..analysis.calibrate import calibration_table
from ..analysis.evidence import complete_design, test_comparisons
from ..analysis.interaction import (
    CHANGES,
    NO_TERMS,
    interaction_placebos,
    interaction_verdicts,
)
from ..analysis.nulls import design_populations, family_verdicts, headline_designs
from ..analysis.ranked import RANKED_METRICS
from ..analysis.replicates import seed_sets
from ..analysis.reversals import COMPARISONS
from ..analysis.verdicts import ABOVE, ALPHA, BELOW, MIN_EFFECT, SMALL
from ..controller_ids import display_name
from ..populations.identity import PopulationSpec, spec_of
from ..tables import NO_ROBOT

RANKED = {m.name: m for m in RANKED_METRICS}
SENSITIVE, ROBUST, UNDECIDED_LABEL = "population-sensitive", "robust", "undecided"
#: the columns of the card's robustness table, in order
COLUMNS = ("design", "baseline", "metric", "rule", "observed", "null_mean", "excess", "ci_low",
           "ci_high", "t", "df", "p_t", "p_value", "p_adj", "n_null", "verdict", "test",
           "family", "level", "seed_sets", "null")


@dataclass
class Robustness:
    """The card's robustness tables: ``headline`` (one row per design, metric and rule: the
    controller's orderings against every baseline pooled, decided over the card's table),
    ``null_rates`` (every replicate's rate), ``by_baseline`` (the same per baseline, decided
    over its own table: which baseline carries a verdict), ``calibration`` (each rule's
    false-positive rate on the card's own placebos), the ``label`` and its ``text``;
    ``missing`` says why a design could not be tested."""

    headline: pd.DataFrame
    null_rates: pd.DataFrame
    by_baseline: pd.DataFrame
    calibration: pd.DataFrame
    label: str
    text: str
    missing: dict[str, str]
    #: the raw-rule row that carries the label (:func:`deciding_row`), empty without one
    row: dict = field(default_factory=dict)
    #: the interaction test per design and metric, decided over its rows (module doc)
    interaction: pd.DataFrame = field(default_factory=pd.DataFrame)
    #: the second question's answer in one sentence
    interaction_text: str = ""


def robustness_tables(runs: pd.DataFrame, peds: pd.DataFrame, controller: str,
                      baselines: Sequence[str], specs: Mapping[str, PopulationSpec],
                      observed: Sequence[str], *, rng_seed: int = 0, n_boot: int = 1000,
                      interaction: bool = True) -> Robustness:
    """The card's robustness verdict (module doc) from the evaluation parts' ``runs`` and
    ``peds`` (the controller, the baselines and no robot); ``specs``: the study's
    populations by name; ``observed``: the main part's populations; ``interaction``: ask
    the second question too (a card always does; the label does not depend on it)."""
    present = [spec_of(specs, p) for p in runs["population"].unique()]
    conditions = {s.name for s in present if s.role == "observed"}
    designs = headline_designs(present, [p for p in observed if p in conditions])
    keep = [controller, *baselines, NO_ROBOT]
    runs, peds = runs[runs["controller"].isin(keep)], peds[peds["controller"].isin(keep)]
    frames: dict[str, list[pd.DataFrame]] = {"head": [], "null": [], "pair": [], "pair_null": [],
                                             "inter": [], "inter_null": []}
    refs: dict[tuple[str, str, str], np.ndarray] = {}  # recombined rates, per table row
    pair_refs: dict[tuple[str, str, str], np.ndarray] = {}
    missing: dict[str, str] = {}
    for i, (label, design) in enumerate(designs.items()):
        if not design.nulls:
            missing[label] = f"the study ran no null of the {label} comparison"
            continue
        r, p = complete_design(runs, peds, design_populations(design))
        if r.empty or controller not in set(r["controller"]):
            missing[label] = f"no episode of the {label} design holds the controller's runs"
            continue
        obs_pops = list(dict.fromkeys(x for pair in design.observed for x in pair))
        tested = test_comparisons(r, p, {label: design}, obs_pops,
                                  rng=np.random.default_rng([rng_seed, i]), n_boot=n_boot,
                                  rates_only=True, controller=controller,
                                  interaction=interaction)
        extra = {"design": label, "seed_sets": int(seed_sets(r).nunique()),
                 "null": design.null}
        frames["head"].append(tested.headline.assign(baseline="all", **extra))
        frames["null"].append(tested.null_rates.assign(baseline="all", design=label))
        # per baseline, the comparison label names the baseline: every rate of the
        # breakdown is one test of its own family and one comparison of its placebos
        by = tested.pair_headline.assign(**extra)
        frames["pair"].append(by.assign(comparison=_versus(by["comparison"], by["baseline"])))
        refs.update(tested.references)
        pair_refs.update({(_versus(c, b), m, rule): v
                          for (c, b, m, rule), v in tested.pair_references.items()})
        pn = tested.pair_null_rates
        frames["pair_null"].append(pn.assign(
            design=label, comparison=_versus(pn["comparison"], pn["baseline"])))
        if not tested.interaction.empty:
            frames["inter"].append(tested.interaction.assign(**extra))
            frames["inter_null"].append(tested.interaction_nulls)
    if not frames["head"]:
        empty = pd.DataFrame(columns=COLUMNS)
        return Robustness(empty, pd.DataFrame(), empty, pd.DataFrame(), UNDECIDED_LABEL,
                          "no null design to decide against: " + "; ".join(missing.values())
                          + ". A study with null parts decides it: the paper study (`make "
                          "run`, then evaluate without --study).",
                          missing)
    cat = {k: pd.concat(v, ignore_index=True) if v else pd.DataFrame()
           for k, v in frames.items()}
    head = family_verdicts(cat["head"], cat["null"], references=refs)
    by_baseline = family_verdicts(cat["pair"], cat["pair_null"], references=pair_refs)
    family = int(head.loc[head["rule"] == "raw", "family"].max())
    inter = interaction_verdicts(cat["inter"]) if not cat["inter"].empty else cat["inter"]
    calibration = calibration_table(
        cat["null"], family=family,
        interaction=None if inter.empty else interaction_placebos(cat["inter_null"],
                                                                 int(inter["family"].max())))
    named = display_name(controller)
    label, text = robustness_label(head, by_baseline, named)
    columns = [c for c in COLUMNS if c in head]
    return Robustness(head[columns], cat["null"], by_baseline[columns], calibration, label,
                      text, missing, deciding_row(head, label), inter,
                      interaction_sentence(inter, named))


def _versus(comparison: Any, baseline: Any) -> Any:
    """The per-baseline table's comparison label, ``<design> vs <baseline>`` (strings or
    columns): every rate of the breakdown is one comparison of its own."""
    return comparison + " vs " + baseline


def interaction_sentence(inter: pd.DataFrame, controller: str) -> str:
    """The card's second answer in words: which (design, metric) rows show the controller's
    differences from the baselines changing with the population beyond its null, or that
    none does (and at what level)."""
    if inter.empty:
        return ""
    tested = inter[inter["verdict"] != "descriptive"]
    if tested.empty:
        why = (NO_TERMS if "terms" in inter and (inter["terms"] == 0).all()
               else "too few null replicates")
        return (f"Whether {controller}'s differences from the baselines change with the "
                f"population is not tested: {why}.")
    level = f"one-sided, α/{int(inter['family'].max())} over its {len(tested)} rows"
    yes = tested[tested["verdict"] == CHANGES]
    if len(yes):
        where = "; ".join(f"{_words(r.metric)} ({_place(r.design)}: t {r.t:.1f})"
                          for r in yes.itertuples())
        return (f"{controller}'s differences from the baselines change with the population "
                f"more than under its own null runs for {len(yes)} of {len(tested)} rows: "
                f"{where} ({level}; whether orderings cross is the label's question).")
    return (f"{controller}'s differences from the baselines are not shown to change with the "
            f"population more than under its own null runs in any of {len(tested)} rows "
            f"(largest t {tested['t'].max():.1f}; {level}).")


def deciding_row(head: pd.DataFrame, label: str) -> dict:
    """The raw-rule row a leaderboard shows for the label: the rate most above its null for
    *population-sensitive* (largest t), else the rate whose interval reaches highest (what
    *robust* had to rule out, or what keeps *undecided* open)."""
    raw = head[head["rule"] == "raw"]
    above = raw[raw["verdict"] == ABOVE]
    if label == SENSITIVE and len(above):
        row = above.loc[above["t"].idxmax()]
    elif raw["ci_high"].notna().any():
        row = raw.loc[raw["ci_high"].idxmax()]
    else:  # no rate had a spread between its replicates to be judged by
        return {}
    keep = ("design", "metric", "observed", "null_mean", "excess", "ci_low", "ci_high", "t",
            "p_adj", "p_value", "verdict")
    return {k: (v.item() if hasattr(v, "item") else v) for k, v in row.items() if k in keep}


def robustness_label(head: pd.DataFrame, by_baseline: pd.DataFrame,
                     controller: str) -> tuple[str, str]:
    """The card's label and its sentence from the raw rule's decided rows (module doc); a
    population-sensitive verdict names the baselines whose own rates are above their null."""
    raw = head[head["rule"] == "raw"]
    level = f"{100 * (1 - ALPHA):.0f}% simultaneous intervals over {len(raw)} rates"
    above = raw[raw["verdict"] == ABOVE]
    if len(above):
        pairs = by_baseline[(by_baseline["rule"] == "raw") & (by_baseline["verdict"] == ABOVE)]
        where = "; ".join(f"{_words(r.metric)} ({_place(r.design)}: {100 * r.excess:+.1f} pp "
                          f"[{100 * r.ci_low:+.1f}, {100 * r.ci_high:+.1f}])"
                          for r in above.itertuples())
        carried = ("; against " + ", ".join(sorted(set(pairs["baseline"]))) + " alone"
                   if len(pairs) else "; no baseline alone carries it")
        return SENSITIVE, (f"{controller}'s orderings against the baselines reverse with the "
                           f"population more often than under its own null runs: {where}"
                           f"{carried} ({level}).")
    settled = raw["verdict"].isin([SMALL, BELOW])
    if len(raw) and settled.all():
        worst = float(raw["ci_high"].max())
        return ROBUST, (f"No excess of {100 * MIN_EFFECT:.0f} pp over the null in any of its "
                        f"{len(raw)} reversal rates (largest upper end {100 * worst:+.1f} pp; "
                        f"{level}).")
    open_rows = raw[~settled]
    width = open_rows["ci_high"] - open_rows["ci_low"]
    if width.isna().all():
        return UNDECIDED_LABEL, (f"None of its {len(raw)} rates could be judged: its null "
                                 "replicates did not vary (or were too few).")
    widest = open_rows.loc[width.idxmax()]
    return UNDECIDED_LABEL, (f"Neither an excess over the null nor its absence (< "
                             f"{100 * MIN_EFFECT:.0f} pp) is shown for {len(open_rows)} of "
                             f"its {len(raw)} rates; the least decided: "
                             f"{_words(widest.metric)} ({_place(widest.design)}: "
                             f"{100 * widest.excess:+.1f} pp "
                             f"[{100 * widest.ci_low:+.1f}, {100 * widest.ci_high:+.1f}]) "
                             f"({level}).")


def _words(metric: str) -> str:
    """``mean delay``: a ranked metric in words (its id when it is not one)."""
    m = RANKED.get(metric)
    return m.label if m is not None else metric


def _place(design: str) -> str:
    """``across the population pairs``: where a comparison design's rate was measured."""
    c = COMPARISONS.get(design)
    return c.phrase if c is not None else design
