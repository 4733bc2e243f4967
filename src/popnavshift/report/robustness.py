"""Report sections of the robustness parts (paper §IV-C, §V-D, §V-E).

Each part named in the study's manifest (``mapping``, ``structure``, ``backend``,
``respondent``) is selected from the runs table by its own episodes, populations,
backends and profile sets, analysed with :mod:`popnavshift.analysis.robustness`,
and shown with the paper's figures beside ours. Parts the study did not run say so.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd

from ..analysis.delay import cell_metrics, paired_delays
from ..analysis.robustness import agreement_with, backend_rates, matched_rates, rates_by_set
from ..engine.plan import NO_ROBOT
from .figures import METRIC_LABELS
from .html import Cell, Section, para, pct, table

if TYPE_CHECKING:
    from .build import StudyFolder

#: The paper's robustness figures (rates as fractions), for the tables beside ours.
PAPER_ROBUSTNESS: dict[str, dict[str, dict[str, float]]] = {
    "mapping": {
        "A": {"mean_delay": 0.245, "worst_decile": 0.260},
        "B": {"mean_delay": 0.242, "worst_decile": 0.286},
        "C": {"mean_delay": 0.246, "worst_decile": 0.257},
        "D": {"mean_delay": 0.375, "worst_decile": 0.358},
    },
    "agreement": {
        "B": {"mean_delay": 0.923, "worst_decile": 0.926},
        "C": {"mean_delay": 0.922, "worst_decile": 0.918},
        "D": {"mean_delay": 0.768, "worst_decile": 0.710},
    },
    "structure": {
        "A": {"mean_delay": 0.284, "worst_decile": 0.269},
        "A~reassign": {"mean_delay": 0.198, "worst_decile": 0.188},
        "A~shuffle": {"mean_delay": 0.268, "worst_decile": 0.297},
    },
    "backend": {
        "orca": {"robot_time": 0.032, "mean_delay": 0.105, "worst_decile": 0.098},
        "hl": {"robot_time": 0.024, "mean_delay": 0.352, "worst_decile": 0.346},
    },
    "respondent": {
        "A": {"robot_time": 0.086, "mean_delay": 0.224, "worst_decile": 0.239},
        "second": {"robot_time": 0.091, "mean_delay": 0.256, "worst_decile": 0.265},
    },
}
PARTS = ("mapping", "structure", "backend", "respondent")
SET_LABELS = {
    "A~reassign": "whole profiles reassigned",
    "A~shuffle": "columns shuffled",
    "A~block-time_pressure": "time-pressure block only",
    "A~block-caution": "caution block only",
    "A~block-trust": "trust block only",
}


def part_cells(study: StudyFolder, name: str, seed: int | None = None) -> pd.DataFrame | None:
    """Cell metrics of the study part ``name`` (None when the study has no such part);
    ``seed`` selects one of the part's extra seed sets (default: the study's own)."""
    from ..engine.plan import select_episodes
    from ..engine.study import study_from_dict
    from ..episodes.specs import seed_set_id

    cfg = study.manifest.get("study_config") or {}
    if name not in (cfg.get("parts") or {}) or study.episodes is None:
        return None
    part = study_from_dict(cfg, "manifest study_config").parts[name]
    ids = {e.id for e in select_episodes(part.episodes, study.episodes.itertuples(index=False))}
    if seed is not None and seed != cfg.get("seed", 0):
        ids = {seed_set_id(i, seed) for i in ids}
    mappings = set(part.mappings) | (
        {"A"} if name in ("mapping", "structure", "respondent") else set()
    )

    def keep(df: pd.DataFrame) -> pd.DataFrame:
        return df[
            df["episode"].isin(ids)
            & df["population"].isin(part.populations)
            & df["controller"].isin([NO_ROBOT, *part.controllers])
            & df["backend"].isin(part.backends)
            & df["mapping"].isin(mappings)
        ]

    runs, peds = keep(study.runs), keep(study.pedestrians)
    if runs.empty:
        return None
    return cell_metrics(runs, paired_delays(peds))


def robustness_tables(
    study: StudyFolder, *, rng_seed: int = 0, n_boot: int = 1000
) -> tuple[dict[str, pd.DataFrame], dict[str, str]]:
    """Tables ``robust_<part>`` (and ``robust_agreement``) and why parts are missing."""
    tables: dict[str, pd.DataFrame] = {}
    missing: dict[str, str] = {}
    for name in PARTS:
        cells = part_cells(study, name)
        if cells is None:
            missing[name] = f"the study has no {name!r} part (or it has no runs)"
            continue
        rng = np.random.default_rng(rng_seed)
        if name == "mapping":
            tables["robust_mapping"] = rates_by_set(cells, rng=rng, n_boot=n_boot)
            tables["robust_agreement"] = agreement_with(cells, "A")
        elif name == "structure":
            tables["robust_structure"] = rates_by_set(cells, rng=rng, n_boot=n_boot)
        elif name == "backend":
            tables["robust_backend"] = backend_rates(cells, rng=rng, n_boot=n_boot)
        else:
            tables["robust_respondent"] = matched_rates(cells, rng=rng, n_boot=n_boot)
    spread = seed_spread(study, rng_seed=rng_seed, n_boot=n_boot)
    if spread is None:
        missing["seeds"] = "no study part was repeated with extra episode seed sets (`seeds`)"
    else:
        tables["robust_seeds"] = spread
    return tables, missing


def seed_spread(
    study: StudyFolder, *, rng_seed: int = 0, n_boot: int = 1000
) -> pd.DataFrame | None:
    """Reversal rates (all population pairs of the part) per seed set, for every part
    with extra ``seeds`` (null designs aside: the answer section tests them); None when
    no part has any. Columns: part, seed_set, metric, backend, mapping, reversals,
    comparisons, rate, ci_low, ci_high."""
    cfg = study.manifest.get("study_config") or {}
    frames = []
    for name, part in (cfg.get("parts") or {}).items():
        seeds = [s for s in part.get("seeds", []) if s != cfg.get("seed", 0)]
        if not seeds or part.get("null_design"):
            continue
        for seed in [cfg.get("seed", 0), *seeds]:
            cells = part_cells(study, name, seed)
            if cells is None:
                continue
            rates = rates_by_set(cells, rng=np.random.default_rng(rng_seed), n_boot=n_boot)
            frames.append(rates.assign(part=name, seed_set=seed))
    if not frames:
        return None
    out = pd.concat(frames, ignore_index=True)
    return out[["part", "seed_set", *[c for c in out.columns if c not in ("part", "seed_set")]]]


def seeds_section(tables: dict[str, pd.DataFrame], missing: str) -> Section:
    s = Section("seeds", "Spread across episode seed sets", missing=missing)
    t = tables.get("robust_seeds")
    if t is None:
        return s
    s.blocks.append(
        para(
            "The same part repeated with other episode draws (start positions, "
            "walking directions, slot draws): how much the reversal rates move "
            "when only the physical episodes are redrawn."
        )
    )
    rows = []
    for (part, metric), g in t.groupby(["part", "metric"], sort=True):
        rates = g.sort_values("seed_set")
        rows.append(
            [
                part,
                METRIC_LABELS[metric],
                ", ".join(f"s{r.seed_set}: {pct(r.rate)}" for r in rates.itertuples()),
                pct(rates["rate"].mean()),
                f"{pct(rates['rate'].min())} – {pct(rates['rate'].max())}",
            ]
        )
    s.blocks.append(
        table(
            ["Part", "Metric", "Rate per seed set", "Mean", "Range"],
            rows,
            csv="tables/robust_seeds.csv",
        )
    )
    return s


def _rate_cells(r: Any) -> list[Any]:
    return [
        Cell(pct(r.rate), "num strong"),
        f"[{pct(r.ci_low)}, {pct(r.ci_high)}]",
        f"{r.reversals}/{r.comparisons}",
    ]


def _paper(part: str, key: str, metric: str) -> Cell:
    value = PAPER_ROBUSTNESS.get(part, {}).get(key, {}).get(metric)
    return Cell(pct(value) if value is not None else "—", "paper")


def robustness_sections(
    tables: dict[str, pd.DataFrame], missing: dict[str, str], respondent2: str
) -> list[Section]:
    """The four robustness sections of the page."""
    cols = ["Metric", "Ours", "95% CI", "Reversals / comparable", "Paper"]
    out = []
    s = Section(
        "mapping", "Mapping sensitivity (paper Table III)", missing=missing.get("mapping", "")
    )
    if "robust_mapping" in tables:
        s.blocks.append(
            para(
                "Twelve representative episodes, all population pairs; Mappings "
                "A–D use the same responses, membership and episode assignments. "
                "Agreement: share of controller orderings (non-tied under both) "
                "that a mapping shares with Mapping A."
            )
        )
        t, ag = (
            tables["robust_mapping"],
            tables["robust_agreement"].set_index(["metric", "mapping"]),
        )
        rows = []
        for r in t[t["metric"] != "robot_time"].sort_values(["mapping", "metric"]).itertuples():
            a = ag["agreement"].get((r.metric, r.mapping), np.nan)
            rows.append(
                [
                    r.mapping,
                    METRIC_LABELS[r.metric],
                    *_rate_cells(r),
                    _paper("mapping", r.mapping, r.metric),
                    "—" if r.mapping == "A" else pct(a),
                    _paper("agreement", r.mapping, r.metric),
                ]
            )
        s.blocks.append(
            table(
                ["Mapping", *cols, "Agreement with A", "Paper"],
                rows,
                csv="tables/robust_mapping.csv",
            )
        )
    out.append(s)

    s = Section("structure", "Profile structure (paper §V-D)", missing=missing.get("structure", ""))
    if "robust_structure" in tables:
        s.blocks.append(
            para(
                "Five shared populations on the twelve representative episodes. "
                "Reassigning whole profiles among persona ids keeps the profiles "
                "and breaks who has them; shuffling each column keeps every "
                "marginal and breaks the associations between parameters; single "
                "blocks let only one response block vary."
            )
        )
        t = tables["robust_structure"]
        rows = [
            [
                SET_LABELS.get(r.mapping, "unperturbed (Mapping A)"),
                METRIC_LABELS[r.metric],
                *_rate_cells(r),
                _paper("structure", r.mapping, r.metric),
            ]
            for r in t.sort_values(["mapping", "metric"]).itertuples()
        ]
        s.blocks.append(table(["Profiles", *cols], rows, csv="tables/robust_structure.csv"))
    out.append(s)

    s = Section(
        "backend",
        "Pedestrian dynamics: Ped-ORCA vs navground HL (paper §V-E)",
        missing=missing.get("backend", ""),
    )
    if "robust_backend" in tables:
        s.blocks.append(
            para(
                "Twelve obstacle-free episodes, four populations, everything else "
                "matched; only (cell, population) units completed by all three "
                "controllers under both backends count."
            )
        )
        t = tables["robust_backend"]
        rows = [
            [
                r.backend,
                METRIC_LABELS[r.metric],
                *_rate_cells(r),
                _paper("backend", r.backend, r.metric),
            ]
            for r in t.sort_values(["backend", "metric"]).itertuples()
        ]
        s.blocks.append(table(["Backend", *cols], rows, csv="tables/robust_backend.csv"))
    out.append(s)

    s = Section(
        "respondent",
        "Respondent robustness: the matched intervention again",
        missing=missing.get("respondent", ""),
    )
    if "robust_respondent" in tables:
        s.blocks.append(
            para(
                f"The same persona ids answered by a second respondent "
                f"({respondent2}); probe-defined cohorts are not compared because "
                "their membership depends on the respondent."
            )
        )
        t = tables["robust_respondent"]
        rows = [
            [
                "first (Mapping A)" if r.mapping == "A" else f"second ({r.mapping})",
                METRIC_LABELS[r.metric],
                *_rate_cells(r),
                _paper("respondent", "A" if r.mapping == "A" else "second", r.metric),
            ]
            for r in t.sort_values(["mapping", "metric"]).itertuples()
        ]
        s.blocks.append(table(["Respondent", *cols], rows, csv="tables/robust_respondent.csv"))
    out.append(s)
    out.append(seeds_section(tables, missing.get("seeds", "")))
    return out
