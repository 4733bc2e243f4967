"""The report's sections about the study itself rather than the paper's results:
populations, no-robot sanity checks, replays of illustrative runs and what produced
the report, each declared once (:class:`.blocks.SectionSpec`) with its content.
"""

from __future__ import annotations

import json
from typing import Any

import pandas as pd

from ..populations.build import population_order
from ..populations.identity import NULL_KINDS, PopulationSpec, spec_of
from ..viz.style import controller_label
from .blocks import Block, Cell, Page, SectionSpec, fmt, para, pct, table
from .figures import pop_label


def _populations(p: Page, _: pd.DataFrame) -> list[Block]:
    out = []
    pops = p.study.populations
    if pops is not None:
        a = pops[pops["mapping"] == "A"] if "mapping" in pops else pops
        n = a.groupby("population")["persona_id"].nunique()
        specs = {q: spec_of(p.study.population_specs, q) for q in n.index}
        order = population_order([q for q in n.index if not specs[q].is_null])
        used = set(p.a.populations)
        rows: list[list[Any]] = [[pop_label(q), int(n[q]), "yes" if q in used else "no"]
                                 for q in order]
        rows += null_rows(n, specs)
        out.append(table(["Population", "Members", "In the analysed runs"], rows,
                         caption="Cohort sizes (null replicates: one line per null design)"))
    out += p.figure("fig3a_profiles", "(a) Median position of each motion parameter within its "
                    "range, per population.")
    out += p.figure("fig3b_matched_shift", "(b) The matched personas before and after time "
                    "pressure := Deadline.")
    if p.a.profiles_missing:
        out.append(para(f"Motion profiles: {p.a.profiles_missing}.", "missing"))
    return out


POPULATIONS = SectionSpec("populations", "Populations and motion profiles (paper Fig. 3)",
                          _populations)


def null_rows(sizes: pd.Series, specs: dict[str, PopulationSpec]) -> list[list[str]]:
    """One line per null design among the populations (swap permutations, size-matched
    subsets, any kind of :data:`~popnavshift.populations.identity.NULL_KINDS`, in the words
    it declares): how many replicates and populations, and the members of each."""
    rows = []
    for kind in NULL_KINDS.values():
        names = [q for q, s in specs.items() if s.role == kind.role]
        if not names:
            continue
        k = len({specs[q].replicate for q in names})
        lo, hi = int(sizes[names].min()), int(sizes[names].max())
        rows.append([f"null: {k} {kind.listed or kind.words}, {len(names)} populations",
                     f"{lo}" if lo == hi else f"{lo}–{hi}", "in the headline tests"])
    return rows


def _checks(p: Page, _: pd.DataFrame) -> list[Block]:
    out = []
    t = p.a.tables.get("no_robot_checks")
    if t is None:
        out.append(para(f"No-robot checks: {p.a.missing.get('no_robot_checks', 'not computed')}.",
                        "missing"))
    else:
        t = t.set_index("population").loc[population_order(t["population"])].reset_index()
        out.append(para("Pedestrians of the no-robot runs of each population: do they arrive, "
                        "and at plausible speeds? A population is flagged when more than 5% "
                        "never arrive."))
        rows = [[pop_label(r.population), r.n_peds,
                 Cell(pct(r.stuck_share), "bad" if r.stuck_flag else "ok"),
                 Cell("FLAG" if r.stuck_flag else "ok", "bad" if r.stuck_flag else "ok"),
                 fmt(r.travel_time_mean), fmt(r.travel_time_p10), fmt(r.travel_time_p50),
                 fmt(r.travel_time_p90), fmt(r.walk_distance_mean), fmt(r.speed_mean)]
                for r in t.itertuples(index=False)]
        out.append(table(
            ["Population", "Pedestrians", "Never arrived", "Check", "Travel time mean (s)",
             "p10 (s)", "p50 (s)", "p90 (s)", "Walked mean (m)", "Speed mean (m/s)"], rows,
            csv="no_robot_checks"))
    share = p.a.tables.get("paired_share")
    if share is not None:
        out.append(table(["Controller", "Pedestrian records", "With a paired delay", "Share"],
                         [[controller_label(r.controller), r.n_records, r.n_paired,
                           pct(r.share)] for r in share.itertuples(index=False)],
                         caption="Paired delay availability (the paper: nearly all)",
                         csv="paired_share"))
    return out


CHECKS = SectionSpec("checks", "No-robot sanity checks (before any controller is scored)",
                     _checks)


def _replays(p: Page, t: pd.DataFrame) -> list[Block]:
    ok = int(t["reproduced"].sum())
    out = [para(
        f"Each run below was simulated again from its episode id, the population table and the "
        f"study seed. {ok} of {len(t)} re-simulated runs reproduce their stored run and "
        f"pedestrian rows bit for bit" + ("." if ok == len(t) else "; the others differ in the "
                                          "columns listed (the results are not reproducible)."),
        "p" if ok == len(t) else "note")]
    titles = {"reversal": "Largest reversal", "delay": "Largest delay"}
    cases = []
    for (kind, i), g in t.groupby(["case", "index"], sort=False):
        runs = [{"href": r.file or None, "ok": r.reproduced, "diff": r.differences,
                 "label": f"{r.episode} · {pop_label(r.population)} · "
                          f"{controller_label(r.controller)}"} for r in g.itertuples(index=False)]
        cases.append({"title": f"{titles.get(str(kind), kind)} #{i}", "text": g["text"].iloc[0],
                      "runs": runs})
    return out + [{"kind": "replays", "cases": cases}]


REPLAYS = SectionSpec("replays", "Replays of illustrative runs", _replays, needs=("replays",))


def _manifest(p: Page, _: pd.DataFrame) -> list[Block] | str:
    m = p.study.manifest
    if not m:
        return "the folder has no manifest.json"
    items: list[tuple[str, Any]] = [
        ("Study", f"{m.get('study')} — {m.get('study_config', {}).get('description', '')}"),
        ("Config hash", m.get("config_hash")), ("Probe-set hash", m.get("probe_set")),
        ("Seeds", m.get("seeds"))]
    items += [(f"Version: {k}", v) for k, v in m.get("versions", {}).items()]
    items += [(f"Respondent: {k}", v) for k, v in m.get("respondent", {}).items()]
    resp, pers = p.study.metadata.get("responses", {}), p.study.metadata.get("personas", {})
    items += [(f"Responses: {k}", resp[k]) for k in ("records", "invalid", "calls", "cached")
              if k in resp]
    items += [(f"Personas: {k}", pers[k]) for k in ("kind", "n_obtained", "source_mix")
              if k in pers]
    items += [("Runs", m.get("counts", {}).get("distinct")), ("Table rows", m.get("tables"))]
    items += [(f"Timing: {k}", v) for k, v in m.get("timings", {}).items()]
    items += [(f"Report: {k}", v) for k, v in p.settings.items()]
    return [{"kind": "kv", "entries": [
        (k, json.dumps(v, sort_keys=True) if isinstance(v, dict) else str(v)) for k, v in items]},
        {"kind": "pre", "summary": "Full manifest.json",
         "text": json.dumps(m, indent=2, sort_keys=True)}]


MANIFEST = SectionSpec("manifest", "What produced this report", _manifest)
