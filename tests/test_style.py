"""One colour and marker per controller: the same on two cards, on the compare page and in
the report's figures, and the same in every process for a name nobody declared."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pandas as pd
import pytest
from matplotlib.colors import to_hex

from popnavshift.evaluate.card import card_tables
from popnavshift.evaluate.card_page import card_figure
from popnavshift.evaluate.compare import Comparison, compare_table
from popnavshift.evaluate.compare_page import compare_figure
from popnavshift.evaluate.robustness import robustness_tables
from popnavshift.report.figures import plot_tradeoff
from popnavshift.viz.style import FIXED, controller_style, controller_styles
from synth_study import no_effect, synthetic_study


def _drawn(fig) -> dict[str, tuple[str, str]]:
    """label → (face colour, marker path) of the first panel's scatter series."""
    out = {}
    for coll in fig.axes[0].collections:
        label = coll.get_label()
        if not label.startswith("_"):
            marker = coll.get_paths()[0].vertices.round(3).tobytes().hex()
            out[label] = (to_hex(coll.get_facecolor()[0]), marker)
    return out


def test_the_paper_controllers_have_fixed_styles_and_others_a_stable_hash():
    assert controller_style("robot_orca") == FIXED["robot_orca"]
    mine = controller_style("my_pkg.ctrl:Mine")
    code = ("from popnavshift.viz.style import controller_style; "
            "print(tuple(controller_style('my_pkg.ctrl:Mine')))")
    other = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                           check=True).stdout.strip()
    assert other == str(tuple(mine))  # not Python's salted hash()
    fixed = {s.colour for s in FIXED.values()}
    names = [f"ctrl{i}" for i in range(40)]
    assert not {controller_style(n).colour for n in names} & fixed
    assert len({controller_style(n) for n in names}) > 10  # spread over the palette


@pytest.fixture(scope="module")
def synthetic():
    return synthetic_study({"p1": no_effect, "p2": no_effect}, n_cells=4, variants=2,
                           controllers=("reactive", "HRVO", "my_pkg:Mine"))


def _card(runs, peds, controller, baselines, rng):
    rob = robustness_tables(runs, peds, controller, baselines, {}, ["p1", "p2"], n_boot=10)
    return card_tables(runs, peds, controller, baselines, rob, rng=rng, n_boot=20)


def test_a_controller_looks_the_same_on_two_cards_and_on_the_compare_page(synthetic):
    runs, peds = synthetic
    rng = np.random.default_rng(0)
    first = card_figure(_card(runs, peds, "HRVO", ("reactive", "my_pkg:Mine"), rng))
    second = card_figure(_card(runs, peds, "my_pkg:Mine", ("HRVO", "reactive"), rng))
    a, b = _drawn(first), _drawn(second)
    assert set(a) == set(b) == {"reactive", "HRVO", "my_pkg:Mine"}
    assert a == b  # evaluated on one card, a baseline on the other: same colour, same marker
    styles = controller_styles(["reactive", "HRVO", "my_pkg:Mine"])
    assert a["HRVO"][0] == styles["HRVO"].colour != a["my_pkg:Mine"][0]
    verdicts = {c: {"robustness": {"label": "undecided", "text": "", "decide": "", "row": {}},
                    "safety": {"label": "safe", "text": "", "findings": [], "threshold": 0.01}}
                for c in a}
    table, per_pop = compare_table(runs, peds, ["my_pkg:Mine", "HRVO", "reactive"], verdicts)
    page = compare_figure(Comparison(("my_pkg:Mine", "HRVO", "reactive"), table, per_pop, {},
                                     verdicts, None, None))  # type: ignore[arg-type]
    assert _drawn(page) == a


def test_every_row_of_a_leaderboard_has_its_own_colour_and_marker():
    """navground's behaviours beside the paper's three: no two share a colour or a marker
    (ORCA and SocialForce drew the same pair by hash alone), whatever their order."""
    names = ["reactive", "early_yield", "robot_orca", "Dummy", "HRVO", "ORCA", "HL",
             "SocialForce", "examples.go_to_goal:GoToGoal", "my_pkg:Mine"]
    styles = controller_styles(names)
    assert len({s.colour for s in styles.values()}) == len(names)
    assert len({s.marker for s in styles.values()}) == len(names)
    assert controller_styles(names[::-1]) == styles
    assert styles["robot_orca"] == FIXED["robot_orca"]


def test_the_report_figures_use_the_same_colours():
    rows = [{"population": "mixed", "controller": c, "robot_time": 20.0 + i, "mean_delay": 1.0,
             "worst_decile": 2.0} for i, c in enumerate(("reactive", "robot_orca", "HRVO"))]
    drawn = _drawn(plot_tradeoff(pd.DataFrame(rows)))
    assert drawn["Robot-ORCA"][0] == controller_style("robot_orca").colour
    assert drawn["HRVO"][0] == controller_style("HRVO").colour
