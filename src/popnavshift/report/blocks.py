"""The report's building blocks: a section is a list of blocks (paragraph, note, table,
figure, findings, headline, replays, key–value list, preformatted text) that the page
template renders with autoescaping on, so persona ids, population names and model
strings from the data are always escaped. Figures are embedded as base64 PNG data URIs.

A section is declared once (:class:`SectionSpec`: its id, title, the tables it needs,
its introduction) with a function of its content only; :meth:`SectionSpec.render` does
the rest: the section says why it is empty when its tables are absent (the analysis's
reason under the table's name), and shows only tables declared with it
(:data:`popnavshift.result_tables.RESULT_TABLES`).
"""

from __future__ import annotations

import base64
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd

from ..result_tables import csv_path, result_table

if TYPE_CHECKING:
    from ..analysis.study import Analysis
    from ..read.folder import StudyFolder

Block = dict[str, Any]


@dataclass
class Cell:
    text: str
    cls: str = ""


@dataclass
class Section:
    id: str
    title: str
    blocks: list[dict[str, Any]] = field(default_factory=list)
    missing: str = ""


def fmt(value: Any, pattern: str = "{:.2f}") -> str:
    """``pattern`` applied to a number; an en dash for NaN/None."""
    if value is None or (isinstance(value, (float, np.floating)) and np.isnan(value)):
        return "–"
    return pattern.format(value)


def pct(x: Any) -> str:
    return fmt(None if x is None else 100 * float(x), "{:.1f}%")


def table(columns: list[str], rows: list[list[Any]], *, caption: str = "", csv: str = "",
          collapsed: bool = False, groups: list[tuple[str, int]] | None = None) -> Block:
    """A table block; ``csv`` names the declared report table it shows (its CSV is linked,
    :func:`popnavshift.result_tables.csv_path`), ``groups`` is an optional header row
    above ``columns``: (label, span)."""
    cells = [[c if isinstance(c, Cell) else Cell(str(c)) for c in r] for r in rows]
    return {"kind": "table", "columns": columns, "rows": cells, "caption": caption,
            "table": csv, "csv": csv_path(csv) if csv else "", "collapsed": collapsed,
            "groups": groups or []}


def para(text: str, kind: str = "p") -> dict[str, Any]:
    return {"kind": kind, "text": text}


def figure(png: Path, out: Path, caption: str) -> dict[str, Any]:
    data = base64.b64encode(png.read_bytes()).decode("ascii")
    rel = png.relative_to(out).as_posix()
    return {"kind": "figure", "src": f"data:image/png;base64,{data}", "caption": caption,
            "png": rel, "svg": rel[: -len(".png")] + ".svg", "alt": caption.split(".")[0]}


@dataclass(frozen=True)
class Page:
    """What every section renders from: the study folder, its analysis, the figures (name
    → PNG path), the report folder and the build settings."""

    study: StudyFolder
    a: Analysis
    figs: dict[str, Path]
    out: Path
    settings: dict[str, Any]

    def figure(self, name: str, caption: str) -> list[Block]:
        """Figure ``name`` with its caption, or nothing when it was not drawn."""
        return [figure(self.figs[name], self.out, caption)] if name in self.figs else []


#: a section's content: from the page and the first of its tables present (an empty
#: frame when it needs none), its blocks, or why it has none (a string)
Content = Callable[[Page, pd.DataFrame], "list[Block] | str"]


@dataclass(frozen=True)
class SectionSpec:
    """A section of the page: its ``id`` (its anchor, and the ``section`` its tables are
    declared with), ``title``, ``content``, the tables it ``needs`` (it shows nothing when
    none of them was computed; its content gets the first present), its ``intro`` and what
    it says when its tables are absent and the analysis said nothing (``otherwise``)."""

    id: str
    title: str
    content: Content
    needs: tuple[str, ...] = ()
    intro: str = ""
    otherwise: str = "not computed on this study"

    def render(self, page: Page) -> Section:
        """The section of ``page``: its content, or why it has none."""
        s = Section(self.id, self.title)
        for name in self.needs:
            self._declared_here(name)
        present = [page.a.tables[n] for n in self.needs
                   if n in page.a.tables and not page.a.tables[n].empty]
        if self.needs and not present:
            s.missing = next((page.a.missing[n] for n in self.needs if n in page.a.missing),
                             self.otherwise)
            return s
        got = self.content(page, present[0] if present else pd.DataFrame())
        if isinstance(got, str):
            s.missing = got
            return s
        s.blocks = ([para(self.intro)] if self.intro else []) + got
        for block in s.blocks:
            if block.get("table"):
                self._declared_here(block["table"])
        return s

    def _declared_here(self, name: str) -> None:
        declared = result_table(name).section
        if declared != self.id:
            raise ValueError(f"section {self.id!r} shows table {name!r}, which "
                             f"popnavshift/result_tables.py declares with section {declared!r}")
