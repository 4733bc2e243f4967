"""The report's sections about the study itself rather than the paper's results:
populations, no-robot sanity checks, replays of illustrative runs and what produced
the report, each a list of blocks (:mod:`.blocks`).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pandas as pd

from ..analysis.study import Analysis
from ..populations.build import population_order
from ..populations.identity import NULL_KINDS, PopulationSpec, spec_of
from ..read.folder import StudyFolder
from .blocks import Cell, Section, figure, fmt, para, pct, table
from .figures import controller_label, pop_label


def populations_section(study: StudyFolder, analysed: list[str], figs: dict[str, Path],
                        out: Path) -> Section:
    s = Section("populations", "Populations and motion profiles (paper Fig. 3)")
    pops = study.populations
    if pops is not None:
        a = pops[pops["mapping"] == "A"] if "mapping" in pops else pops
        n = a.groupby("population")["persona_id"].nunique()
        specs = {p: spec_of(study.population_specs, p) for p in n.index}
        order = population_order([p for p in n.index if not specs[p].is_null])
        used = set(analysed)
        rows: list[list[Any]] = [[pop_label(p), int(n[p]), "yes" if p in used else "no"]
                                 for p in order]
        rows += null_rows(n, specs)
        s.blocks.append(table(["Population", "Members", "In the analysed runs"], rows,
                              caption="Cohort sizes (null replicates: one line per null design)"))
    caps = {"fig3a_profiles": "(a) Median position of each motion parameter within its range, "
            "per population.", "fig3b_matched_shift": "(b) The matched personas before and "
            "after time pressure := Deadline."}
    s.blocks += [figure(figs[k], out, c) for k, c in caps.items() if k in figs]
    return s


#: the populations section's words for a null design kind (default: the kind's own)
NULL_ROWS = {"swap_null": "swap permutations of the matched pair (2 arms each)",
             "sized_null": "size-matched random subsets of mixed (one per cohort)"}


def null_rows(sizes: pd.Series, specs: dict[str, PopulationSpec]) -> list[list[str]]:
    """One line per null design among the populations (swap permutations, size-matched
    subsets, any kind of :data:`~popnavshift.populations.identity.NULL_KINDS`): how many
    replicates and populations, and the members of each."""
    rows = []
    for kind in NULL_KINDS.values():
        role, words = kind.role, NULL_ROWS.get(kind.role, kind.words)
        names = [p for p, s in specs.items() if s.role == role]
        if not names:
            continue
        k = len({specs[p].replicate for p in names})
        lo, hi = int(sizes[names].min()), int(sizes[names].max())
        rows.append([f"null: {k} {words}, {len(names)} populations",
                     f"{lo}" if lo == hi else f"{lo}–{hi}", "in the headline tests"])
    return rows


def checks_section(a: Analysis) -> Section:
    s = Section("checks", "No-robot sanity checks (before any controller is scored)",
                missing=a.missing.get("no_robot_checks", ""))
    t = a.tables.get("no_robot_checks")
    if t is not None:
        t = t.set_index("population").loc[population_order(t["population"])].reset_index()
        s.blocks.append(para("Pedestrians of the no-robot runs of each population: do they "
                             "arrive, and at plausible speeds? A population is flagged when more "
                             "than 5% never arrive."))
        rows = [[pop_label(r.population), r.n_peds,
                 Cell(pct(r.stuck_share), "bad" if r.stuck_flag else "ok"),
                 Cell("FLAG" if r.stuck_flag else "ok", "bad" if r.stuck_flag else "ok"),
                 fmt(r.travel_time_mean), fmt(r.travel_time_p10), fmt(r.travel_time_p50),
                 fmt(r.travel_time_p90), fmt(r.walk_distance_mean), fmt(r.speed_mean)]
                for r in t.itertuples(index=False)]
        s.blocks.append(table(
            ["Population", "Pedestrians", "Never arrived", "Check", "Travel time mean (s)",
             "p10 (s)", "p50 (s)", "p90 (s)", "Walked mean (m)", "Speed mean (m/s)"], rows,
            csv="no_robot_checks"))
    share = a.tables.get("paired_share")
    if share is not None:
        s.blocks.append(table(["Controller", "Pedestrian records", "With a paired delay", "Share",
                               "Blocked", "Blocked share"],
                              [[controller_label(r.controller), r.n_records, r.n_paired,
                                pct(r.share), r.n_blocked, pct(r.blocked_share)]
                               for r in share.itertuples(index=False)],
                              caption="Paired delays: a pedestrian that arrived with and "
                                      "without the robot has one; blocked = it arrived "
                                      "without the robot but not with it (no delay; "
                                      "share of those that arrived without the robot)",
                              csv="paired_share"))
    return s


def replays_section(a: Analysis) -> Section:
    s = Section("replays", "Replays of illustrative runs", missing=a.missing.get("replays", ""))
    t = a.tables.get("replays")
    if t is None:
        return s
    ok = int(t["reproduced"].sum())
    s.blocks.append(para(
        f"Each run below was simulated again from its episode id, the population table and the "
        f"study seed. {ok} of {len(t)} re-simulated runs reproduce their stored run and "
        f"pedestrian rows bit for bit" + ("." if ok == len(t) else "; the others differ in the "
                                          "columns listed (the results are not reproducible)."),
        "p" if ok == len(t) else "note"))
    titles = {"reversal": "Largest reversal", "delay": "Largest delay"}
    cases = []
    for (kind, i), g in t.groupby(["case", "index"], sort=False):
        runs = [{"href": r.file or None, "ok": r.reproduced, "diff": r.differences,
                 "label": f"{r.episode} · {pop_label(r.population)} · "
                          f"{controller_label(r.controller)}"} for r in g.itertuples(index=False)]
        cases.append({"title": f"{titles.get(str(kind), kind)} #{i}", "text": g["text"].iloc[0],
                      "runs": runs})
    s.blocks.append({"kind": "replays", "cases": cases})
    return s


def manifest_section(study: StudyFolder, settings: dict[str, Any]) -> Section:
    s = Section("manifest", "What produced this report")
    m = study.manifest
    if not m:
        s.missing = "the folder has no manifest.json"
        return s
    items: list[tuple[str, Any]] = [
        ("Study", f"{m.get('study')} — {m.get('study_config', {}).get('description', '')}"),
        ("Config hash", m.get("config_hash")), ("Probe-set hash", m.get("probe_set")),
        ("Seeds", m.get("seeds"))]
    items += [(f"Version: {k}", v) for k, v in m.get("versions", {}).items()]
    items += [(f"Respondent: {k}", v) for k, v in m.get("respondent", {}).items()]
    resp, pers = study.metadata.get("responses", {}), study.metadata.get("personas", {})
    items += [(f"Responses: {k}", resp[k]) for k in ("records", "invalid", "calls", "cached")
              if k in resp]
    items += [(f"Personas: {k}", pers[k]) for k in ("kind", "n_obtained", "source_mix")
              if k in pers]
    items += [("Runs", m.get("counts", {}).get("distinct")), ("Table rows", m.get("tables"))]
    items += [(f"Timing: {k}", v) for k, v in m.get("timings", {}).items()]
    items += [(f"Report: {k}", v) for k, v in settings.items()]
    s.blocks.append({"kind": "kv", "entries": [
        (k, json.dumps(v, sort_keys=True) if isinstance(v, dict) else str(v)) for k, v in items]})
    s.blocks.append({"kind": "pre", "summary": "Full manifest.json",
                     "text": json.dumps(m, indent=2, sort_keys=True)})
    return s


def second_respondent(manifest: dict[str, Any]) -> str:
    second = (manifest.get("study_config") or {}).get("respondent2") or {}
    name = second.get("name", "none")
    if name == "rule":
        return "the rule surrogate with a second parameter set, not a language model"
    return f"{name} {second.get('options', {})}"


