"""Stage 9: a study folder → every table, figure and replay of the report, then the page.

``build_report(folder)`` reads the Parquet tables and the manifest, selects the
main grid (the study's ``main`` part), computes each section with the pure
functions of :mod:`popnavshift.analysis` (``analyse``), writes the tables as CSV,
draws the figures, re-simulates a few illustrative runs as replays (checking that
each reproduces its stored row) and renders ``report/index.html``.

A section that cannot be computed on the study given (too few populations or
controllers, no no-robot baselines, no matched pair, no split-half populations)
is left out of ``Analysis.tables`` with the reason in ``Analysis.missing``; the
page says why instead of failing.
"""

from __future__ import annotations

import json
import re
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from ..analysis import (
    MATCHED,
    PAPER,
    Finding,
    cell_metrics,
    comparisons,
    controller_outcomes,
    delay_change,
    no_robot_checks,
    noise_floor,
    paired_delays,
    paired_share,
    paper_findings,
    population_pairs,
    population_sensitivity,
    ranking_tau,
    reversal_table,
    sensitivity_by_width,
)
from ..analysis.summary import (
    BUILTIN_CONTROLLERS,
    burden_exceeds_time,
    completed_lower,
    controller_extreme,
    matched_change_direction,
    tail_ratio,
    width_decreases,
)
from ..errors import InputError, PopNavShiftError
from ..io import write_atomic, write_text
from ..populations.build import HALF_SUFFIXES
from ..tables import NO_ROBOT, RUN_KEY

REPORT_DIR = "report"
WIDTH_SCENES: tuple[str, ...] = ("sidewalk", "bottleneck")  # the two panels of the paper's Fig. 4


@dataclass
class Analysis:
    """Everything the report shows, computed from one study's tables.

    ``populations``: those analysed (split halves aside); ``tables``: name → table
    (each written as ``tables/<name>.csv``);
    ``missing``: section id → why it could not be computed; ``findings``: the
    paper's qualitative claims checked on our numbers; ``cells``, ``comps`` and
    ``paired`` are kept for choosing the illustrative replays.
    """

    selection: str
    populations: list[str] = field(default_factory=list)
    tables: dict[str, pd.DataFrame] = field(default_factory=dict)
    missing: dict[str, str] = field(default_factory=dict)
    findings: list[Finding] = field(default_factory=list)
    cells: pd.DataFrame | None = None
    comps: pd.DataFrame | None = None
    paired: pd.DataFrame | None = None


# --- Reading the folder and selecting the main grid -----------------------------------------


@dataclass(frozen=True)
class StudyFolder:
    folder: Path
    runs: pd.DataFrame
    pedestrians: pd.DataFrame
    populations: pd.DataFrame | None
    episodes: pd.DataFrame | None
    manifest: dict[str, Any]
    metadata: dict[str, dict[str, Any]]  # personas.json, responses.json


def _read_json(path: Path) -> dict[str, Any]:
    return json.loads(path.read_text("utf-8")) if path.exists() else {}


def read_study_folder(folder: Path) -> StudyFolder:
    """The tables of a study folder; raises :class:`InputError` without runs or pedestrians."""
    folder = Path(folder)
    for name in ("runs.parquet", "pedestrians.parquet"):
        if not (folder / name).exists():
            raise InputError(f"study folder {folder}: {name} not found",
                             hint="run the study first (popnavshift run)")

    def optional(name: str) -> pd.DataFrame | None:
        return pd.read_parquet(folder / name) if (folder / name).exists() else None

    return StudyFolder(
        folder=folder,
        runs=pd.read_parquet(folder / "runs.parquet"),
        pedestrians=pd.read_parquet(folder / "pedestrians.parquet"),
        populations=optional("populations.parquet"),
        episodes=optional("episodes.parquet"),
        manifest=_read_json(folder / "manifest.json"),
        metadata={n: _read_json(folder / f"{n}.json") for n in ("personas", "responses")},
    )


def _isin(df: pd.DataFrame, column: str, values) -> pd.Series:
    return df[column].isin(list(values))


def split_halves(populations) -> list[tuple[str, str, str]]:
    """(population, half a, half b) for every pair of split-half names among ``populations``."""
    pops = set(populations)
    a, b = HALF_SUFFIXES
    return sorted((p[: -len(a)], p, p[: -len(a)] + b) for p in pops
                  if p.endswith(a) and p[: -len(a)] + b in pops)


def is_half(population: pd.Series) -> pd.Series:
    return population.str.endswith(HALF_SUFFIXES[0]) | population.str.endswith(HALF_SUFFIXES[1])


def main_grid(study: StudyFolder) -> tuple[pd.DataFrame, pd.DataFrame, str]:
    """Runs and pedestrians of the study's ``main`` part (else its first part), and a description.

    The part is read from the manifest's study configuration: its episodes,
    populations, controllers (plus the no-robot baseline), backends and mapping.
    Split-half populations (for the noise floor) are kept on the same episodes, so the
    floor is at Table I's design (their other seed sets feed the seed-spread section).
    Without a configuration every run is kept.
    """
    from ..engine.plan import select_episodes
    from ..engine.study import study_from_dict
    from .figures import pop_order

    runs, peds = study.runs, study.pedestrians
    cfg = study.manifest.get("study_config")
    if not cfg or not cfg.get("parts") or study.episodes is None:
        return runs, peds, "every run in the folder (the manifest names no study part)"
    spec = study_from_dict(cfg, "manifest study_config")
    name = "main" if "main" in spec.parts else next(iter(spec.parts))
    part = spec.parts[name]
    ids = {e.id for e in select_episodes(part.episodes, study.episodes.itertuples(index=False))}

    # a part's mapping is one name or (newer studies) a tuple of them
    mappings = (part.mapping,) if isinstance(part.mapping, str) else tuple(part.mapping)

    def keep(df: pd.DataFrame) -> pd.DataFrame:
        grid = (_isin(df, "controller", (NO_ROBOT, *part.controllers))
                & _isin(df, "backend", part.backends) & _isin(df, "mapping", mappings))
        on_grid = _isin(df, "episode", ids)  # the paper's design: one seed set
        main = _isin(df, "population", part.populations) | is_half(df["population"])
        return df[grid & on_grid & main]

    runs, peds = keep(runs), keep(peds)
    text = (f"part {name!r}: {runs['episode'].nunique()} episodes, populations "
            f"{', '.join(pop_order(runs['population'].unique()))}; controllers "
            f"{', '.join(part.controllers)} and no robot; backend {', '.join(part.backends)}; "
            f"mapping {', '.join(mappings)}")
    return runs, peds, text


# --- Sections ----------------------------------------------------------------------------------


def _sanity(a: Analysis, peds: pd.DataFrame) -> None:
    base = peds[peds["controller"] == NO_ROBOT]
    if base.empty:
        a.missing["checks"] = "the study ran no no-robot baselines"
    else:
        a.tables["no_robot_checks"] = no_robot_checks(base)


def _rankings(a: Analysis, cells: pd.DataFrame, rng_seed: int, n_boot: int) -> None:
    pops = sorted(cells["population"].unique())
    ctrl = sorted(cells["controller"].unique())
    if len(pops) < 2 or len(ctrl) < 2:
        why = (f"rankings need at least 2 populations and 2 controllers; this study has "
               f"{len(pops)} population(s) and {len(ctrl)} controller(s)")
        for s in ("table1", "matched", "tau"):
            a.missing[s] = why
        return
    t1 = reversal_table(cells, rng=np.random.default_rng(rng_seed), n_boot=n_boot)
    a.tables["reversals"] = t1.assign(paper_rate=[
        PAPER["reversal_rate"].get(c, {}).get(s, {}).get(m, np.nan)
        for c, s, m in t1[["comparison", "cells", "metric"]].itertuples(index=False)])
    if not set(MATCHED) <= set(pops):
        a.missing["matched"] = f"the study lacks the matched pair ({', '.join(MATCHED)})"
    a.comps = comparisons(cells, population_pairs(pops))
    tau = ranking_tau(a.comps).groupby(["metric", "pop_a", "pop_b"])
    a.tables["kendall_tau"] = tau.agg(tau=("tau", "mean"), n_cells=("tau", "count")).reset_index()


def _outcomes(a: Analysis, runs: pd.DataFrame, cells: pd.DataFrame) -> None:
    out = controller_outcomes(runs, cells)
    a.tables["controller_outcomes"] = out.reset_index()
    per_pop = [controller_outcomes(runs[runs["population"] == p], cells[cells["population"] == p])
               .reset_index().assign(population=p) for p in sorted(cells["population"].unique())]
    a.tables["tradeoff"] = pd.concat(per_pop, ignore_index=True)


def _delay_change(a: Analysis, cells: pd.DataFrame) -> None:
    pops = set(cells["population"])
    if not (set(MATCHED) <= pops or ("homogeneous" in pops and pops - {"homogeneous", *MATCHED})):
        a.missing["change"] = ("the change in delay needs the matched pair, or the homogeneous "
                               "reference and a population outside the matched pair")
        return
    frames = [delay_change(cells, metric=m).assign(metric=m)
              for m in ("mean_delay", "worst_decile")]
    change = pd.concat(frames, ignore_index=True)
    if change.empty:
        a.missing["change"] = "no cell has a paired delay under both populations of a row"
        return
    a.tables["delay_change"] = change


def _sensitivity(a: Analysis, cells: pd.DataFrame) -> None:
    if cells["population"].nunique() < 2:
        a.missing["sensitivity"] = "population sensitivity needs at least 2 populations"
        return
    sens = population_sensitivity(cells)
    a.tables["population_sensitivity"] = sens
    frames = []
    for scenes in (WIDTH_SCENES, *((s,) for s in WIDTH_SCENES)):
        label = "+".join(scenes)
        for done in (False, True):
            for by in ((), ("controller",)):
                f = sensitivity_by_width(sens, scenes=scenes, by=by, completed_only=done)
                frames.append(f.assign(scenes=label, cells="completed" if done else "all",
                                       controller=f.get("controller", "pooled")))
    by_width = pd.concat(frames, ignore_index=True)
    if by_width.empty:
        a.missing["sensitivity"] = "no sidewalk or bottleneck cell has a sensitivity value"
        return
    a.tables["sensitivity_by_width"] = by_width[
        ["scenes", "cells", "controller", "width", "sensitivity", "n"]]


def _noise_floor(a: Analysis, runs: pd.DataFrame, peds: pd.DataFrame) -> None:
    halves = split_halves(runs["population"].unique())
    robot = runs.loc[is_half(runs["population"]) & (runs["controller"] != NO_ROBOT), "controller"]
    if not halves or robot.nunique() < 2:
        a_, b_ = HALF_SUFFIXES
        a.missing["noise"] = (f"the noise floor was not run: the study has no split-half "
                              f"populations (named <population>{a_} and <population>{b_}) "
                              "with runs of 2 or more controllers")
        return
    frames = [noise_floor(runs, peds, (ha, hb), completed_only=done)
              .assign(population=base, cells="completed" if done else "all")
              for base, ha, hb in halves for done in (False, True)]
    a.tables["noise_floor"] = pd.concat(frames, ignore_index=True)


def analyse(runs: pd.DataFrame, peds: pd.DataFrame, *, selection: str = "",
            rng_seed: int = 0, n_boot: int = 1000) -> Analysis:
    """Every section of the report from one analysis's runs and pedestrians tables.

    Split-half populations (``<population>_half_a`` / ``_half_b``) feed only the
    noise floor; every other section uses the other populations. ``rng_seed``
    seeds the Table I bootstrap (``numpy.random.default_rng(rng_seed)``, fresh, so
    the intervals can be recomputed); ``n_boot`` is its resample count.
    """
    a = Analysis(selection=selection)
    _noise_floor(a, runs, peds)
    runs, peds = runs[~is_half(runs["population"])], peds[~is_half(peds["population"])]
    a.populations = sorted(runs["population"].unique())
    _sanity(a, peds)
    if runs[runs["controller"] != NO_ROBOT].empty:
        why = "the study has no robot runs"
        for s in ("table1", "matched", "tau", "table2", "tradeoff", "change", "sensitivity",
                  "findings"):
            a.missing[s] = why
        return a
    a.paired = paired_delays(peds)
    if a.paired.empty:
        a.missing["delays"] = "no pedestrian has a paired delay (no no-robot baseline?)"
    a.tables["paired_share"] = paired_share(peds, a.paired)
    a.cells = cell_metrics(runs, a.paired)
    a.tables["cell_metrics"] = a.cells
    _rankings(a, a.cells, rng_seed, n_boot)
    _outcomes(a, runs, a.cells)
    _delay_change(a, a.cells)
    _sensitivity(a, a.cells)
    a.findings, why = check_findings(a.tables)
    if why:
        a.missing["findings"] = why
    if a.findings:
        a.tables["findings"] = pd.DataFrame(
            [{"statement": f.statement, "holds": f.holds,
              "numbers": json.dumps(f.numbers, default=str)} for f in a.findings])
    return a


def _widths(tables: dict[str, pd.DataFrame]) -> dict[str, pd.DataFrame]:
    """The pooled and per-panel width curves with at least two widths (all cells, pooled)."""
    bw = tables.get("sensitivity_by_width")
    if bw is None:
        return {}
    sel = bw[(bw["cells"] == "all") & (bw["controller"] == "pooled")]
    out = {}
    for scenes, label in (("+".join(WIDTH_SCENES), "pooled"), *((s, s) for s in WIDTH_SCENES)):
        w = sel[sel["scenes"] == scenes][["width", "sensitivity"]]
        if len(w) >= 2:
            out[label] = w.reset_index(drop=True)
    return out


def check_findings(tables: dict[str, pd.DataFrame]) -> tuple[list[Finding], str]:
    """The paper's findings (:func:`paper_findings`) on our tables, and what could not be checked.

    With every input present this is exactly ``paper_findings``; otherwise the
    findings whose inputs exist are checked with the same functions, and the
    returned text names the ones left out.
    """
    if "controller_outcomes" not in tables:
        return [], "no controller outcomes"
    outcomes = tables["controller_outcomes"].set_index("controller")
    t1 = tables.get("reversals", pd.DataFrame(columns=["comparison", "cells", "metric", "rate"]))
    change = tables.get("delay_change", pd.DataFrame(columns=["metric", "controller", "population",
                                                             "change"]))
    mean_change, widths = change[change["metric"] == "mean_delay"], _widths(tables)
    delays = bool(outcomes["mean_delay"].notna().all())
    pairs = "reversals" in tables and delays
    matched = pairs and bool((t1["comparison"] == "matched").any())
    ctrl = set(BUILTIN_CONTROLLERS) <= set(outcomes.index)
    if matched and widths and ctrl:
        return paper_findings(t1, outcomes, widths, mean_change), ""

    def rates(comp: str, cells: str) -> pd.Series:
        sel = t1[(t1["comparison"] == comp) & (t1["cells"] == cells)]
        return sel.set_index("metric")["rate"]

    def extreme(column: str, controller: str, highest: bool, among=None) -> Finding:
        return controller_extreme(outcomes, column, controller, highest=highest, among=among)

    checks: list[tuple[bool, str, Callable[[], list[Finding]]]] = [
        (matched, "the matched-pair reversal finding",
         lambda: [burden_exceeds_time(rates("matched", "all"), "matched, all cells")]),
        (pairs, "the all-pairs reversal findings", lambda: [
            burden_exceeds_time(rates("all_pairs", "all"), "all pairs, all cells"),
            burden_exceeds_time(rates("all_pairs", "completed"), "all pairs, completed"),
            completed_lower(rates("all_pairs", "all"), rates("all_pairs", "completed"),
                            "all pairs")]),
        (bool(widths), "the width findings (sidewalks or bottlenecks at 2+ widths)",
         lambda: [width_decreases(w, label) for label, w in widths.items()]),
        (delays, "the tail-to-mean finding",
         lambda: [tail_ratio(outcomes, PAPER["tail_to_mean_ratio"])]),
        (ctrl, "the controller findings (all three built-in controllers)", lambda: [
            extreme("success_pct", "reactive", True), extreme("timeout_pct", "early_yield", True)]),
        (ctrl and delays, "the controller delay findings", lambda: [
            extreme("mean_delay", "robot_orca", False),
            extreme("worst_decile", "robot_orca", False),
            extreme("mean_delay", "early_yield", False, ("reactive", "early_yield"))]),
        (ctrl and matched, "the matched-shift direction finding",
         lambda: [matched_change_direction(mean_change, PAPER["matched_change_sign"])]),
    ]
    found = [f for ok, _, make in checks if ok for f in make()]
    left = [what for ok, what, _ in checks if not ok]
    return found, ("not checked on this study: " + "; ".join(left)) if left else ""


# --- Writing ----------------------------------------------------------------------------------


def write_tables(tables: dict[str, pd.DataFrame], folder: Path) -> list[Path]:
    """Each table as ``folder/<name>.csv`` (full precision, no index)."""
    paths = []
    for name, df in tables.items():
        paths.append(write_atomic(folder / f"{name}.csv", partial(df.to_csv, index=False)))
    return paths


def build_report(folder: Path, *, rng_seed: int = 0, n_boot: int = 1000, replays: int = 2) -> Path:
    """Write ``folder/report/index.html`` (self-contained) with its tables, figures and replays.

    Args:
      folder: a study folder (``runs.parquet``, ``pedestrians.parquet``,
        ``populations.parquet``, ``manifest.json``, ``figures/``).
      rng_seed: seed of the cluster bootstrap of the reversal rates.
      n_boot: bootstrap resamples.
      replays: illustrative cases per kind (largest reversal, largest delay) to
        re-simulate and replay; 0 for none.

    Returns the path of ``index.html``. Tables go to ``report/tables/*.csv``,
    figures to ``report/figures/*.png|svg``, replays to ``report/replays/*.html``.
    """
    from .answer import with_null_rates, write_answer_figures
    from .evidence import evidence_tables
    from .figures import profile_figures, write_figures
    from .html import render_report
    from .robustness import robustness_tables

    study = read_study_folder(Path(folder))
    out = study.folder / REPORT_DIR
    runs, peds, selection = main_grid(study)
    analysis = analyse(runs, peds, selection=selection, rng_seed=rng_seed, n_boot=n_boot)
    evidence, evidence_missing = evidence_tables(study, rng_seed=rng_seed, n_boot=n_boot)
    analysis.tables.update(evidence)
    analysis.missing.update(evidence_missing)
    if "reversals" in analysis.tables:
        analysis.tables["reversals"] = with_null_rates(analysis.tables["reversals"], evidence)
    figures = write_figures(analysis, out / "figures")
    figures.update(write_answer_figures(evidence, out / "figures"))
    fig3, why = profile_figures(study.folder / "figures", study.populations, out / "figures")
    if why:
        analysis.missing["profiles"] = why
    robust, robust_missing = robustness_tables(study, rng_seed=rng_seed, n_boot=n_boot)
    analysis.tables.update(robust)
    analysis.missing.update({f"robust_{k}": v for k, v in robust_missing.items()})
    reps = write_replays(study, analysis, runs, peds, out / "replays", replays)
    if reps is not None and not reps.empty:
        analysis.tables["replays"] = reps
    elif replays <= 0:
        analysis.missing["replays"] = "replays were not asked for (replays=0)"
    written = write_tables(analysis.tables, out / "tables")
    written += [p.with_suffix(x) for p in {**figures, **fig3}.values() for x in (".png", ".svg")]
    if reps is not None:
        files = [out / f for f in reps["file"] if f]
        written += files + [f.with_suffix(".svg") for f in files]
    prune(out, written)
    settings = {"rng_seed": rng_seed, "n_boot": n_boot, "replays": replays}
    page = render_report(study, analysis, {**figures, **fig3}, out, settings)
    return write_text(page, out / "index.html")


def prune(out: Path, written: list[Path]) -> None:
    """Delete what an earlier build left in ``tables/``, ``figures/`` and ``replays/``, so a
    section that is now missing cannot show a stale file."""
    keep = {p.resolve() for p in written}
    for sub in ("tables", "figures", "replays"):
        for path in (out / sub).glob("*") if (out / sub).is_dir() else ():
            if path.is_file() and path.resolve() not in keep:
                path.unlink()


def slug(text: str) -> str:
    """A file-name-safe version of ``text`` (letters, digits, ``._-``)."""
    return re.sub(r"[^A-Za-z0-9._-]+", "_", text).strip("_") or "x"


# --- Replays of illustrative runs ------------------------------------------------------------


@dataclass(frozen=True)
class Case:
    """An illustrative case: what it shows and the runs (keys as dicts) that show it."""

    kind: str  # "reversal" or "delay"
    index: int
    text: str
    runs: tuple[dict[str, str], ...]


def _run_mean_delay(paired: pd.DataFrame) -> pd.Series:
    return paired.groupby(["episode", "population", "controller"])["delay"].mean()


def reversal_cases(a: Analysis, runs: pd.DataFrame, n: int) -> list[Case]:
    """The ``n`` strongest mean-delay reversals (distinct cells): both orderings' smaller |Δ|.

    Each case replays the two controllers under the two populations in the
    variant where the per-run mean delays reverse most strongly (else the first).
    """
    if a.comps is None or a.paired is None or n <= 0:
        return []
    c = a.comps[(a.comps["metric"] == "mean_delay") & a.comps["reversal"]]
    c = c.assign(strength=np.minimum(c["diff_a"].abs(), c["diff_b"].abs()))
    c = c.sort_values("strength", ascending=False, kind="stable").drop_duplicates("cell").head(n)
    md = _run_mean_delay(a.paired)
    from ..analysis import episode_cells

    eps = episode_cells(runs)
    cases = []
    for i, r in enumerate(c.itertuples(index=False), start=1):
        def gap(ep: str, pop: str, r=r) -> float:
            return float(md.get((ep, pop, r.ctrl_1), np.nan) - md.get((ep, pop, r.ctrl_2), np.nan))

        options = sorted(eps.loc[eps["cell"] == r.cell, "episode"])
        score = [min(abs(gap(e, r.pop_a)), abs(gap(e, r.pop_b)))
                 if gap(e, r.pop_a) * gap(e, r.pop_b) < 0 else -1.0 for e in options]
        ep = options[int(np.argmax(score))]
        text = (f"Cell {r.cell}: under {r.pop_a}, {r.ctrl_1} minus {r.ctrl_2} mean delay is "
                f"{r.diff_a:+.2f} s; under {r.pop_b} it is {r.diff_b:+.2f} s, so the order "
                f"flips. Replayed episode: {ep}.")
        keys = tuple({"episode": ep, "population": p, "controller": ctrl, "backend": r.backend,
                      "mapping": r.mapping} for p in (r.pop_a, r.pop_b)
                     for ctrl in (r.ctrl_1, r.ctrl_2))
        cases.append(Case("reversal", i, text, keys))
    return cases


def delay_cases(a: Analysis, n: int) -> list[Case]:
    """The ``n`` robot runs with the largest single paired delay, each with its baseline run."""
    if a.paired is None or a.paired.empty or n <= 0:
        return []
    p = a.paired.sort_values("delay", ascending=False, kind="stable")
    p = p.drop_duplicates(list(RUN_KEY)).head(n)
    cases = []
    for i, r in enumerate(p.itertuples(index=False), start=1):
        key = {k: str(getattr(r, k)) for k in RUN_KEY}
        text = (f"Persona {r.persona_id} (slot {r.slot}) took {r.delay:.1f} s longer with "
                f"{r.controller} than without a robot in {r.episode} under {r.population}.")
        cases.append(Case("delay", i, text, (key, {**key, "controller": NO_ROBOT})))
    return cases


def _same(x: Any, y: Any) -> bool:
    if isinstance(x, (float, np.floating)) or isinstance(y, (float, np.floating)):
        return bool(np.array_equal(np.float64(x), np.float64(y), equal_nan=True))
    return bool(x == y)


def run_differences(stored_run: pd.Series, stored_peds: pd.DataFrame, result) -> list[str]:
    """Columns where a re-simulated run (:class:`SimResult`) differs from the stored rows."""
    bad = [k for k, v in result.run.items() if k in stored_run and not _same(stored_run[k], v)]
    new = result.pedestrians.sort_values("slot").reset_index(drop=True)
    old = stored_peds.sort_values("slot").reset_index(drop=True)
    if len(new) != len(old):
        return [*bad, f"pedestrians ({len(old)} stored rows, {len(new)} re-simulated)"]
    for col in new.columns.intersection(old.columns):
        if not all(_same(x, y) for x, y in zip(old[col], new[col], strict=True)):
            bad.append(f"pedestrians.{col}")
    return bad


def resimulate(key: dict[str, str], populations: pd.DataFrame, seed: int, *, record: bool = True):
    """Simulate one stored run again from the episode id, the population table and the seed."""
    from ..episodes.specs import assign_slots, get_episode
    from ..sim.run import simulate

    spec = get_episode(key["episode"], seed=seed)
    pops = populations[(populations["mapping"] == key["mapping"])
                       & (populations["population"] == key["population"])]
    slots = assign_slots(spec, pops.sort_values("persona_id"))
    return simulate(spec, slots, key["controller"], key["backend"], record=record)


def _row(df: pd.DataFrame, key: dict[str, str]) -> pd.DataFrame:
    m = np.ones(len(df), dtype=bool)
    for k, v in key.items():
        m &= (df[k] == v).to_numpy()
    return df[m]


def study_seed(manifest: dict[str, Any]) -> int | None:
    seed = manifest.get("seeds", {}).get("study", manifest.get("study_config", {}).get("seed"))
    return None if seed is None else int(seed)


def write_replays(study: StudyFolder, a: Analysis, runs: pd.DataFrame, peds: pd.DataFrame,
                  out: Path, n: int) -> pd.DataFrame | None:
    """Re-simulate the illustrative cases, write ``out/<name>.html`` (+ .svg) and check each run.

    Returns one row per replayed run: case, run keys, ``file`` (relative to the
    report), ``reproduced`` (every stored column equal, bit for bit) and
    ``differences``; None with ``a.missing["replays"]`` set when impossible.
    """
    from ..viz.replay import write_replay

    seed = study_seed(study.manifest)
    if n <= 0:
        return None
    if study.populations is None or seed is None:
        a.missing["replays"] = "the folder lacks populations.parquet or the study seed"
        return None
    cases = reversal_cases(a, runs, n) + delay_cases(a, n)
    if not cases:
        a.missing["replays"] = "no reversal and no paired delay to illustrate"
        return None
    rows = []
    for case in cases:
        for key in case.runs:
            stored = _row(runs, key)
            if stored.empty:
                continue
            try:
                result = resimulate(key, study.populations, seed)
            except PopNavShiftError as exc:  # e.g. a run stored as controller_error
                rows.append({"case": case.kind, "index": case.index, "text": case.text, **key,
                             "file": "", "reproduced": False,
                             "differences": f"could not re-simulate: {exc}"})
                continue
            diff = run_differences(stored.iloc[0], _row(peds, key), result)
            name = slug(f"{case.kind}{case.index}-{key['controller']}-{key['population']}")
            metrics = {"illustrates": case.text,
                       **{k: stored.iloc[0][k] for k in REPLAY_METRICS if k in stored},
                       "reproduces the stored run": "yes, bit for bit" if not diff
                       else "NO, differs in " + ", ".join(diff)}
            title = f"{key['episode']} · {key['population']} · {key['controller']}"
            write_replay(result.trajectory, metrics, out / f"{name}.html", title)
            rows.append({"case": case.kind, "index": case.index, "text": case.text, **key,
                         "file": f"replays/{name}.html", "reproduced": not diff,
                         "differences": ", ".join(diff)})
    return pd.DataFrame(rows)


REPLAY_METRICS = ("outcome", "robot_time", "robot_path_length", "robot_stop_time",
                  "robot_min_clearance", "ped_collisions", "world_collisions", "n_peds",
                  "peds_arrived")
