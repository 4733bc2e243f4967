"""Tables a paper can include: Markdown and LaTeX (booktabs) from a DataFrame, and CSV.

A tiny formatter rather than pandas' ``to_markdown`` (which needs ``tabulate``, not a
dependency) and ``to_latex`` (which does not escape by default): every cell is escaped
for its format (a controller's name is data: it can hold ``|``, ``<script>``, ``$``, ``%``
or a line break), floats get ``digits`` decimals, a missing value is a dash. CSV cells a
spreadsheet would run as a formula are written safe (:func:`popnavshift.io.csv_text`).
"""

from __future__ import annotations

import re
import textwrap
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from ..io import csv_text, write_text

FORMATS: tuple[str, ...] = ("csv", "md", "tex")
_LABEL = re.compile(r"[^A-Za-z0-9:.-]")  # what a \label may hold: any other character → -
_TEX = {"\\": r"\textbackslash{}", "&": r"\&", "%": r"\%", "$": r"\$", "#": r"\#",
        "_": r"\_", "{": r"\{", "}": r"\}", "~": r"\textasciitilde{}",
        "^": r"\textasciicircum{}"}


def _cell(value: Any, digits: int, missing: str) -> str:
    if value is None or (isinstance(value, float | np.floating) and not np.isfinite(value)):
        return missing
    if isinstance(value, float | np.floating):
        return f"{value:.{digits}f}"
    return str(value)


#: characters that make Markdown (GitHub's, with its HTML and math) of a table cell
_MD = {ch: "\\" + ch for ch in "\\|`*_<>~$&"}


def md_escape(text: str) -> str:
    """``text`` as the literal text of one Markdown table cell: markup characters
    backslash-escaped (no emphasis, code, HTML, math or entity), a link's ``](`` broken,
    line breaks and other control characters as spaces."""
    text = "".join(" " if not ch.isprintable() else _MD.get(ch, ch) for ch in text)
    return text.replace("](", "]\\(")


def to_markdown(table: pd.DataFrame, digits: int = 2) -> str:
    """A GitHub-flavoured Markdown table of ``table``'s columns (the index is dropped);
    every cell escaped (:func:`md_escape`)."""
    head = [md_escape(str(c)) for c in table.columns]
    lines = ["| " + " | ".join(head) + " |",
             "|" + "|".join("---:" if pd.api.types.is_numeric_dtype(table[c]) else ":---"
                            for c in table.columns) + "|"]
    for row in table.itertuples(index=False):
        lines.append("| " + " | ".join(md_escape(_cell(v, digits, "–")) for v in row) + " |")
    return "\n".join(lines) + "\n"


def tex_escape(text: str) -> str:
    """``text`` with LaTeX's special characters escaped, line breaks and other control
    characters as spaces."""
    return "".join(" " if not ch.isprintable() else _TEX.get(ch, ch) for ch in text)


def _stacked(header: str, width: int) -> str:
    """A column header broken between words into lines of about ``width`` characters, as
    a one-column tabular (plain LaTeX), so that a long name does not widen its column."""
    lines = textwrap.wrap(header, width, break_long_words=False, break_on_hyphens=False) or [""]
    if len(lines) == 1:
        return tex_escape(header)
    return ("\\begin{tabular}[b]{@{}c@{}}" + r" \\{} ".join(tex_escape(x) for x in lines)
            + "\\end{tabular}")


def to_latex(table: pd.DataFrame, digits: int = 2, *, header_width: int | None = None
             ) -> str:
    """A booktabs ``tabular`` of ``table``'s columns (the index is dropped): numbers right,
    text left, every cell escaped; with ``header_width`` each header is broken into lines
    of about that many characters. Needs ``\\usepackage{booktabs}``."""
    align = "".join("r" if pd.api.types.is_numeric_dtype(table[c]) else "l"
                    for c in table.columns)
    head = [_stacked(str(c), header_width) if header_width else tex_escape(str(c))
            for c in table.columns]
    lines = [f"\\begin{{tabular}}{{{align}}}", "\\toprule", " & ".join(head) + r" \\",
             "\\midrule"]
    for row in table.itertuples(index=False):
        lines.append(" & ".join(tex_escape(_cell(v, digits, "--")) for v in row) + r" \\")
    lines += ["\\bottomrule", "\\end{tabular}"]
    return "\n".join(lines) + "\n"


def latex_table(table: pd.DataFrame, caption: str, *, label: str, digits: int = 2) -> str:
    """``table`` as a complete LaTeX ``table`` float: centred, the caption (plain text,
    escaped here) and label above, the booktabs ``tabular`` scaled to the
    line width (so it fits any page without an overfull box), headers broken into short
    lines so that the scale stays readable. Needs ``booktabs`` and ``graphicx``."""
    body = to_latex(table, digits, header_width=10).rstrip("\n")
    return ("\\begin{table}[tbp]\n\\centering\n"
            f"\\caption{{{tex_escape(caption)}}}\n\\label{{{_LABEL.sub('-', label)}}}\n"
            "\\footnotesize\n\\resizebox{\\linewidth}{!}{%\n"
            f"{body}%\n}}\n\\end{{table}}\n")


def table_text(table: pd.DataFrame, fmt: str, digits: int = 2) -> str:
    """``table`` as ``fmt`` (csv: every digit; md, tex: ``digits``)."""
    if fmt == "csv":
        return csv_text(table)
    if fmt == "md":
        return to_markdown(table, digits)
    if fmt == "tex":
        return to_latex(table, digits)
    raise ValueError(f"unknown table format {fmt!r}; allowed: {', '.join(FORMATS)}")


def write_table(table: pd.DataFrame, path: Path, fmt: str, digits: int = 2) -> Path:
    """Write ``table`` to ``path`` as ``fmt`` (:func:`table_text`), atomically."""
    return write_text(table_text(table, fmt, digits), path)
