"""Stage 9: a study folder → every table, figure and replay of the report, then the page.

``build_report(folder)`` reads the study (:mod:`popnavshift.read.folder`), analyses
its main grid, its evidence (the answer: rates against their nulls), its respondents'
answers (the audit) and its robustness parts (:mod:`popnavshift.analysis`), writes the
tables as CSV, draws the figures, re-simulates a few illustrative runs as replays
(:mod:`.replays`) and renders ``report/index.html`` (:mod:`.page`). A section that
cannot be computed on the study given says why on the page instead of failing. The
report is built in a temporary folder and swapped in whole; its ``stamp.json`` holds
the stamp of its inputs and the sha256 of every file it wrote, so a report that is
stale, half-made or edited since is rebuilt (:func:`report_is_current`), and a reader
of its tables refuses one that is not as written
(:func:`popnavshift.read.access.report_intact`).
"""

from __future__ import annotations

import shutil
from collections.abc import Callable
from pathlib import Path

import pandas as pd

from ..analysis.audit_verdict import audit_tables
from ..analysis.study import analyse
from ..analysis.study_evidence import evidence_tables, with_null_rates
from ..analysis.study_robustness import robustness_tables
from ..hashing import digest, sources_digest
from ..io import write_csv, write_text
from ..outputs import (
    folder_hashes,
    read_output_manifest,
    remove_staging,
    replace_folder,
    staging_folder,
    verify,
    write_output_manifest,
)
from ..read.access import REPORT_DIR, STAMP
from ..read.folder import StudyFolder, main_grid, open_study
from ..read.respondent_tables import read_respondent_tables
from ..result_tables import check_declared, csv_path
from ..version import __version__
from .answer_figures import write_answer_figures
from .figures import profile_figures, write_figures
from .page import render_report
from .replays import write_replays

#: What a report is built from: if none of these changed, nor the analysis and report code,
#: nor the settings, the report on disk is current.
INPUTS = ("runs.parquet", "pedestrians.parquet", "populations.parquet", "episodes.parquet",
          "manifest.json", "personas.parquet", "responses.parquet", "responses_alt.parquet",
          "profiles.parquet")


def report_stamp(folder: Path, settings: dict) -> str:
    """Hash of the report's inputs (name, size, modification time), of the analysis and
    report code and of ``settings``: equal stamps give an equal report."""
    files = [folder / n for n in INPUTS if (folder / n).exists()]
    inputs = [[f.name, f.stat().st_size, f.stat().st_mtime_ns] for f in files]
    return digest([__version__, inputs, sources_digest("analysis", "report"), settings])


def report_is_current(folder: Path, settings: dict) -> str:
    """Why the report of ``folder`` must be built again ("" when it is current): no
    report, a damaged stamp, changed inputs, code or settings, or a file of the report
    missing, changed or added since it was written (as
    :func:`popnavshift.read.access.report_intact`)."""
    out = Path(folder) / REPORT_DIR
    if not (out / "index.html").exists():
        return "there is no report yet"
    stamp, why = read_output_manifest(out / STAMP)
    if why:
        return why
    if not isinstance(stamp.get("stamp"), str):
        return f"{out / STAMP} is damaged (it holds no stamp)"
    if stamp["stamp"] != report_stamp(Path(folder), settings):
        return "the study's tables, the analysis code or the settings changed since it was written"
    return verify(out, stamp, only=True, ignore=(STAMP,))


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
    ``report/stamp.json`` records what it was built from and the sha256 of every file
    it wrote (:func:`report_is_current`). The report is built in a temporary folder
    beside it and put in place whole (:func:`popnavshift.outputs.replace_folder`): an
    interrupted build leaves the old report or none, never a mix. ``progress`` is
    called with the name of each step as it starts.
    """
    step = progress or (lambda _: None)
    settings = {"rng_seed": rng_seed, "n_boot": n_boot, "replays": replays}
    step("reading the study")
    study = open_study(Path(folder))
    study.runs, study.pedestrians  # noqa: B018 — a folder without its run tables fails here
    target = study.folder / REPORT_DIR
    remove_staging(study.folder, REPORT_DIR)  # what a killed build left
    out = staging_folder(target)
    try:
        _build(study, out, settings, step)
        write_output_manifest(out / STAMP, {"stamp": report_stamp(study.folder, settings),
                                            "files": folder_hashes(out)})
        replace_folder(out, target)
    finally:
        if out.exists():
            shutil.rmtree(out, ignore_errors=True)
    return target / "index.html"


def _build(study: StudyFolder, out: Path, settings: dict, step: Callable[[str], None]) -> None:
    """Every table, figure, replay and the page of ``study``'s report, into ``out``."""
    rng_seed, n_boot = settings["rng_seed"], settings["n_boot"]
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
    fig3, analysis.profiles_missing = profile_figures(study.folder / "figures",
                                                      study.populations, out / "figures")
    if (study.folder / "responses.parquet").exists():
        step("the respondent audit")
        analysis.tables.update(audit_tables(*read_respondent_tables(study.folder),
                                            rng_seed=rng_seed, n_boot=n_boot))
    step("robustness parts")
    robust, robust_missing = robustness_tables(study, rng_seed=rng_seed, n_boot=n_boot)
    analysis.tables.update(robust)
    analysis.missing.update(robust_missing)
    step("replays")
    reps = write_replays(study, analysis, runs, out / "replays", settings["replays"])
    if reps is not None and not reps.empty:
        analysis.tables["replays"] = reps
    elif settings["replays"] <= 0:
        analysis.missing["replays"] = "replays were not asked for (replays=0)"
    check_declared(analysis.missing, "why tables are missing, for tables")
    write_tables(analysis.tables, out)
    step("the page")
    write_text(render_report(study, analysis, {**figures, **fig3}, out, settings),
               out / "index.html")


def write_tables(tables: dict[str, pd.DataFrame], folder: Path) -> list[Path]:
    """Each table as ``folder/tables/<name>.csv`` (:func:`popnavshift.result_tables.csv_path`;
    full precision, no index, text cells safe in a spreadsheet: :func:`popnavshift.io.csv_text`).
    A ValueError names any table :data:`popnavshift.result_tables.RESULT_TABLES` does not
    declare."""
    check_declared(tables, "report tables")
    return [write_csv(df, folder / csv_path(name)) for name, df in tables.items()]
