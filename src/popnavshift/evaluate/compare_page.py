"""The comparison as files: one self-contained HTML page with one figure, the full table as
CSV, and its main columns as Markdown and LaTeX.

``write_comparison(comparison, page)`` writes ``page`` (``.html``) and, beside it, the
same stem with ``.csv`` (every column), ``.md`` and ``.tex`` (:func:`display_table`) and
``.png`` (the figure, also embedded in the page).
"""

from __future__ import annotations

import base64
import os
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from jinja2 import Environment, select_autoescape

from ..analysis.ranked import names
from ..io import write_text
from .card import METRIC_LABELS
from .card_page import population_panel, save_png
from .compare import COMPARE_METRICS, Comparison
from .export import write_table

RANKED = names(summary=True)  # the ranks the main table shows
_SHARES = {"success": "success %", "pedestrian_collision": "ped. coll. %",
           "world_collision": "wall/obstacle %", "timeout": "timeout %",
           "controller_error": "ctrl error %"}


def _share(row: pd.Series, outcome: str) -> str:
    """``12.5 [3.5, 29.0]``: a share [%] with its 95 % interval."""
    if not np.isfinite(row[f"{outcome}_pct"]):
        return "–"
    return (f"{row[f'{outcome}_pct']:.1f} [{row[f'{outcome}_low']:.1f}, "
            f"{row[f'{outcome}_high']:.1f}]")


def _rank(row: pd.Series, metric: str) -> str:
    """``2 (1–3)``: the overall rank, then its best–worst over populations."""
    r, best, worst = (row[f"rank_{metric}{s}"] for s in ("", "_best", "_worst"))
    if pd.isna(r):
        return "–"
    return f"{r}" if best == worst == r else f"{r} ({best}–{worst})"


def display_table(table: pd.DataFrame) -> pd.DataFrame:
    """The comparison's main columns as text, one row per controller: verdict, safety
    findings, outcome shares [%] with 95 % intervals, the metrics [s] and ranks."""
    rows = []
    for _, row in table.iterrows():
        out: dict[str, Any] = {"controller": row["controller"], "verdict": row["verdict"],
                               "safety findings": int(row["safety_findings"])}
        out.update({label: _share(row, o) for o, label in _SHARES.items()})
        out.update({METRIC_LABELS[m]: f"{row[m]:.2f}" if np.isfinite(row[m]) else "–"
                    for m in COMPARE_METRICS})
        out.update({f"rank {METRIC_LABELS[m].split(' [')[0]}": _rank(row, m) for m in RANKED})
        rows.append(out)
    return pd.DataFrame(rows)


def compare_figure(comparison: Comparison):
    """Four panels, one per compared metric: its mean per population, each controller in
    its own style (the same as on every card). A matplotlib Figure."""
    import matplotlib  # lazy: slow to import

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 2, figsize=(12, 8), constrained_layout=True)
    for ax, metric in zip(axes.flat, COMPARE_METRICS, strict=True):
        population_panel(ax, comparison.per_population, metric, comparison.controllers)
    handles, labels = axes.flat[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside lower center", ncol=min(6, len(labels)),
               fontsize=9)  # outside the panels: it never hides a point
    fig.suptitle("Controllers compared, per population", fontsize=13)
    return fig


def render_html(comparison: Comparison, png: bytes, page: Path) -> str:
    """The page: every value escaped; the figure embedded (no file beside it needed)."""
    env = Environment(autoescape=select_autoescape(default=True, default_for_string=True))
    shown = display_table(comparison.table)
    links = {c: os.path.relpath(p, Path(page).parent) for c, p in comparison.cards.items()}
    return env.from_string(_PAGE).render(
        c=comparison, columns=list(shown.columns), rows=shown.to_dict("records"),
        verdicts=comparison.verdicts,
        links=links, png=base64.b64encode(png).decode("ascii"), stem=Path(page).stem)


def write_comparison(comparison: Comparison, page: Path) -> dict[str, Path]:
    """Write the page and its tables and figure (module doc); format → path."""
    page = Path(page)
    page.parent.mkdir(parents=True, exist_ok=True)
    paths = {"csv": write_table(comparison.table, page.with_suffix(".csv"), "csv")}
    shown = display_table(comparison.table)
    for fmt in ("md", "tex"):
        paths[fmt] = write_table(shown, page.with_suffix(f".{fmt}"), fmt)
    paths["png"] = save_png(compare_figure(comparison), page.with_suffix(".png"), dpi=100)
    paths["html"] = write_text(render_html(comparison, paths["png"].read_bytes(), page), page)
    return paths


_PAGE = """<!doctype html>
<html lang="en"><head><meta charset="utf-8"><title>Controllers compared:
{{ c.controllers | join(", ") }}</title>
<style>body{font-family:sans-serif;margin:1.5em auto;max-width:1250px;font-size:14px}
table{border-collapse:collapse;margin:.4em 0}td,th{border:1px solid #ccc;padding:2px 7px}
td{text-align:right;white-space:nowrap}td.l,th{text-align:left}.small{color:#555;font-size:12px}
.unsafe,.fails-every-run{color:#b00;font-weight:bold}img{max-width:100%}</style></head><body>
<h1>Controllers compared</h1>
<p>Study <b>{{ c.study.name }}</b> ({{ c.base_folder }}): {{ c.controllers | length }}
controllers on the same episodes and populations. Each row's verdict is its robustness
card's (against the study's built-in baselines); the other columns are computed here on
the union of their runs.</p>
<table><tr>{% for col in columns %}<th>{{ col }}</th>{% endfor %}</tr>
{% for r in rows %}<tr>{% for col in columns %}{% if loop.index <= 2 %}<td class="l{%
if col == 'verdict' %} {{ r[col] | replace(' ', '-') }}{% endif %}">{% if col == 'controller'
%}<a href="{{ links[r[col]] }}">{{ r[col] }}</a>{% else %}{{ r[col] }}{% endif %}</td>{%
else %}<td>{{ r[col] }}</td>{% endif %}{% endfor %}</tr>{% endfor %}</table>
<p class="small">Shares in % of each controller's runs with exact 95% intervals; metrics
in s, the mean over (cell, population) of the cell statistic; rank among the compared
(1 = lowest), in brackets its best–worst rank over the populations. Tables:
{{ stem }}.csv (every column), {{ stem }}.md, {{ stem }}.tex beside this page.</p>
<img src="data:image/png;base64,{{ png }}" alt="compared metrics per population" width="1200">
<h2>Safety findings</h2>
<ul>{% for ctrl, v in verdicts.items() %}<li><b>{{ ctrl }}</b> ({{ v.label }}): {% if v.safety
%}<ul>{% for f in v.safety %}<li>{{ f }}</li>{% endfor %}</ul>{% else %}no failure above
the baselines{% endif %}</li>{% endfor %}</ul>
</body></html>
"""
