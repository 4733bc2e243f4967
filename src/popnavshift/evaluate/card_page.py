"""The population-robustness card as a figure (PNG) and one HTML page.

``write_card(card, meta, files, svg)`` renders a :class:`~.card.Card` (the pure tables of
:func:`~.card.card_tables`) with the replay SVG of its worst run, drawn elsewhere, into
the card's :class:`~popnavshift.outputs.FileSet` (committed with the rest of the card).
"""

from __future__ import annotations

import io
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from jinja2 import Environment, select_autoescape
from markupsafe import Markup

from ..analysis import METRICS, TOLERANCES
from ..outputs import FileSet
from ..populations.build import population_order
from ..viz.style import controller_style
from .card import METRIC_LABELS, N_WORST, Card
from .safety import FAILURES
from .verdict import VERDICT_METRICS


# ------------------------------------------------------------------------ the figure
def card_figure(card: Card):
    """Four panels: the three metrics per population by controller (each in its own style,
    the evaluated one highlighted), and the reversal rates against each baseline with
    their intervals. A matplotlib Figure."""
    import matplotlib  # lazy: only drawing the card needs matplotlib (slow to import)

    matplotlib.use("Agg")
    matplotlib.rcParams["text.parse_math"] = False  # a label is data: "$" is no math
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 2, figsize=(12, 8), constrained_layout=True)
    ctrls = (*card.baselines, card.controller)
    for ax, metric in zip(axes.flat[:3], METRICS, strict=True):
        population_panel(ax, card.per_population, metric, ctrls, card.controller)
    axes.flat[0].legend(fontsize=8)
    _reversal_panel(axes.flat[3], card)
    fig.suptitle(f"Population robustness of {card.controller}", fontsize=13)
    return fig


def png_bytes(fig, dpi: int = 110) -> bytes:
    """``fig`` as PNG; the figure is closed."""
    import matplotlib.pyplot as plt

    buffer = io.BytesIO()
    try:
        fig.savefig(buffer, format="png", dpi=dpi)
    finally:
        plt.close(fig)
    return buffer.getvalue()


def population_panel(ax, per_population: pd.DataFrame, metric: str, controllers: Sequence[str],
                     highlight: str | None = None) -> None:
    """``metric`` [s] per population (x, categories: markers, no joining lines), one series
    per controller in its own style (:func:`controller_style`); ``highlight`` drawn larger
    with a black edge. ``per_population``: rows (population, controller) with ``metric``."""
    pops = population_order(per_population["population"].unique())
    x = np.arange(len(pops))
    for i, ctrl in enumerate(controllers):
        s = per_population[per_population["controller"] == ctrl].set_index("population")
        look, mine = controller_style(ctrl), ctrl == highlight
        ax.scatter(x + (i - (len(controllers) - 1) / 2) * 0.15,
                   s[metric].reindex(pops).to_numpy(float), marker=look.marker,
                   s=60 if mine else 28, color=look.colour, label=ctrl, zorder=3 if mine else 2,
                   edgecolors="black" if mine else "none", linewidths=1.2)
    ax.set_title(METRIC_LABELS[metric])
    ax.set_xticks(x, pops, rotation=30, ha="right", fontsize=8)
    ax.grid(alpha=0.3)


def _reversal_panel(ax, card: Card) -> None:
    rv = card.reversals
    width = 0.8 / max(1, len(card.baselines))
    for i, b in enumerate(card.baselines):
        s = rv[rv["baseline"] == b].set_index("metric").reindex(list(METRICS))
        rate = 100 * s["rate"].to_numpy(float)  # in %, as the tables
        low, high = 100 * s["ci_low"].to_numpy(float), 100 * s["ci_high"].to_numpy(float)
        err = np.vstack([rate - low, high - rate])
        xs = np.arange(len(METRICS)) + (i - (len(card.baselines) - 1) / 2) * width
        ax.bar(xs, np.nan_to_num(rate), width, label=f"vs {b}", color=controller_style(b).colour)
        ax.errorbar(xs, rate, yerr=np.nan_to_num(err), fmt="none", ecolor="#333", capsize=3)
        tops = np.nan_to_num(np.fmax(high, rate))
        for xi, top, k, n in zip(xs, tops, s["reversals"], s["comparisons"], strict=True):
            ax.text(xi, top + 2, f"{k}/{n}", ha="center", fontsize=7)
    ax.set_xticks(np.arange(len(METRICS)), [METRIC_LABELS[m].split(" [")[0] for m in METRICS])
    ax.set_ylim(0, 115)  # room for the count labels above a 100% bar
    ax.set_ylabel("reversals (% of comparable pairs)")
    ax.set_title("ranking reversals across population pairs (95% CI)")
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.0, 1.0))
    ax.grid(alpha=0.3, axis="y")


# ---------------------------------------------------------------------- the page
def render_html(card: Card, meta: dict[str, Any], png_name: str, svg: str | None) -> str:
    """The one-page card; every value is escaped except the replay SVG we drew."""
    env = Environment(autoescape=select_autoescape(default=True, default_for_string=True))
    env.filters["f"] = _fmt
    env.filters["pct"] = lambda v: "–" if _fmt(v) == "–" else f"{100 * v:.1f}%"
    pp = card.per_population.set_index(["population", "controller"])
    pops = list(card.gaps["population"])
    order = population_order(card.per_population["population"].unique())
    rows = [{"population": p, "gap": card.gaps.set_index("population").loc[p].to_dict(),
             "own": pp.loc[(p, card.controller)].to_dict() if (p, card.controller) in pp.index
             else {}} for p in order]
    return env.from_string(_PAGE).render(
        card=card, meta=meta, png=png_name, svg=Markup(svg) if svg else None,
        outcomes=card.outcomes.reset_index().to_dict("records"), rows=rows,
        worst=pops[:N_WORST], metrics=METRICS, labels=METRIC_LABELS, tol=TOLERANCES,
        ranks_metrics=VERDICT_METRICS,
        reversals=card.reversals.to_dict("records"), top=_most_reversed(card.reversals),
        errors=card.errors.head(10).to_dict("records"), verdict=card.verdict,
        ranks=_rank_rows(card, order), wins=_win_rows(card),
        sig=card.evidence.reversals.to_dict("records"), safety=safety_rows(card),
        testable=bool(card.evidence.reversals["orderings"].sum()),
        failed=card.verdict.label == "fails every run")


def safety_rows(card: Card) -> list[dict[str, Any]]:
    """Per failure kind and scope (all runs, then each scene where anyone failed): the
    controller's rate [95% CI], each baseline's, and the paired difference to the least
    safe baseline [95% CI]; scenes with no failure of that kind are left out."""
    rates, diffs = card.safety_rates, card.safety_differences
    rows = []
    for kind, label in FAILURES.items():
        for scope in rates.loc[rates["kind"] == kind, "scope"].unique():
            r = rates[(rates["kind"] == kind) & (rates["scope"] == scope)].set_index(
                "controller")
            if scope != "all" and r["failures"].sum() == 0:
                continue
            own = r.loc[card.controller]
            base = [b for b in card.baselines if b in r.index]
            worst = max(base, key=lambda b: r.loc[b, "rate"]) if base else None
            d = diffs[(diffs["kind"] == kind) & (diffs["scope"] == scope)
                      & (diffs["baseline"] == worst)] if worst else pd.DataFrame()
            rows.append({"kind": label, "scope": scope,
                         "own": f"{100 * own['rate']:.1f}% [{100 * own['low']:.1f}, "
                                f"{100 * own['high']:.1f}]",
                         "baselines": [f"{100 * r.loc[b, 'rate']:.1f}%" if b in r.index else "–"
                                       for b in card.baselines],
                         "diff": "–" if d.empty else
                         f"{100 * d['difference'].iloc[0]:+.1f} pp [{100 * d['low'].iloc[0]:+.1f},"
                         f" {100 * d['high'].iloc[0]:+.1f}] vs {worst}",
                         "bad": bool(not d.empty and d["low"].iloc[0] > 0)})
    return rows


def _rank_rows(card: Card, order: list[str]) -> list[dict[str, Any]]:
    """Per population: the controller's rank [interval] among all compared, per metric."""
    r = card.evidence.ranks
    own = r[r["controller"] == card.controller].set_index(["population", "metric"])
    n = r.groupby(["population", "metric"])["controller"].nunique()
    rows = []
    for p in order:
        cells = {}
        for m in VERDICT_METRICS:
            if (p, m) not in own.index:
                cells[m] = "–"
                continue
            x = own.loc[(p, m)]
            span = (str(x["rank"]) if x["rank_low"] == x["rank_high"]
                    else f"{x['rank']} [{x['rank_low']}–{x['rank_high']}]")
            cells[m] = f"{span} of {n[(p, m)]}"
        rows.append({"population": p, **cells})
    return rows


def _win_rows(card: Card) -> list[dict[str, Any]]:
    """Per (baseline, metric): cells significantly better / worse / tied, over populations."""
    w = card.evidence.wins.groupby(["baseline", "metric"], sort=False)[
        ["better", "worse", "tied"]].sum().reset_index()
    return w.to_dict("records")


def write_card(card: Card, meta: dict[str, Any], files: FileSet,
               svg: str | None) -> tuple[Path, Path]:
    """Stage ``card.png`` and ``card.html`` in ``files``; returns both final paths."""
    png = files.add("card.png", lambda tmp: tmp.write_bytes(png_bytes(card_figure(card))))
    return files.add_text("card.html", render_html(card, meta, png.name, svg)), png


def _most_reversed(reversals: pd.DataFrame) -> dict | None:
    """The (baseline, metric) row with the highest reversal rate, None if none is > 0."""
    rated = reversals[reversals["rate"] > 0]
    return None if rated.empty else rated.loc[rated["rate"].idxmax()].to_dict()


def _fmt(v: Any, digits: int = 2) -> str:
    if v is None or (isinstance(v, float) and not np.isfinite(v)):
        return "–"
    return f"{v:.{digits}f}" if isinstance(v, float | np.floating) else str(v)


_PAGE = """<!doctype html>
<html lang="en"><head><meta charset="utf-8"><title>Robustness card: {{ card.controller }}</title>
<style>body{font-family:sans-serif;margin:1.5em auto;max-width:1150px;font-size:14px}
table{border-collapse:collapse;margin:.4em 0}td,th{border:1px solid #ccc;padding:2px 7px}
td{text-align:right}td.l,th{text-align:left}.bad{color:#b00;font-weight:bold}
.warn{background:#fff3cd;border:1px solid #e0c36a;padding:.5em 1em}
.danger{background:#fde2e1;border:2px solid #b00;padding:.5em 1em;color:#600}
.verdict{border:2px solid #3b5b92;background:#f3f6fb;padding:.6em 1em;font-size:15px}
.verdict.unsafe,.verdict.fails-every-run{border-color:#b00;background:#fde2e1}
.verdict.inconclusive{border-color:#c90;background:#fff8e1}
.cols{display:flex;gap:2em;flex-wrap:wrap}h2{margin:.8em 0 .2em;font-size:1.15em}
.small{color:#555;font-size:12px}.replay{overflow-x:auto}
.replay svg{width:auto;height:auto;max-width:100%;max-height:560px}</style></head><body>
<h1>Population robustness card: <code>{{ card.controller }}</code></h1>
<p>Study <b>{{ meta.study }}</b>, part <b>{{ meta.part }}</b> ({{ meta.n_cells }} cells ×
{{ meta.n_populations }} populations, backend(s) {{ meta.backends }}, mapping(s)
{{ meta.mappings }}) against {{ card.baselines | join(", ") }}. Contract check:
{{ meta.check }}. The card uses {{ "{:,}".format(meta.get("n_used", meta.reused + meta.executed)) }}
runs of this part; this evaluation simulated {{ "{:,}".format(meta.executed) }} new ones.</p>
<div class="verdict {{ verdict.label | replace(' ', '-') }}"><b>Verdict: {{ verdict.label }}.</b>
{{ verdict.text }}</div>
{% if verdict.safety %}<p class="danger"><b>Safety:</b> {{ verdict.safety | length }}
failure kind{% if verdict.safety | length > 1 %}s{% endif %} above the baselines (table
below). Rankings of an unsafe controller are not evidence of robustness.</p>{% endif %}
<h2>Safety: each failure, against the baselines on the same runs</h2>
<table><tr><th>failure</th><th>scene</th><th>{{ card.controller }} [95% CI]</th>
{% for b in card.baselines %}<th>{{ b }}</th>{% endfor %}<th>difference to the least safe
baseline [95% CI]</th></tr>
{% for r in safety %}<tr><td class="l">{{ r.kind }}</td><td class="l">{{ r.scope }}</td>
<td{% if r.bad %} class="bad"{% endif %}>{{ r.own }}</td>
{% for b in r.baselines %}<td>{{ b }}</td>{% endfor %}
<td{% if r.bad %} class="bad"{% endif %}>{{ r.diff }}</td></tr>{% endfor %}</table>
<p class="small">Rates over the controller's runs (Clopper–Pearson intervals); the
difference is paired on the same episodes and populations, its interval from resampling
episodes. A pedestrian collision with the robot slower than 0.05 m/s at the contact is a
pedestrian walking into the standing robot, on its own line. Unsafe = significantly more
of a failure than the least safe baseline (timeouts and standing contacts excepted)
{%- if meta.get('safety_threshold') is not none %}, or above
{{ meta.safety_threshold | pct }} of its runs{% endif %}.</p>
{% if card.errors | length %}<p class="warn"><b>Controller errors:</b> the controller raised
in {{ meta.n_errors }} of its {{ meta.n_runs }} runs; they count as failures (robot time
45 s, no pedestrian delay). First message: <code>{{ card.errors.error.iloc[0] }}</code></p>
{% endif %}
{% if not failed %}<p>Where it does worst (lowest success, then largest mean-delay gap to the best
baseline): {% for p in worst %}<b>{{ p }}</b>{% if not loop.last %}, {% endif %}{% endfor %}.
{% if top %}Its ranking reverses most often against <b>{{ top.baseline }}</b> on
{{ labels[top.metric].split(" [")[0] }}: {{ top.rate | pct }} of comparable population
pairs (95% CI {{ top.ci_low | pct }}–{{ top.ci_high | pct }}).{% else %}Its ranking
against the baselines never reverses between two populations.{% endif %}</p>
<img src="{{ png }}" alt="per-population metrics and reversal rates" width="1100">{% endif %}
<div class="cols"><div>
<h2>Outcomes</h2><table><tr><th>controller</th><th>success %</th><th>ped. coll. %</th>
<th>world coll. %</th><th>timeout %</th><th>ctrl error %</th><th>robot time [s]</th>
<th>mean delay [s]</th><th>worst decile [s]</th><th>runs</th></tr>
{% for o in outcomes %}<tr><td class="l">{{ o.controller }}</td><td>{{ o.success_pct | f(1) }}</td>
<td>{{ o.pedestrian_collision_pct | f(1) }}</td><td>{{ o.world_collision_pct | f(1) }}</td>
<td>{{ o.timeout_pct | f(1) }}</td><td>{{ o.controller_error_pct | f(1) }}</td>
<td>{{ o.robot_time | f }}</td><td>{{ o.mean_delay | f }}</td><td>{{ o.worst_decile | f }}</td>
<td>{{ o.n_runs }}</td></tr>{% endfor %}</table></div><div>
<h2>Ranking reversals against each baseline</h2><table><tr><th>baseline</th><th>metric</th>
<th>reversals / comparable</th><th>rate</th><th>95% CI</th></tr>
{% for r in reversals %}<tr><td class="l">{{ r.baseline }}</td><td class="l">{{ r.metric }}</td>
<td>{{ r.reversals }} / {{ r.comparisons }}</td><td>{{ r.rate | pct }}</td>
<td>{% if r.comparisons %}{{ r.ci_low | pct }}–{{ r.ci_high | pct }}{% else %}–{% endif
%}</td></tr>{% endfor %}</table>
</div></div>
{% if failed %}<p class="warn">It reached the goal in none of its runs: no ranking, win or
reversal below says anything about it.</p>{% endif %}
{% if testable and not failed %}<h2>Rank per population (1 = best of
{{ card.baselines | length + 1 }}; [90% interval over episode resamples])</h2>
<table><tr><th>population</th>{% for m in ranks_metrics %}<th>{{ labels[m] }}</th>{% endfor %}</tr>
{% for r in ranks %}<tr><td class="l">{{ r.population }}</td>{% for m in ranks_metrics
%}<td>{{ r[m] }}</td>{% endfor %}</tr>{% endfor %}</table>
<div class="cols"><div>
<h2>Cells where it is significantly better / worse</h2><table><tr><th>baseline</th>
<th>metric</th><th>better</th><th>worse</th><th>tied</th></tr>
{% for w in wins %}<tr><td class="l">{{ w.baseline }}</td><td class="l">{{ w.metric }}</td>
<td>{{ w.better }}</td><td>{{ w.worse }}</td><td>{{ w.tied }}</td></tr>{% endfor %}</table>
</div><div>
<h2>Significant reversals (both orderings significant)</h2><table><tr><th>baseline</th>
<th>metric</th><th>significant</th><th>raw (incl. near-ties)</th></tr>
{% for r in sig %}<tr><td class="l">{{ r.baseline }}</td><td class="l">{{ r.metric }}</td>
<td>{{ r.sig_reversals }} / {{ r.sig_comparable }}</td>
<td>{{ r.raw_reversals }} / {{ r.raw_comparable }}</td></tr>{% endfor %}</table>
</div></div>{% elif not failed %}<p class="warn">Ranks with intervals, significant wins and
losses and significant reversals need at least 2 episodes per cell: this design has one, so
none is shown (the raw reversal counts above are descriptive).</p>{% endif %}
<h2>Per population (mean over cells; Δ = minus the best baseline, positive is
worse)</h2>
<table><tr><th>population</th><th>success %</th>{% for m in metrics %}<th>{{ labels[m] }}</th>
<th>Δ</th>{% endfor %}</tr>
{% for r in rows %}<tr><td class="l">{% if r.population in worst %}<span class="bad">{{
r.population }}</span>{% else %}{{ r.population }}{% endif %}</td>
<td>{{ r.own.success_pct | f(1) }}</td>{% for m in metrics %}<td>{{ r.own[m] | f }}</td>
<td>{{ r.gap[m] | f }}</td>{% endfor %}</tr>{% endfor %}</table>
{% if errors %}<h2>Controller errors (first {{ errors | length }})</h2><table>
<tr><th>episode</th><th>population</th><th>error</th></tr>{% for e in errors %}<tr>
<td class="l">{{ e.episode }}</td><td class="l">{{ e.population }}</td>
<td class="l"><code>{{ e.error }}</code></td></tr>{% endfor %}</table>{% endif %}
<h2>Worst run</h2>
{% if card.worst_run %}<p>{{ card.worst_run.episode }} · {{ card.worst_run.population }} ·
{{ card.worst_run.backend }} → {{ card.worst_run.outcome }} (robot time
{{ card.worst_run.robot_time | f(1) }} s, worst-decile delay
{{ card.worst_run.run_worst_decile | f }} s): {{ card.worst_run.why }}.
{{ meta.replay_note }}</p>{% if svg %}<div class="replay">{{ svg }}</div>{% endif %}
{% else %}<p>No replayable run (every run raised, or no pedestrian delay).</p>{% endif %}
<p class="small">Cells pool their variants; delay = pedestrian travel time minus the same
pedestrian's time without robot (arrived in both). A reversal is a comparable pair
(|Δ| above the tie tolerance, {% for m in metrics %}{{ tol[m] }} s for {{ labels[m].split(" [")[0]
}}{% if not loop.last %}, {% endif %}{% endfor %}, under both populations) whose sign flips;
rates pool every cell and population pair; intervals are percentile cluster-bootstrap
intervals over cells ({{ meta.n_boot }} resamples, seed {{ meta.seed }}). Tables:
runs.parquet and pedestrians.parquet beside this page (the controller's runs);
the baselines are in {{ meta.base_folder }}.</p>
</body></html>
"""
