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
from ..analysis.recombine import PREDICTION, RECOMBINED
from ..controller_ids import display_name
from ..outputs import FileSet
from ..populations.build import population_order
from ..viz.style import controller_styles
from .card import METRIC_LABELS, N_WORST, Card
from .safety import FAILURES, UNSAFE_KINDS
from .verdict import FAILS, VERDICT_METRICS


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
    # the controllers' legend below the panels: inside one it can hide a point
    handles, labels = axes.flat[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside lower center", ncol=len(labels), fontsize=9)
    _null_panel(axes.flat[3], card)
    fig.suptitle(f"Population robustness of {display_name(card.controller)}",
                 fontsize=13)
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
    per controller in its own style (:func:`controller_styles`: no two alike);
    ``highlight`` drawn larger with a black edge. ``per_population``: rows (population,
    controller) with ``metric``."""
    pops = population_order(per_population["population"].unique())
    x = np.arange(len(pops))
    styles = controller_styles(controllers)
    step = min(0.15, 0.8 / max(1, len(controllers)))  # a population's markers stay apart
    for i, ctrl in enumerate(controllers):
        s = per_population[per_population["controller"] == ctrl].set_index("population")
        look, mine = styles[ctrl], ctrl == highlight
        ax.scatter(x + (i - (len(controllers) - 1) / 2) * step,
                   s[metric].reindex(pops).to_numpy(float), marker=look.marker,
                   s=60 if mine else 28, color=look.colour, label=display_name(ctrl),
                   zorder=3 if mine else 2,
                   edgecolors="black" if mine else "none", linewidths=1.2)
    ax.set_title(METRIC_LABELS[metric])
    ax.set_xticks(x, pops, rotation=30, ha="right", fontsize=8)
    ax.grid(alpha=0.3)


def _null_panel(ax, card: Card) -> None:
    """Each design's observed reversal rate of the controller's orderings (raw rule) beside
    its null replicates' rates, per metric: the raw rate is never shown without its null."""
    rob = card.robustness
    head = rob.headline[rob.headline["rule"] == "raw"] if len(rob.headline) else rob.headline
    if head.empty:
        ax.text(0.5, 0.5, "no null design to set the rates beside", ha="center",
                va="center", transform=ax.transAxes)
        ax.set_axis_off()
        return
    nulls = rob.null_rates[rob.null_rates["rule"] == "raw"]
    designs = list(dict.fromkeys(head["design"]))
    metrics = list(dict.fromkeys(head["metric"]))
    width = 0.8 / len(designs)
    shapes = dict(zip(designs, ("D", "s", "^", "o"), strict=False))
    for i, design in enumerate(designs):
        for j, metric in enumerate(metrics):
            x = j + (i - (len(designs) - 1) / 2) * width
            reps = nulls[(nulls["comparison"] == design) & (nulls["metric"] == metric)]["rate"]
            ax.scatter(np.full(len(reps), x), 100 * reps.to_numpy(float), s=10, color="#999",
                       label="null replicates" if i == j == 0 else None, zorder=2)
            row = head[(head["design"] == design) & (head["metric"] == metric)]
            if len(row):
                above = row["verdict"].iloc[0] == "above the null"
                ax.scatter([x], [100 * float(row["observed"].iloc[0])], s=60,
                           marker=shapes.get(design, "o"), color="#b00" if above else "#3b5b92",
                           label=f"observed: {design.replace('_', ' ')}" if j == 0 else None,
                           zorder=3)
    ax.set_xticks(np.arange(len(metrics)), [METRIC_LABELS.get(m, m).split(" [")[0]
                                             for m in metrics], fontsize=8)
    ax.set_ylabel("reversals (% of comparable pairs)")
    ax.set_title("its orderings' reversal rate vs its own null replicates (raw rule)")
    ax.legend(fontsize=8)
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
        ranks_metrics=VERDICT_METRICS, robustness=_robustness_rows(card),
        by_baseline=_robustness_rows(card, by_baseline=True),
        calibration=_calibration_line(card),
        errors=card.errors.head(10).to_dict("records"), verdict=card.verdict,
        ranks=_rank_rows(card, order), wins=_win_rows(card), safety=safety_rows(card),
        testable=bool(card.evidence.crossovers["p"].notna().any())
        if len(card.evidence.crossovers) else False,
        failed=card.verdict.robustness == FAILS)


def _robustness_rows(card: Card, by_baseline: bool = False) -> list[dict[str, Any]]:
    """The robustness table's raw-rule rows as text: observed and null rates [%], the
    excess [pp] with its simultaneous interval, its test's p (the prediction t, or the
    randomization test over recombined designs) with the adjusted p, the
    exact permutation p, and the verdict."""
    rob = card.robustness
    table = rob.by_baseline if by_baseline else rob.headline
    if table is None or table.empty:
        return []
    rows = []
    for r in table[table["rule"] == "raw"].itertuples():
        rows.append({"design": str(r.design).replace("_", " "), "baseline": r.baseline,
                     "metric": METRIC_LABELS.get(r.metric, r.metric).split(" [")[0],
                     "observed": f"{100 * r.observed:.1f}%",
                     "null": f"{100 * r.null_mean:.1f}% ({int(r.n_null)} replicates, "
                             f"{int(r.seed_sets)} seed set{'s' if r.seed_sets != 1 else ''})",
                     "excess": f"{100 * r.excess:+.1f} pp [{100 * r.ci_low:+.1f}, "
                               f"{100 * r.ci_high:+.1f}]",
                     "t": (f"randomization p {_fmt(r.p_t, 4)} (t {r.t:.2f}, not used), "
                           f"p adj. {_fmt(r.p_adj, 3)}" if getattr(r, "test", "") == RECOMBINED
                           else f"{r.t:.2f} ({int(r.df)} df), p adj. {_fmt(r.p_adj, 3)}"),
                     "exact": _fmt(r.p_value, 3), "verdict": r.verdict,
                     "above": r.verdict == "above the null"})
    return rows


def _calibration_line(card: Card) -> str:
    """The card's own placebos: how often the raw rule's test (the prediction t; across the
    population pairs the randomization test over recombined designs) claimed an effect
    where none is."""
    cal = card.robustness.calibration
    if cal is None or cal.empty:
        return ""
    rows = cal[(cal["comparison"] == "all") & cal["test"].isin([PREDICTION, RECOMBINED])
               & (cal["kind"] == "false positive")]
    parts = [f"{r.test}, {r.claim}: {r.claims}/{r.placebos} ({100 * r.rate:.1f}% "
             f"[{100 * r.cp_low:.1f}, {100 * r.cp_high:.1f}], nominal {100 * r.nominal:g}%)"
             for r in rows.itertuples() if r.placebos]
    return "; ".join(parts)


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
            counted = kind in UNSAFE_KINDS
            rows.append({"kind": label + ("" if counted else " (reported, not counted)"),
                         "scope": scope,
                         "own": f"{100 * own['rate']:.1f}% [{100 * own['low']:.1f}, "
                                f"{100 * own['high']:.1f}]",
                         "baselines": [f"{100 * r.loc[b, 'rate']:.1f}%" if b in r.index else "–"
                                       for b in card.baselines],
                         "diff": "–" if d.empty else
                         f"{100 * d['difference'].iloc[0]:+.1f} pp [{100 * d['low'].iloc[0]:+.1f},"
                         f" {100 * d['high'].iloc[0]:+.1f}] vs {worst}",
                         "bad": counted and scope == "all"
                         and own["low"] > card.verdict.safety.threshold})
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
.verdicts{display:flex;gap:1em;flex-wrap:wrap}.verdicts>div{flex:1 1 420px}
.verdict{border:2px solid #3b5b92;background:#f3f6fb;padding:.6em 1em;font-size:15px}
.verdict.population-sensitive,.verdict.unsafe,.verdict.fails-every-run{border-color:#b00;
background:#fde2e1}
.verdict.undecided{border-color:#c90;background:#fff8e1}
.verdict.robust,.verdict.safe{border-color:#2a7a2a;background:#e8f5e8}
.cols{display:flex;gap:2em;flex-wrap:wrap}h2{margin:.8em 0 .2em;font-size:1.15em}
.small{color:#555;font-size:12px}.replay{overflow-x:auto}.wrap{overflow-x:auto}
.replay svg{width:auto;height:auto;max-width:100%;max-height:560px}</style></head><body>
<h1>Population robustness card: <code>{{ card.controller }}</code></h1>
<p>Study <b>{{ meta.study }}</b>: main part <b>{{ meta.part }}</b> ({{ meta.n_cells }} cells ×
{{ meta.n_populations }} populations, backend(s) {{ meta.backends }}, mapping(s)
{{ meta.mappings }}), robustness decided on {{ meta.parts }}
({{ "{:,}".format(meta.n_every) }} runs), against {{ card.baselines | join(", ") }}.
Contract check: {{ meta.check }}. This evaluation simulated {{ "{:,}".format(meta.executed) }}
new runs. PopNavShift {{ meta.version }}, study configuration {{ meta.config_hash }},
made {{ meta.made }}.</p>
<div class="verdicts"><div class="verdict {{ verdict.robustness | replace(' ', '-') }}">
<b>Robustness: {{ verdict.robustness }}.</b> {{ verdict.robustness_text }}
{% if verdict.decide %}<br><b>What would decide it:</b> {{ verdict.decide }}{% endif %}
{% if verdict.interaction %}<br><b>Its differences from the baselines:</b>
{{ verdict.interaction }}{% endif %}</div>
<div class="verdict {{ verdict.safety.label }}"><b>Safety: {{ verdict.safety.label }}.</b>
{{ verdict.safety.text }}</div></div>
<h2>Robustness: how often its orderings reverse with the population, beside its own null</h2>
{% if robustness %}<div class="wrap"><table><tr><th>design</th><th>metric</th>
<th>observed rate</th><th>null rate (mean)</th><th>excess [simultaneous 95% CI]</th>
<th>its test</th><th>exact p vs replicates</th><th>verdict</th></tr>
{% for r in robustness %}<tr><td class="l">{{ r.design }}</td><td class="l">{{ r.metric }}</td>
<td>{{ r.observed }}</td><td>{{ r.null }}</td><td{% if r.above %} class="bad"{% endif %}>{{
r.excess }}</td><td>{{ r.t }}</td><td>{{ r.exact }}</td><td class="l">{{ r.verdict }}</td></tr>
{% endfor %}</table></div>
<p class="small">A rate pools its orderings against every baseline over the cells and the
design's population pairs (the matched pair against swap permutations of its personas'
profiles; the population pairs against size-matched subsets of mixed), on the same
episodes; each null replicate is the same rate with the population label carrying no
information. The verdict rests on the spread between replicates (a prediction t; across
the population pairs, whose null is drawn population by population, the exact randomization
test over designs recombined from the replicates; decided at α/m over the table's m rates;
the exact permutation p beside it). "no excess ≥ 5 pp"
is a robust finding; "undecided" claims nothing.{% if calibration %} On this card's own
placebos (a null replicate taken as the observed): {{ calibration }}.{% endif %}</p>
{% if by_baseline %}<details><summary>Against each baseline alone (decided over its own
table)</summary><table><tr><th>design</th><th>baseline</th><th>metric</th><th>observed</th>
<th>null (mean)</th><th>excess [95% CI]</th><th>verdict</th></tr>
{% for r in by_baseline %}<tr><td class="l">{{ r.design }}</td><td class="l">{{ r.baseline }}</td>
<td class="l">{{ r.metric }}</td><td>{{ r.observed }}</td><td>{{ r.null }}</td>
<td{% if r.above %} class="bad"{% endif %}>{{ r.excess }}</td><td class="l">{{ r.verdict }}</td>
</tr>{% endfor %}</table></details>{% endif %}
{% else %}<p class="warn">No null design to decide against: {{ card.robustness.text }}</p>
{% endif %}
<h2>Safety: each failure, the same rule for every controller</h2>
<table><tr><th>failure</th><th>scene</th><th>{{ card.controller }} [95% CI]</th>
{% for b in card.baselines %}<th>{{ b }}</th>{% endfor %}<th>difference to the least safe
baseline, same runs [95% CI]</th></tr>
{% for r in safety %}<tr><td class="l">{{ r.kind }}</td><td class="l">{{ r.scope }}</td>
<td{% if r.bad %} class="bad"{% endif %}>{{ r.own }}</td>
{% for b in r.baselines %}<td>{{ b }}</td>{% endfor %}
<td>{{ r.diff }}</td></tr>{% endfor %}</table>
<p class="small">Rates over the controller's runs on the main part (Clopper–Pearson
intervals). Unsafe: a counted failure (pedestrian collisions with the robot moving, wall and
obstacle contacts, controller errors) above {{ verdict.safety.threshold | pct }} of its runs
with 95% confidence; safe: every one below it. A pedestrian collision with the robot slower
than 0.05 m/s at the contact is a pedestrian walking into the standing robot, on its own
line; it and timeouts are reported, not counted. The paired difference to the least safe
baseline is context, not the rule.</p>
{% if card.errors | length %}<p class="warn"><b>Controller errors:</b> the controller raised
in {{ meta.n_errors }} of its {{ meta.n_runs }} runs; they count as failures (robot time
45 s, no pedestrian delay). First message: <code>{{ card.errors.error.iloc[0] }}</code></p>
{% endif %}
{% if not failed %}<p>Where it does worst (lowest success, then largest mean-delay gap to the best
baseline): {% for p in worst %}<b>{{ p }}</b>{% if not loop.last %}, {% endif %}{% endfor %}.</p>
<img src="{{ png }}" alt="per-population metrics, and reversal rates beside their null"
style="max-width:100%">{% endif %}
<h2>Outcomes (main part)</h2><div class="wrap"><table><tr><th>controller</th><th>success %</th>
<th>ped. coll. % (robot moving)</th><th>standing contacts %</th><th>world coll. %</th>
<th>timeout %</th><th>ctrl error %</th><th>robot time [s]</th><th>mean delay [s]</th>
<th>worst decile [s]</th><th>blocked %</th><th>min. clearance [m]</th><th>path [m]</th>
<th>stop time [s]</th><th>runs</th></tr>
{% for o in outcomes %}<tr><td class="l">{{ o.controller }}</td><td>{{ o.success_pct | f(1) }}</td>
<td>{{ o.pedestrian_collision_pct | f(1) }}</td><td>{{ o.standing_contact_pct | f(1) }}</td>
<td>{{ o.world_collision_pct | f(1) }}</td><td>{{ o.timeout_pct | f(1) }}</td>
<td>{{ o.controller_error_pct | f(1) }}</td><td>{{ o.robot_time | f }}</td>
<td>{{ o.mean_delay | f }}</td><td>{{ o.worst_decile | f }}</td><td>{{ o.blocked_pct | f }}</td>
<td>{{ o.min_clearance | f }}</td>
<td>{{ o.path_length | f(1) }}</td><td>{{ o.stop_time | f(1) }}</td><td>{{ o.n_runs }}</td></tr>
{% endfor %}</table></div>
{% if failed %}<p class="warn">It reached the goal in none of its runs: no ranking or win
below says anything about it.</p>{% endif %}
{% if testable and not failed %}<h2>Rank per population (1 = best of
{{ card.baselines | length + 1 }}; [90% interval over episode resamples])</h2>
<table><tr><th>population</th>{% for m in ranks_metrics %}<th>{{ labels[m] }}</th>{% endfor %}</tr>
{% for r in ranks %}<tr><td class="l">{{ r.population }}</td>{% for m in ranks_metrics
%}<td>{{ r[m] }}</td>{% endfor %}</tr>{% endfor %}</table>
<h2>Cells where it is significantly better / worse</h2><table><tr><th>baseline</th>
<th>metric</th><th>better</th><th>worse</th><th>tied</th></tr>
{% for w in wins %}<tr><td class="l">{{ w.baseline }}</td><td class="l">{{ w.metric }}</td>
<td>{{ w.better }}</td><td>{{ w.worse }}</td><td>{{ w.tied }}</td></tr>{% endfor %}</table>
{% elif not failed %}<p class="warn">Ranks with intervals and significant wins and losses
need at least 2 episodes per cell: this design has one, so none is shown.</p>{% endif %}
<h2>Per population (mean over cells; Δ = minus the best baseline, positive is
worse)</h2>
<table><tr><th>population</th><th>success %</th>{% for m in metrics %}<th>{{ labels[m] }}</th>
<th>Δ</th>{% endfor %}</tr>
{% for r in rows %}<tr><td class="l">{% if r.population in worst %}<b>{{
r.population }}</b>{% else %}{{ r.population }}{% endif %}</td>
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
}}{% if not loop.last %}, {% endif %}{% endfor %}, under both populations) whose sign flips.
Bootstrap: {{ meta.n_boot }} episode resamples, seed {{ meta.seed }}. Tables:
runs.parquet and pedestrians.parquet beside this page (the controller's runs) and a CSV of
every table; the baselines are in {{ meta.base_folder }}.</p>
</body></html>
"""
