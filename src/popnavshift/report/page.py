"""The report page: the sections of an analysed study → one self-contained HTML file.

One Jinja2 template (``templates/report.html.j2``) with autoescaping on renders the
sections in reading order: the answer first (:mod:`.answer`; under the title, the
respondent audit's banner, :mod:`.audit_section`), then the populations, the
checks before any score, the paper's tables and figures (:mod:`.sections`), the
robustness parts (:mod:`.robustness`), the replays and what produced the report. The page
has no script.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from jinja2 import Environment, PackageLoader

from ..analysis.study import Analysis
from ..read.folder import StudyFolder
from .answer import answer_section, ranks_section
from .audit_section import answer_flag, audit_banner, audit_section
from .blocks import Section
from .evidence_sections import calibration_section, replicates_section
from .robustness import (
    backend_section,
    mapping_section,
    respondent_section,
    seeds_section,
    structure_section,
)
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
    if not r.get("endpoint"):  # a plug-in that calls no server: not known to be an LLM
        return "p", f"Probe responses come from the {name} respondent ({model})."
    return "p", (f"Probe responses come from the language model {model} ({name} respondent "
                 f"at {r['endpoint']}).")


@dataclass(frozen=True)
class Page:
    """What every section renders from: the study folder, its analysis, the figures (name
    → PNG path), the report folder and the build settings."""

    study: StudyFolder
    a: Analysis
    figs: dict[str, Path]
    out: Path
    settings: dict[str, Any]

    def missing(self, key: str) -> str:
        return self.a.missing.get(key, "")


#: The page's sections in reading order: (section id, render). A new section is a
#: function returning a :class:`~.blocks.Section` and one line here.
SECTIONS: tuple[tuple[str, Callable[[Page], Section]], ...] = (
    ("answer", lambda p: answer_section(p.a.tables, p.a.missing, p.figs, p.out)),
    ("ranks", lambda p: ranks_section(p.a.tables)),
    ("replicates", lambda p: replicates_section(p.a.tables, p.a.missing, p.figs, p.out)),
    ("calibration", lambda p: calibration_section(p.a.tables)),
    ("audit", lambda p: audit_section(p.a.tables)),
    ("populations", lambda p: populations_section(p.study, p.a.populations, p.figs, p.out)),
    ("checks", lambda p: checks_section(p.a)),
    ("summary", lambda p: summary_section(p.a)),
    ("table1", lambda p: reversals_section(p.a, p.figs, p.out)),
    ("noise", lambda p: noise_section(p.a)),
    ("table2", lambda p: outcomes_section(p.a)),
    ("change", lambda p: change_section(p.a, p.figs, p.out)),
    ("sensitivity", lambda p: sensitivity_section(p.a, p.figs, p.out)),
    ("tau", lambda p: tau_section(p.a, p.figs, p.out)),
    ("tradeoff", lambda p: tradeoff_section(p.a, p.figs, p.out)),
    ("mapping", lambda p: mapping_section(p.a.tables, p.missing("robust_mapping"))),
    ("structure", lambda p: structure_section(p.a.tables, p.missing("robust_structure"))),
    ("backend", lambda p: backend_section(p.a.tables, p.missing("robust_backend"))),
    ("respondent", lambda p: respondent_section(p.a.tables, p.missing("robust_respondent"),
                                                second_respondent(p.study.manifest))),
    ("seeds", lambda p: seeds_section(p.a.tables, p.missing("robust_seeds"))),
    ("replays", lambda p: replays_section(p.a)),
    ("manifest", lambda p: manifest_section(p.study, p.settings)),
)


def render_report(study: StudyFolder, a: Analysis, figs: dict[str, Path], out: Path,
                  settings: dict[str, Any]) -> str:
    """The HTML page (a string) of analysis ``a``; ``figs`` maps figure names to PNG paths."""
    page = Page(study, a, figs, out, settings)
    sections = [render(page) for _, render in SECTIONS]
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
