"""The report page: the sections of an analysed study → one self-contained HTML file.

One Jinja2 template (``templates/report.html.j2``) with autoescaping on renders the
sections in reading order: the answer first (:mod:`.answer`; under the title, the
respondent audit's banner, :mod:`.audit_section`), then the populations, the
checks before any score, the paper's tables and figures (:mod:`.sections`), the
robustness parts (:mod:`.robustness`), the replays and what produced the report. The page
has no script.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from jinja2 import Environment, PackageLoader

from ..analysis.study import Analysis
from ..engine.folder import StudyFolder
from .answer import answer_section, ranks_section
from .audit_section import answer_flag, audit_banner, audit_section
from .evidence_sections import calibration_section, replicates_section
from .robustness import robustness_sections
from .sections import (
    change_section,
    noise_section,
    outcomes_section,
    reversals_section,
    sensitivity_section,
    summary_section,
    tau_section,
    tradeoff_section,
)
from .study_sections import (
    checks_section,
    manifest_section,
    populations_section,
    replays_section,
    second_respondent,
)


def respondent_note(manifest: dict[str, Any]) -> tuple[str, str]:
    """(css class, text) saying who answered the probes; the rule surrogate is named as such."""
    r = manifest.get("respondent", {})
    name, model = r.get("respondent"), r.get("model", "unknown model")
    if name is None:
        return "note", "The manifest does not say which respondent answered the probes."
    if name == "rule":
        return "warn", (f"Probe responses come from the rule-based surrogate respondent "
                        f"({model}): deterministic offline rules, NOT a language model. The "
                        "paper's personas answered through an LLM, so this run tests the "
                        "pipeline and the simulated populations, not LLM behaviour.")
    where = f" at {r['base_url']}" if r.get("base_url") else ""
    return "p", f"Probe responses come from the language model {model} ({name} respondent{where})."


def render_report(study: StudyFolder, a: Analysis, figs: dict[str, Path], out: Path,
                  settings: dict[str, Any]) -> str:
    """The HTML page (a string) of analysis ``a``; ``figs`` maps figure names to PNG paths."""
    sections = [
        answer_section(a.tables, a.missing, figs, out), ranks_section(a.tables),
        replicates_section(a.tables, a.missing, figs, out),
        calibration_section(a.tables), audit_section(a.tables),
        populations_section(study, a.populations, figs, out), checks_section(a), summary_section(a),
        reversals_section(a, figs, out), noise_section(a), outcomes_section(a),
        change_section(a, figs, out), sensitivity_section(a, figs, out),
        tau_section(a, figs, out), tradeoff_section(a, figs, out),
        *robustness_sections(a.tables, {k[len("robust_"):]: v for k, v in a.missing.items()
                                        if k.startswith("robust_")},
                             second_respondent(study.manifest)),
        replays_section(a), manifest_section(study, settings)]
    if "profiles" in a.missing and not any(b["kind"] == "figure" for b in sections[0].blocks):
        sections[0].missing = a.missing["profiles"]
    flag = answer_flag(a.tables)  # a respondent that is not usable: said before any rate
    if flag:
        sections[0].blocks.insert(0, flag)
    env = Environment(loader=PackageLoader("popnavshift.report", "templates"), autoescape=True,
                      trim_blocks=True, lstrip_blocks=True)
    cls, note = respondent_note(study.manifest)
    return env.get_template("report.html.j2").render(
        title=f"PopNavShift report — {study.manifest.get('study', study.folder.name)}",
        respondent_cls=cls, respondent_note=note, audit=audit_banner(a.tables),
        selection=a.selection,
        delays_missing=a.missing.get("delays", ""), sections=sections,
        tables=sorted(a.tables))
