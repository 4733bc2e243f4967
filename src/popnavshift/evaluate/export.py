"""Tables a paper can include: Markdown and LaTeX (booktabs) from a DataFrame.

A tiny formatter rather than pandas' ``to_markdown`` (which needs ``tabulate``, not a
dependency) and ``to_latex`` (which does not escape by default): every cell is escaped
for its format, floats get ``digits`` decimals, a missing value is a dash.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from ..io import write_text

FORMATS: tuple[str, ...] = ("csv", "md", "tex")
_TEX = {"\\": r"\textbackslash{}", "&": r"\&", "%": r"\%", "$": r"\$", "#": r"\#",
        "_": r"\_", "{": r"\{", "}": r"\}", "~": r"\textasciitilde{}",
        "^": r"\textasciicircum{}"}


def _cell(value: Any, digits: int, missing: str) -> str:
    if value is None or (isinstance(value, float | np.floating) and not np.isfinite(value)):
        return missing
    if isinstance(value, float | np.floating):
        return f"{value:.{digits}f}"
    return str(value)


def to_markdown(table: pd.DataFrame, digits: int = 2) -> str:
    """A GitHub-flavoured Markdown table of ``table``'s columns (the index is dropped);
    ``|`` and line breaks in cells are escaped."""
    def esc(text: str) -> str:
        return text.replace("|", r"\|").replace("\n", " ")

    head = [esc(str(c)) for c in table.columns]
    lines = ["| " + " | ".join(head) + " |",
             "|" + "|".join("---:" if pd.api.types.is_numeric_dtype(table[c]) else ":---"
                            for c in table.columns) + "|"]
    for row in table.itertuples(index=False):
        lines.append("| " + " | ".join(esc(_cell(v, digits, "–")) for v in row) + " |")
    return "\n".join(lines) + "\n"


def tex_escape(text: str) -> str:
    """``text`` with LaTeX's special characters escaped."""
    return "".join(_TEX.get(ch, ch) for ch in text)


def to_latex(table: pd.DataFrame, digits: int = 2) -> str:
    """A booktabs ``tabular`` of ``table``'s columns (the index is dropped): numbers right,
    text left, every cell escaped. Needs ``\\usepackage{booktabs}``."""
    align = "".join("r" if pd.api.types.is_numeric_dtype(table[c]) else "l"
                    for c in table.columns)
    lines = [f"\\begin{{tabular}}{{{align}}}", "\\toprule",
             " & ".join(tex_escape(str(c)) for c in table.columns) + r" \\", "\\midrule"]
    for row in table.itertuples(index=False):
        lines.append(" & ".join(tex_escape(_cell(v, digits, "--")) for v in row) + r" \\")
    lines += ["\\bottomrule", "\\end{tabular}"]
    return "\n".join(lines) + "\n"


def write_table(table: pd.DataFrame, path: Path, fmt: str, digits: int = 2) -> Path:
    """Write ``table`` to ``path`` as ``fmt`` (csv: every digit; md, tex: ``digits``)."""
    if fmt == "csv":
        text = table.to_csv(index=False)
    elif fmt == "md":
        text = to_markdown(table, digits)
    elif fmt == "tex":
        text = to_latex(table, digits)
    else:
        raise ValueError(f"unknown table format {fmt!r}; allowed: {', '.join(FORMATS)}")
    return write_text(text, path)
