"""Stage 9: a study folder → every table, figure and replay of the report, then the page.

``build_report(folder)`` reads the study (:mod:`popnavshift.engine.folder`), analyses
its main grid, its evidence (the answer: rates against their nulls), its respondents'
answers (the audit) and its robustness parts (:mod:`popnavshift.analysis`), writes the
tables as CSV, draws the figures, re-simulates a few illustrative runs as replays
(:mod:`.replays`) and renders ``report/index.html`` (:mod:`.page`). A section that
cannot be computed on the study given says why on the page instead of failing.
"""

from __future__ import annotations

from functools import partial
from pathlib import Path

import pandas as pd

from ..analysis.audit_verdict import audit_tables
from ..analysis.study import analyse
from ..analysis.study_evidence import evidence_tables
from ..analysis.study_robustness import robustness_tables
from ..engine.folder import main_grid, read_study_folder
from ..engine.respondent_tables import read_respondent_tables
from ..io import write_atomic, write_text
from .answer import with_null_rates
from .answer_figures import write_answer_figures
from .figures import profile_figures, write_figures
from .page import render_report
from .replays import write_replays

REPORT_DIR = "report"


def build_report(folder: Path, *, rng_seed: int = 0, n_boot: int = 1000, replays: int = 2) -> Path:
    """Write ``folder/report/index.html`` (self-contained) with its tables, figures and replays.

    Args:
      folder: a study folder (``runs.parquet``, ``pedestrians.parquet``,
        ``populations.parquet``, ``manifest.json``, ``figures/``).
      rng_seed: seed of every bootstrap of the report.
      n_boot: bootstrap resamples.
      replays: illustrative cases per kind (largest reversal, largest delay) to
        re-simulate and replay; 0 for none.

    Returns the path of ``index.html``. Tables go to ``report/tables/*.csv``,
    figures to ``report/figures/*.png|svg``, replays to ``report/replays/*.html``.
    """
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
    if (study.folder / "responses.parquet").exists():
        analysis.tables.update(audit_tables(*read_respondent_tables(study.folder),
                                            rng_seed=rng_seed, n_boot=n_boot))
    robust, robust_missing = robustness_tables(study, rng_seed=rng_seed, n_boot=n_boot)
    analysis.tables.update(robust)
    analysis.missing.update({f"robust_{k}": v for k, v in robust_missing.items()})
    reps = write_replays(study, analysis, runs, out / "replays", replays)
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


def write_tables(tables: dict[str, pd.DataFrame], folder: Path) -> list[Path]:
    """Each table as ``folder/<name>.csv`` (full precision, no index)."""
    paths = []
    for name, df in tables.items():
        paths.append(write_atomic(folder / f"{name}.csv", partial(df.to_csv, index=False)))
    return paths


def prune(out: Path, written: list[Path]) -> None:
    """Delete what an earlier build left in ``tables/``, ``figures/`` and ``replays/``, so a
    section that is now missing cannot show a stale file."""
    keep = {p.resolve() for p in written}
    for sub in ("tables", "figures", "replays"):
        for path in (out / sub).glob("*") if (out / sub).is_dir() else ():
            if path.is_file() and path.resolve() not in keep:
                path.unlink()
