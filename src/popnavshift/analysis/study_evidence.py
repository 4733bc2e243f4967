"""A study's evidence tables: do rankings change with the population beyond noise?

``evidence_tables(study)`` selects, from a study folder, the runs of each headline
comparison at its own design — the matched pair with its swap null over every seed
set they share, the populations of the ``main`` part with their size-matched null
on the main grid — and computes with :mod:`popnavshift.analysis` (pure functions):

* ``evidence_headline``: observed vs null rates per (comparison, metric, rule), the
  verdict with its deciding interval and test (:mod:`.verdicts`), the permutation p and the
  episode-only interval;
* ``evidence_interaction``: do controller differences change with the population more than
  under the null (:mod:`.interaction`), per (comparison, metric), decided as one family;
  ``evidence_interaction_nulls``: every null replicate's statistic and its placebo;
* ``evidence_null_rates``: every null replicate's rate;
* ``evidence_calibration``: every verdict rule's false-positive rate on placebos drawn
  from those replicates (:mod:`.calibrate`), with ``evidence_placebo_crossovers``;
* ``evidence_crossovers``: crossover tests per comparison, BH-adjusted, with the size each
  could detect;
* ``evidence_orderings``: every observed controller ordering with its interval;
* ``evidence_ranks``: each controller's rank per population with rank intervals;
* ``evidence_curve``, ``evidence_replicability``: each comparison run on several seed sets
  against their number; ``evidence_power``: what would decide each undecided rate, and its
  cost (:mod:`.power`);
* ``evidence_findings``: the paper's findings under the significance rule
  (:mod:`popnavshift.analysis.surviving`), and ``evidence_burden``: "burden reverses
  more than robot time" against the nulls.

``with_null_rates`` then gives Table I (``reversals``) the null rate of each comparison.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from ..populations.identity import spec_of
from ..read.folder import StudyFolder
from ..tables import NO_ROBOT
from .calibrate import calibration_table
from .evidence import complete_design, test_comparisons
from .interaction import interaction_placebos, interaction_verdicts
from .nulls import (
    Design,
    burden_beyond_time,
    design_populations,
    family_verdicts,
    headline_designs,
)
from .pair_excess import pair_tables
from .power import Costs, design_advice
from .ranked import names
from .replicates import replicability, replicate_curve, seed_sets, variants_per_cell
from .significance import LEVEL
from .surviving import surviving_findings
from .verdicts import ALPHA

PREFIX = "evidence_"
HEADLINE = PREFIX + "headline"


def lacks(missing: dict[str, str], table: str, why: str) -> None:
    """Say in ``missing`` why (part of) ``table`` could not be computed: one reason per
    comparison, joined."""
    missing[table] = f"{missing[table]}; {why}" if table in missing else why


def evidence_tables(study: StudyFolder, *, rng_seed: int = 0, n_boot: int = 1000,
                    level: float = LEVEL, null_sizes: dict[str, int] | None = None
                    ) -> tuple[dict[str, pd.DataFrame], dict[str, str]]:
    """Every evidence table of the study (see the module doc) and why any is missing (by the
    table's name). ``null_sizes``: per null kind (``swap``, ``sized``), the replicates each
    placebo of the calibration is judged against (``calibrate --replicates``: the design of
    the study that was extended; :func:`.calibrate.placebo_nulls`)."""
    main = study.main_part()
    if main is None:
        return {}, {HEADLINE: "the study has no main part (name one `main` or declare "
                              "`role: main`)"}
    populations, backends, mappings = main[1].populations, main[1].backends, main[1].mappings
    runs = study.runs[study.runs["backend"].isin(backends)
                      & study.runs["mapping"].isin(mappings)]
    peds = study.pedestrians[study.pedestrians["backend"].isin(backends)
                             & study.pedestrians["mapping"].isin(mappings)]
    index = study.population_specs
    present = [spec_of(index, p) for p in runs["population"].unique()]
    conditions = {s.name for s in present if s.role == "observed"}
    observed = [p for p in populations if p in conditions]
    designs = headline_designs(present, observed)
    if not designs:
        return {}, {HEADLINE: "the study has neither the matched pair nor two populations"}
    sizes = {label: null_sizes[d.null] for label, d in designs.items()
             if null_sizes and d.null in null_sizes}
    seed = 0 if study.seed is None else int(study.seed)
    frames: dict[str, list[pd.DataFrame]] = {}
    missing: dict[str, str] = {}
    boot_excess: dict[tuple[str, str, str], np.ndarray] = {}
    references: dict[tuple[str, str, str], np.ndarray] = {}
    costs: dict[str, Costs] = {}
    for i, (label, design) in enumerate(designs.items()):
        pops = design_populations(design)
        r, p = complete_design(runs, peds, pops)
        if r.empty:
            lacks(missing, HEADLINE, f"no episode has runs of every population of the {label} "
                                     "design")
            continue
        if (r["controller"] == NO_ROBOT).all():
            lacks(missing, HEADLINE, f"the {label} design has no robot runs")
            continue
        obs_pops = list(dict.fromkeys(x for pair in design.observed for x in pair))
        one = {label: design}
        tested = test_comparisons(r, p, one, obs_pops, rng=np.random.default_rng([rng_seed, i]),
                                  n_boot=n_boot, level=level, null_sizes=sizes)
        n_sets = int(seed_sets(r).nunique())
        per_cell = variants_per_cell(r)  # the study's own episodes, not the paper's 3/set
        head = tested.headline.assign(null=design.null,
                                      seed_sets=n_sets, variants_per_cell=per_cell)
        add = {"headline": head, "null_rates": tested.null_rates,
               "crossovers": tested.crossovers,
               "placebo_crossovers": tested.placebo_crossovers,
               "orderings": tested.orderings.assign(comparison=label),
               "ranks": tested.ranks.assign(comparison=label)}
        add.update(_replicates(r, p, one, obs_pops, tested.headline, label=label, seed=seed,
                               rng_seed=rng_seed, level=level, missing=missing))
        boot_excess.update(tested.boot_excess)
        references.update(tested.references)
        if not tested.pair_counts.empty:
            pops_table = study.populations
            add.update(pair_tables(tested.pair_counts, None if pops_table is None else
                                   pops_table[pops_table["mapping"].isin(mappings)], design,
                                   index, seed=seed))
        elif len(design.observed) > 1:
            lacks(missing, PREFIX + "pairs", f"the study ran no null of the {label} comparison")
        if tested.interaction.empty:
            lacks(missing, PREFIX + "interaction", f"the study ran no null of the {label} "
                                                   "comparison")
        else:
            add["interaction"] = tested.interaction.assign(null=design.null, seed_sets=n_sets,
                                                           variants_per_cell=per_cell)
            add["interaction_nulls"] = tested.interaction_nulls
        if head["n_null"].max() > 0:
            costs[label] = design_costs(r, obs_pops, design.nulls, study.manifest)
        else:
            lacks(missing, PREFIX + "power", f"the study ran no null of the {label} "
                                             f"comparison (a {design.null} null part)")
        if label == "all_pairs":
            add["findings"] = surviving_findings(r[r["population"].isin(obs_pops)],
                                                 p[p["population"].isin(obs_pops)],
                                                 rng=np.random.default_rng([rng_seed, 99]),
                                                 n_boot=n_boot, level=level)
        for k, v in add.items():
            frames.setdefault(k, []).append(v)
    tables = {PREFIX + k: pd.concat(v, ignore_index=True) for k, v in frames.items()}
    if PREFIX + "headline" in tables:
        tables.update(_decided(tables, boot_excess, costs, sizes, references))
    return tables, missing


def _decided(tables: dict[str, pd.DataFrame], boot_excess: dict, costs: dict[str, Costs],
             null_sizes: dict[str, int] | None = None, references: dict | None = None
             ) -> dict[str, pd.DataFrame]:
    """The headline's verdicts with multiplicity control over its table, "burden beyond
    robot time" with control over its own, the interaction test's over its own rows, the
    power advice at the headline's level, and the calibration on placebos."""
    nulls = tables[PREFIX + "null_rates"]
    head = family_verdicts(tables[PREFIX + "headline"], nulls, references=references)
    comps = list(dict.fromkeys(head["comparison"]))
    burden_metrics = names("burden", summary=True)
    m = max(sum(c in costs for c in comps) * len(burden_metrics), 1)
    burden = [burden_beyond_time(head[head["comparison"] == c], nulls, boot_excess, burden=b,
                                 alpha=ALPHA / m)
              for c in comps for b in burden_metrics]
    inter = tables.get(PREFIX + "interaction")
    inter = interaction_verdicts(inter) if inter is not None and not inter.empty else None
    inter_nulls = tables.get(PREFIX + "interaction_nulls")
    out = {PREFIX + "headline": head,
           PREFIX + "burden": pd.concat(burden, ignore_index=True).assign(family=m),
           PREFIX + "calibration": calibration_table(
               nulls, tables.get(PREFIX + "placebo_crossovers"),
               family=int(head.loc[head["rule"] == "raw", "family"].max()),
               null_kinds=dict(zip(head["comparison"], head["null"], strict=True)),
               interaction=None if inter is None or inter_nulls is None else
               interaction_placebos(inter_nulls, int(inter["family"].max())),
               null_sizes=null_sizes)}
    if inter is not None:
        out[PREFIX + "interaction"] = inter
    curves = tables.get(PREFIX + "curve")
    power = []
    for c in comps:
        if c not in costs:
            continue
        h = head[head["comparison"] == c]
        # only a comparison's own curve says how its null's spread falls with seed sets:
        # another comparison's null is of another kind (swap vs size-matched)
        curve = (curves[curves["comparison"] == c]
                 if curves is not None and not curves.empty else None)
        power.append(design_advice(h, curve, costs[c], alpha=ALPHA / int(h["family"].max())))
    if power:
        out[PREFIX + "power"] = pd.concat(power, ignore_index=True)
    return out


def design_costs(runs: pd.DataFrame, observed: list[str], nulls: list, manifest: dict
                 ) -> Costs:
    """What one more seed set or null replicate of a comparison design costs, from its runs
    and the study's measured throughput (``manifest.json``'s timings)."""
    n_sets = max(int(seed_sets(runs).nunique()), 1)
    per_pop = float(runs[runs["population"].isin(observed)].groupby("population").size().mean())
    per_rep = len({x for pair in nulls[0] for x in pair} - set(observed)) if nulls else 0
    t = manifest.get("timings", {})
    speed = (t["runs_executed"] / t["simulation_s"]
             if t.get("simulation_s") and t.get("runs_executed") else float("nan"))
    return Costs(per_pop / n_sets, len(observed), per_rep, speed)


def _replicates(runs: pd.DataFrame, peds: pd.DataFrame, design: dict[str, Design],
                observed: list[str],
                full: pd.DataFrame, *, label: str, seed: int, rng_seed: int, level: float,
                missing: dict[str, str]) -> dict[str, pd.DataFrame]:
    """A comparison against its seed sets: rates curve and replicability (the curve is what
    the power advice measures the fall of the null's spread on)."""
    if int(seed_sets(runs).nunique()) < 2:
        lacks(missing, PREFIX + "curve", f"the {label} comparison was run on one episode seed "
                                         "set: add `seeds` to its parts to see rates against "
                                         "replicates")
        return {}
    curve = replicate_curve(runs, peds, design, observed, study_seed=seed, seed=rng_seed,
                            level=level, full=full)
    return {"curve": curve.assign(comparison=label),
            "replicability": replicability(runs, peds, design, study_seed=seed)}


def with_null_rates(reversals: pd.DataFrame, tables: dict[str, pd.DataFrame]) -> pd.DataFrame:
    """Table I with ``null_rate``: the raw rate of each comparison's null at Table I's design
    (one seed set, all cells) — the matched pair's swap null on the study seed's episodes,
    the pairs' size-matched null on the main grid; NaN where the study ran no null."""
    null = {}
    curve, head = tables.get("evidence_curve"), tables.get("evidence_headline")
    if curve is not None and not curve.empty:
        c = curve[(curve["seed_sets"] == 1) & (curve["rule"] == "raw")
                  & (curve["comparison"] == "matched")]
        null.update({("matched", m): v for m, v in zip(c["metric"], c["null_mean"], strict=True)})
    if head is not None and not head.empty:
        h = head[(head["rule"] == "raw") & (head["seed_sets"] == 1)]
        for r in h.itertuples():
            null.setdefault((r.comparison, r.metric), r.null_mean)
    key = zip(reversals["comparison"], reversals["metric"], strict=True)
    rates = [null.get(k, np.nan) for k in key]
    return reversals.assign(null_rate=np.where(reversals["cells"] == "all", rates, np.nan))
