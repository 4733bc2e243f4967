"""The report's building blocks: a section is a list of blocks (paragraph, note, table,
figure, findings, headline, replays, key–value list, preformatted text) that the page
template renders with autoescaping on, so persona ids, population names and model
strings from the data are always escaped. Figures are embedded as base64 PNG data URIs.
"""

from __future__ import annotations

import base64
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np


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


#: the report's folder of tables, relative to index.html
TABLES_DIR = "tables"


def csv_path(name: str) -> str:
    """The path of table ``name``'s CSV relative to index.html (where the build writes it)."""
    return f"{TABLES_DIR}/{name}.csv"


def table(columns: list[str], rows: list[list[Any]], *, caption: str = "", csv: str = "",
          collapsed: bool = False, groups: list[tuple[str, int]] | None = None) -> dict[str, Any]:
    """A table block; ``csv`` names the analysis table it shows (its CSV is linked),
    ``groups`` is an optional header row above ``columns``: (label, span)."""
    cells = [[c if isinstance(c, Cell) else Cell(str(c)) for c in r] for r in rows]
    return {"kind": "table", "columns": columns, "rows": cells, "caption": caption,
            "csv": csv_path(csv) if csv else "", "collapsed": collapsed, "groups": groups or []}


def para(text: str, kind: str = "p") -> dict[str, Any]:
    return {"kind": kind, "text": text}


def figure(png: Path, out: Path, caption: str) -> dict[str, Any]:
    data = base64.b64encode(png.read_bytes()).decode("ascii")
    rel = png.relative_to(out).as_posix()
    return {"kind": "figure", "src": f"data:image/png;base64,{data}", "caption": caption,
            "png": rel, "svg": rel[: -len(".png")] + ".svg", "alt": caption.split(".")[0]}
