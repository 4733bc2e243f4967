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
import re
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from jinja2 import Environment, select_autoescape
from markupsafe import Markup, escape

from ..controller_ids import display_name
from ..errors import ConfigError, InputError
from ..io import read_json_object
from ..outputs import FileSet, check_writable
from ..version import __version__
from ..viz.style import controller_styles
from .card import METRIC_LABELS
from .card_files import folder_name
from .card_page import png_bytes, population_panel
from .compare import COMPARE_METRICS, Comparison
from .export import latex_table, table_text

RANKED = COMPARE_METRICS  # the ranks the tables show: every ranked metric, as the CSV
_SHARES = {"success": "success %", "pedestrian_collision": "ped. coll. % (robot moving)",
           "standing_contact": "standing contacts %", "world_collision": "wall / obstacle %",
           "timeout": "timeout %", "controller_error": "ctrl error %"}
_MEANS = {"min_clearance": "min. clearance [m]", "path_length": "path [m]",
          "stop_time": "stop time [s]"}


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


def _excess(row: pd.Series, *, where: bool = True) -> str:
    """``+3.2 [-1.0, +7.4] pp (all pairs, mean delay)``: the rate that carries the
    robustness verdict, its excess over the null with the simultaneous interval (without
    ``where``, the numbers only: ``+3.2 [-1.0, +7.4]``)."""
    if not np.isfinite(row["excess_pp"]):
        return "–"
    if not where:
        return (f"{row['excess_pp']:+.1f} [{row['excess_low_pp']:+.1f}, "
                f"{row['excess_high_pp']:+.1f}]")
    metric = METRIC_LABELS.get(row["robustness_metric"], row["robustness_metric"])
    place = (f" ({str(row['robustness_design']).replace('_', ' ')}, "
             f"{str(metric).split(' [')[0]})")
    return (f"{row['excess_pp']:+.1f} [{row['excess_low_pp']:+.1f}, "
            f"{row['excess_high_pp']:+.1f}] pp{place}")


def display_table(table: pd.DataFrame, *, short: bool = False) -> pd.DataFrame:
    """The comparison's main columns as text, one row per controller: the robustness verdict
    with the excess that carries it, how many of its interaction rows change beyond the null
    (the card's second question), the safety verdict, outcome shares [%] with 95 %
    intervals, the metrics [s], the robot's clearance, path and stop time, and the ranks
    with their best–worst range over populations. ``short``: the columns a paper's page
    holds (the LaTeX table, :data:`SHORT_DROPS`): no intervals on the shares; the burden
    metrics, the clearance and the burden ranks only."""
    rows = []
    for _, row in table.iterrows():
        out: dict[str, Any] = {"controller": row["controller"],
                               "robustness": row["robustness"],
                               "excess over null" + (" [pp]" if short else ""):
                                   _excess(row, where=not short),
                               # the second question: its rows whose differences from the
                               # baselines change beyond the null, of those tested
                               "differences change": _text(row.get("differences_change")),
                               "safety": row["safety"]}
        for o, label in _SHARES.items():
            out[label] = (f"{row[f'{o}_pct']:.1f}" if short and np.isfinite(row[f"{o}_pct"])
                          else _share(row, o))
        out.update({METRIC_LABELS[m]: f"{row[m]:.2f}" if np.isfinite(row[m]) else "–"
                    for m in COMPARE_METRICS})
        out.update({label: f"{row[m]:.2f}" if np.isfinite(row[m]) else "–"
                    for m, label in _MEANS.items()})
        out.update({f"rank {METRIC_LABELS[m].split(' [')[0]}": _rank(row, m) for m in RANKED})
        rows.append({k: v for k, v in out.items() if not (short and k in SHORT_DROPS)})
    return pd.DataFrame(rows)


def _text(value: Any) -> str:
    """A text cell, "–" when empty or missing."""
    return value if isinstance(value, str) and value else "–"


#: the columns the short (LaTeX) table leaves to the CSV and Markdown: a paper's page holds
#: about a dozen; the robot time and the timeouts are in Table II of the study's report
SHORT_DROPS = frozenset({"differences change",
    _SHARES["timeout"], _SHARES["controller_error"], _SHARES["standing_contact"],
    METRIC_LABELS["cvar90"], _MEANS["path_length"], _MEANS["stop_time"],
    "rank " + METRIC_LABELS["robot_time"].split(" [")[0],
    "rank " + METRIC_LABELS["cvar90"].split(" [")[0],
    "rank " + METRIC_LABELS["blocked_pct"].split(" [")[0]})


def caption(comparison: Comparison) -> str:
    """The table's caption, plain text: what the rows are, the study, the rules, provenance."""
    st = comparison.settings
    return (f"Controllers under behavioural population shift (PopNavShift {__version__}, "
            f"study {comparison.study.name}, configuration {comparison.study.config_hash()}, "
            f"{comparison.made[:10]}). Robustness: reversal rates of each controller's "
            f"orderings against {', '.join(st.get('baselines', []))} beyond its own null "
            "runs (excess in pp, simultaneous 95% interval); safety: a counted failure above "
            f"{100 * st.get('safety_threshold', 0):g}% of its runs with 95% confidence; shares "
            "in % of runs, metrics in s or m, blocked pedestrians in % of those that "
            "arrived without the robot; rank among the compared (best-worst over "
            "populations).")


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
    if len(axes.flat) > len(COMPARE_METRICS):  # in the empty panel: it never hides a point
        axes.flat[-1].legend(handles, labels, loc="center", fontsize=9, frameon=False)
    else:  # below the panels, in as many columns as long names leave room for
        wide = max((len(x) for x in labels), default=0) > 24
        fig.legend(handles, labels, loc="outside lower center",
                   ncol=min(3 if wide else 6, len(labels)), fontsize=9)
    fig.suptitle("Controllers compared, per population", fontsize=13)
    return fig


def render_html(comparison: Comparison, png: bytes, page: Path) -> str:
    """The page: every value escaped; the figure embedded (no file beside it needed)."""
    env = Environment(autoescape=select_autoescape(default=True, default_for_string=True))
    env.filters["label"] = display_name
    shown = display_table(comparison.table)
    links = {c: os.path.relpath(p, Path(page).parent) for c, p in comparison.cards.items()}
    rows = [{k: _two_lines(v) if k not in ("controller", "robustness", "safety") else v
             for k, v in r.items()} for r in shown.to_dict("records")]
    styles = controller_styles(comparison.controllers)
    looks = {c: {"colour": st.colour, "symbol": MARKER_SYMBOLS.get(st.marker, st.marker)}
             for c, st in styles.items()}
    return env.from_string(_PAGE).render(
        c=comparison, columns=list(shown.columns), rows=rows,
        verdicts=comparison.verdicts, looks=looks, version=__version__,
        links=links, png=base64.b64encode(png).decode("ascii"), stem=Path(page).stem,
        folder=folder_name(comparison.base_folder),
        heading=HEADINGS.get(comparison.kind, HEADINGS["compare"]))


_INTERVAL = re.compile(r"^(.*?) ([\[(].*)$")


def _two_lines(value: Any) -> Any:
    """``90.0 [76.3, 97.2]`` (a share and its interval) or ``2 (1–3)`` (a rank and its
    range) as the value with the bracket below it, smaller (the page's table stays narrow
    enough for a 1280 px window); anything else as it is. Escaped."""
    m = _INTERVAL.match(value) if isinstance(value, str) else None
    if not m:
        return value
    return Markup(f"{escape(m.group(1))}<br><span class=\"ci\">{escape(m.group(2))}</span>")


#: each matplotlib marker as the character the page draws it with beside a row's name
MARKER_SYMBOLS = {"o": "●", "s": "■", "^": "▲", "D": "◆", "v": "▼", "P": "✚", "X": "✖",
                  "h": "⬢", "<": "◀", ">": "▶", "p": "⬟", "*": "★", "d": "♦", "8": "⯃",
                  "H": "⬣"}


#: the page's heading by the comparison's kind
HEADINGS = {"compare": "Controllers compared",
            "leaderboard": "Leaderboard: every controller, two verdicts each"}

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


def _labelled(shown: pd.DataFrame) -> pd.DataFrame:
    """``shown`` with a policy named by its file and hash, not its machine path (the CSV
    and the page's links keep the id)."""
    return shown.assign(controller=[display_name(c) for c in shown["controller"]])


def write_comparison(comparison: Comparison, page: Path) -> dict[str, Path]:
    """Write the page and its tables and figure as one set (module doc; the caller has
    checked ``page``: :func:`check_page`); format → path."""
    page = Path(page)
    shown = display_table(comparison.table)
    with FileSet(page.parent, page.with_suffix(".json").name) as files:
        paths = {"csv": files.add_text(page.with_suffix(".csv").name,
                                       table_text(comparison.table, "csv")),
                 "md": files.add_text(page.with_suffix(".md").name,
                                      table_text(_labelled(shown), "md")),
                 "tex": files.add_text(page.with_suffix(".tex").name, latex_table(
                     _labelled(display_table(comparison.table, short=True)), caption(comparison),
                     label=f"tab:{Path(page).stem}"))}
        png = png_bytes(compare_figure(comparison), dpi=100)
        paths["png"] = files.add(page.with_suffix(".png").name, lambda tmp: tmp.write_bytes(png))
        paths["html"] = files.add_text(page.name, render_html(comparison, png, page))
        files.commit({"kind": KIND, "what": comparison.kind,
                      "controllers": list(comparison.controllers),
                      "study": comparison.study.name,
                      "config_hash": comparison.study.config_hash(),
                      "popnavshift": __version__, "made": comparison.made,
                      "settings": comparison.settings, "verdicts": comparison.verdicts})
    return paths


_PAGE = """<!doctype html>
<html lang="en"><head><meta charset="utf-8"><title>{{ heading }}:
{{ c.controllers | map("label") | join(", ") }}</title>
<style>body{font-family:sans-serif;margin:1em auto;max-width:1264px;padding:0 .5em;
font-size:14px}table{border-collapse:collapse;margin:.4em 0;font-size:11px}
td,th{border:1px solid #ccc;padding:2px 3px}td{text-align:right;white-space:nowrap}
td.l,th{text-align:left}.small{color:#555;font-size:12px}.wrap{overflow-x:auto;max-width:100%}
.population-sensitive,.unsafe,.fails-every-run{color:#b00;font-weight:bold}
.robust,.safe{color:#2a7a2a;font-weight:bold}.undecided{color:#a60}
.mark{font-size:15px}img{max-width:100%}.ci{color:#666;font-size:10px}</style></head><body>
<h1>{{ heading }}</h1>
<p>Study <b>{{ c.study.name }}</b> (configuration {{ c.study.config_hash() }}, folder
{{ folder }}): {{ c.controllers | length }} controllers on the same episodes and
populations. PopNavShift {{ version }}, made {{ c.made }}. Every card was made under the
same rules: against {{ c.settings.get("baselines", []) | map("label") | join(", ") }},
{{ c.settings.get("n_boot", "–") }} bootstrap resamples, seed {{ c.settings.get("seed", "–") }},
safety threshold {{ c.settings.get("safety_threshold", "–") }} of the runs. The
<b>robustness</b> verdict of each row is decided against that controller's own null runs
(the rate shown is the one that carries it: its excess over the null in percentage points,
with its simultaneous 95% interval); <b>safety</b> follows one rule for every row, so both
columns can be ranked.</p>
<div class="wrap"><table><tr>{% for col in columns %}<th>{{ col }}</th>{% endfor %}</tr>
{% for r in rows %}<tr>{% for col in columns %}{% if col == 'controller' %}<td class="l">
<span class="mark" style="color:{{ looks[r[col]].colour }}">{{ looks[r[col]].symbol }}</span>
<a href="{{ links[r[col]] }}">{{ r[col] | label }}</a></td>{% elif col in ('robustness', 'safety')
%}<td class="l {{ r[col] | replace(' ', '-') }}">{{ r[col] }}</td>{% else %}<td>{{ r[col] }}</td>
{% endif %}{% endfor %}</tr>{% endfor %}</table></div>
<p class="small">Shares in % of each controller's runs with exact 95% intervals
(pedestrian collisions with the robot moving apart from pedestrians walking into the
standing robot); metrics in s, the mean over (cell, population) of the cell statistic;
clearance, path and stop time the mean over its runs; rank among the compared (1 = lowest),
in brackets its best–worst rank over the populations. Tables: {{ stem }}.csv (every
column), {{ stem }}.md, {{ stem }}.tex (a LaTeX table with caption and label) beside this
page.</p>
<img src="data:image/png;base64,{{ png }}" alt="compared metrics per population">
<h2>Verdicts in words</h2>
<ul>{% for ctrl, v in verdicts.items() %}<li><b>{{ ctrl | label }}</b> — robustness
<span class="{{ v.robustness.label | replace(' ', '-') }}">{{ v.robustness.label }}</span>:
{{ v.robustness.text }}{% if v.robustness.decide %} {{ v.robustness.decide }}{% endif %}
Safety <span class="{{ v.safety.label }}">{{ v.safety.label }}</span>: {{ v.safety.text }}
</li>{% endfor %}</ul>
</body></html>
"""
