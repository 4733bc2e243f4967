"""The comparison as files: one self-contained HTML page with one figure, the full table as
CSV, and its main columns as Markdown and LaTeX.

``write_comparison(comparison, page)`` writes ``page`` (``.html``) and, beside it, the
same stem with ``.csv`` (every column), ``.md`` and ``.tex`` (:func:`display_table`),
``.png`` (the figure, also embedded in the page) and, last, ``.json``: the manifest of
the set (the controllers, the settings their cards were made under, each file's sha256;
:class:`popnavshift.outputs.FileSet`), so a comparison interrupted while it is written
never leaves the tables of one set of controllers beside the page of another
unannounced. :func:`check_page` refuses, before any work, a page whose files would
replace files that no comparison wrote.
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
from ..errors import ConfigError, InputError
from ..io import read_json_object
from ..outputs import FileSet, check_writable
from .card import METRIC_LABELS
from .card_page import png_bytes, population_panel
from .compare import COMPARE_METRICS, Comparison
from .export import table_text

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
    """One panel per compared metric, two per row: its mean per population, each controller
    in its own style (the same as on every card). A matplotlib Figure."""
    import matplotlib  # lazy: slow to import

    matplotlib.use("Agg")
    matplotlib.rcParams["text.parse_math"] = False  # a label is data: "$" is no math
    import matplotlib.pyplot as plt

    n_rows = -(-len(COMPARE_METRICS) // 2)
    fig, axes = plt.subplots(n_rows, 2, figsize=(12, 4 * n_rows), constrained_layout=True,
                             squeeze=False)
    for ax, metric in zip(axes.flat, COMPARE_METRICS, strict=False):
        population_panel(ax, comparison.per_population, metric, comparison.controllers)
    for ax in axes.flat[len(COMPARE_METRICS):]:
        ax.set_axis_off()
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


#: the files of a comparison, by the suffix of the page's stem; the manifest is ``.json``
SUFFIXES: tuple[str, ...] = (".html", ".csv", ".md", ".tex", ".png")
KIND = "popnavshift compare"


def check_page(page: Path, *, ours: bool = False) -> None:
    """ConfigError unless ``page`` (``--out``) can be written: an ``.html`` name in a
    folder we may write (or create), not a folder, and none of its files
    (:data:`SUFFIXES` and the ``.json`` manifest) an existing file that an earlier
    comparison, by its manifest, did not write (unless the folder is ``ours``: the study's
    own ``compare/``, where a comparison of an older version left no manifest)."""
    page = Path(page)
    hint = "choose another --out (default: STUDY_DIR/compare/compare.html)"
    if page.suffix != ".html":
        raise ConfigError(f"--out must name an .html page, got {str(page)!r}",
                          hint=f"e.g. --out {page.with_suffix('.html')}")
    manifest = page.with_suffix(".json")
    written: set[str] = set()
    try:
        doc = read_json_object(manifest) if manifest.is_file() else {}
    except InputError:
        doc = {}
    if doc.get("kind") == KIND and isinstance(doc.get("files"), dict):
        written = {*doc["files"], manifest.name}
    for path in (page.with_suffix(s) for s in (*SUFFIXES, ".json")):
        if path.is_dir():
            raise ConfigError(f"--out {page}: {path} is a folder", hint=hint)
        if path.exists() and not ours and path.name not in written:
            raise ConfigError(f"--out {page} would replace {path}, which no comparison wrote",
                              hint=hint + ", or move that file")
    check_writable(page.parent, f"--out {page}")


def write_comparison(comparison: Comparison, page: Path) -> dict[str, Path]:
    """Write the page and its tables and figure as one set (module doc; the caller has
    checked ``page``: :func:`check_page`); format → path."""
    page = Path(page)
    shown = display_table(comparison.table)
    with FileSet(page.parent, page.with_suffix(".json").name) as files:
        paths = {"csv": files.add_text(page.with_suffix(".csv").name,
                                       table_text(comparison.table, "csv"))}
        for fmt in ("md", "tex"):
            paths[fmt] = files.add_text(page.with_suffix(f".{fmt}").name, table_text(shown, fmt))
        png = png_bytes(compare_figure(comparison), dpi=100)
        paths["png"] = files.add(page.with_suffix(".png").name, lambda tmp: tmp.write_bytes(png))
        paths["html"] = files.add_text(page.name, render_html(comparison, png, page))
        files.commit({"kind": KIND, "controllers": list(comparison.controllers),
                      "study": comparison.study.name,
                      "config_hash": comparison.study.config_hash(),
                      "settings": comparison.settings, "verdicts": comparison.verdicts})
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
card's, every card made under the same rules: against
{{ c.settings.get("baselines", []) | join(", ") or "the built-in baselines" }},
{{ c.settings.get("n_boot", "–") }} bootstrap resamples, seed {{ c.settings.get("seed", "–") }},
{% if c.settings.get("safety_threshold") is not none %}safety threshold
{{ c.settings.safety_threshold }} of the runs{% else %}no absolute safety threshold{% endif %};
the other columns are computed here on the union of their runs.</p>
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
