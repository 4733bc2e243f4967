"""Stage 9: a study folder → every table, figure and replay of the report, then the page.

``build_report(folder)`` reads the study (:mod:`popnavshift.read.folder`), analyses
its main grid, its evidence (the answer: rates against their nulls), its respondents'
answers (the audit) and its robustness parts (:mod:`popnavshift.analysis`), writes the
tables as CSV, draws the figures, re-simulates a few illustrative runs as replays
(:mod:`.replays`) and renders ``report/index.html`` (:mod:`.page`). A section that
cannot be computed on the study given says why on the page instead of failing.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Callable
from functools import partial
from pathlib import Path

import pandas as pd

from ..analysis.audit_verdict import audit_tables
from ..analysis.study import analyse
from ..analysis.study_evidence import evidence_tables, with_null_rates
from ..analysis.study_robustness import robustness_tables
from ..hashing import digest
from ..io import write_atomic, write_json, write_text
from ..read.folder import main_grid, open_study
from ..read.respondent_tables import read_respondent_tables
from ..version import __version__
from .answer_figures import write_answer_figures
from .blocks import TABLES_DIR, csv_path
from .figures import profile_figures, write_figures
from .page import render_report
from .replays import write_replays

REPORT_DIR = "report"


#: What a report is built from: if none of these changed, nor the analysis and report code,
#: nor the settings, the report on disk is current.
INPUTS = ("runs.parquet", "pedestrians.parquet", "populations.parquet", "episodes.parquet",
          "manifest.json", "personas.parquet", "responses.parquet", "responses_alt.parquet",
          "profiles.parquet")
STAMP = "stamp.json"


def report_stamp(folder: Path, settings: dict) -> str:
    """Hash of the report's inputs (name, size, modification time), of the analysis and
    report code and of ``settings``: equal stamps give an equal report."""
    package = Path(__file__).resolve().parents[1]
    files = [folder / n for n in INPUTS if (folder / n).exists()]
    inputs = [[f.name, f.stat().st_size, f.stat().st_mtime_ns] for f in files]
    code = [[p.relative_to(package).as_posix(), hashlib.sha256(p.read_bytes()).hexdigest()]
            for sub in ("analysis", "report") for p in sorted((package / sub).rglob("*"))
            if p.suffix in (".py", ".j2")]
    return digest([__version__, inputs, code, settings])


def report_is_current(folder: Path, settings: dict) -> str:
    """Why the report of ``folder`` must be built again ("" when it is current)."""
    out = Path(folder) / REPORT_DIR
    if not (out / "index.html").exists():
        return "there is no report yet"
    try:
        stored = json.loads((out / STAMP).read_text("utf-8")).get("stamp")
    except (OSError, ValueError):
        return "the report has no stamp (an older version wrote it)"
    return "" if stored == report_stamp(Path(folder), settings) else (
        "the study's tables, the analysis code or the settings changed since it was written")


def build_report(folder: Path, *, rng_seed: int = 0, n_boot: int = 1000, replays: int = 2,
                 progress: Callable[[str], None] | None = None) -> Path:
    """Write ``folder/report/index.html`` (self-contained) with its tables, figures and replays.

    Args:
      folder: a study folder (``runs.parquet``, ``pedestrians.parquet``,
        ``populations.parquet``, ``manifest.json``, ``figures/``).
      rng_seed: seed of every bootstrap of the report.
      n_boot: bootstrap resamples.
      replays: illustrative cases per kind (largest reversal, largest delay) to
        re-simulate and replay; 0 for none.

    Returns the path of ``index.html``. Tables go to ``report/tables/*.csv``,
    figures to ``report/figures/*.png|svg``, replays to ``report/replays/*.html``;
    ``report/stamp.json`` records what it was built from (:func:`report_is_current`).
    ``progress`` is called with the name of each step as it starts.
    """
    step = progress or (lambda _: None)
    settings = {"rng_seed": rng_seed, "n_boot": n_boot, "replays": replays}
    step("reading the study")
    study = open_study(Path(folder))
    out = study.folder / REPORT_DIR
    runs, peds, selection = main_grid(study)
    step("the paper's tables")
    analysis = analyse(runs, peds, selection=selection, rng_seed=rng_seed, n_boot=n_boot)
    step("rates against their nulls, calibration and power")
    evidence, evidence_missing = evidence_tables(study, rng_seed=rng_seed, n_boot=n_boot)
    analysis.tables.update(evidence)
    analysis.missing.update(evidence_missing)
    if "reversals" in analysis.tables:
        analysis.tables["reversals"] = with_null_rates(analysis.tables["reversals"], evidence)
    step("figures")
    figures = write_figures(analysis, out / "figures")
    figures.update(write_answer_figures(evidence, out / "figures"))
    fig3, why = profile_figures(study.folder / "figures", study.populations, out / "figures")
    if why:
        analysis.missing["profiles"] = why
    if (study.folder / "responses.parquet").exists():
        step("the respondent audit")
        analysis.tables.update(audit_tables(*read_respondent_tables(study.folder),
                                            rng_seed=rng_seed, n_boot=n_boot))
    step("robustness parts")
    robust, robust_missing = robustness_tables(study, rng_seed=rng_seed, n_boot=n_boot)
    analysis.tables.update(robust)
    analysis.missing.update({f"robust_{k}": v for k, v in robust_missing.items()})
    step("replays")
    reps = write_replays(study, analysis, runs, out / "replays", replays)
    if reps is not None and not reps.empty:
        analysis.tables["replays"] = reps
    elif replays <= 0:
        analysis.missing["replays"] = "replays were not asked for (replays=0)"
    written = write_tables(analysis.tables, out)
    written += [p.with_suffix(x) for p in {**figures, **fig3}.values() for x in (".png", ".svg")]
    if reps is not None:
        files = [out / f for f in reps["file"] if f]
        written += files + [f.with_suffix(".svg") for f in files]
    prune(out, written)
    step("the page")
    page = render_report(study, analysis, {**figures, **fig3}, out, settings)
    path = write_text(page, out / "index.html")
    write_json({"stamp": report_stamp(study.folder, settings)}, out / STAMP)
    return path


def write_tables(tables: dict[str, pd.DataFrame], folder: Path) -> list[Path]:
    """Each table as ``folder/tables/<name>.csv`` (:func:`.blocks.csv_path`; full
    precision, no index)."""
    paths = []
    for name, df in tables.items():
        paths.append(write_atomic(folder / csv_path(name), partial(df.to_csv, index=False)))
    return paths


def prune(out: Path, written: list[Path]) -> None:
    """Delete what an earlier build left in ``tables/``, ``figures/`` and ``replays/``, so a
    section that is now missing cannot show a stale file."""
    keep = {p.resolve() for p in written}
    for sub in (TABLES_DIR, "figures", "replays"):
        for path in (out / sub).glob("*") if (out / sub).is_dir() else ():
            if path.is_file() and path.resolve() not in keep:
                path.unlink()
