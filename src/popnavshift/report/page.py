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
from ..read.folder import StudyFolder
from ..result_tables import RESULT_TABLES, csv_path
from .answer import ANSWER, RANKS
from .audit_section import AUDIT, answer_flag, audit_banner
from .blocks import Page, SectionSpec
from .evidence_sections import CALIBRATION, REPLICATES
from .pairs_section import PAIRS
from .robustness import BACKEND, MAPPING, RESPONDENT, SEEDS, STRUCTURE
from .sections import (
    CHANGE,
    NOISE,
    OUTCOMES,
    REVERSALS,
    SENSITIVITY,
    SUMMARY,
    TAU,
    TRADEOFF,
)
from .study_sections import CHECKS, MANIFEST, POPULATIONS, REPLAYS


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


#: The page's sections in reading order. A new section is a :class:`~.blocks.SectionSpec`
#: (its id, title, content function, the tables it needs) and one line here; its tables are
#: declared with its id in :data:`popnavshift.result_tables.RESULT_TABLES`.
SECTIONS: tuple[SectionSpec, ...] = (
    ANSWER,
    RANKS,
    PAIRS,
    REPLICATES,
    CALIBRATION,
    AUDIT,
    POPULATIONS,
    CHECKS,
    SUMMARY,
    REVERSALS,
    NOISE,
    OUTCOMES,
    CHANGE,
    SENSITIVITY,
    TAU,
    TRADEOFF,
    MAPPING,
    STRUCTURE,
    BACKEND,
    RESPONDENT,
    SEEDS,
    REPLAYS,
    MANIFEST,
)


def render_report(study: StudyFolder, a: Analysis, figs: dict[str, Path], out: Path,
                  settings: dict[str, Any]) -> str:
    """The HTML page (a string) of analysis ``a``; ``figs`` maps figure names to PNG paths."""
    page = Page(study, a, figs, out, settings)
    sections = [spec.render(page) for spec in SECTIONS]
    flag = answer_flag(a.tables)  # a respondent that is not usable: said before any rate
    if flag:
        sections[0].blocks.insert(0, flag)
    env = Environment(loader=PackageLoader("popnavshift.report", "templates"), autoescape=True,
                      trim_blocks=True, lstrip_blocks=True)
    cls, note = respondent_note(study.manifest)
    return env.get_template("report.html.j2").render(
        title=f"PopNavShift report — {study.manifest.get('study', study.folder.name)}",
        respondent_cls=cls, respondent_note=note, audit=audit_banner(a.tables),
        selection=a.selection, delays_missing=a.delays_missing, sections=sections,
        tables=[{"name": t.name, "csv": csv_path(t.name), "doc": t.doc} for t in RESULT_TABLES
                if t.name in a.tables])
