"""Replays: a run rendered as SVG, HTML and GIF that show the scene."""

import pytest
from PIL import Image

from popnavshift.episodes.specs import get_episode
from popnavshift.sim.run import simulate
from popnavshift.viz.replay import STATE_COLOURS, write_replay


@pytest.fixture(scope="module")
def run():
    spec = get_episode("sidewalk-w1.8-d0.12-s1.0-v1")
    return simulate(spec, None, "robot_orca", "orca", record=True)


def test_svg_and_page_show_walls_agents_and_the_robot(tmp_path, run):
    page, svg = write_replay(run.trajectory, run.run, tmp_path / "r.html", "a <b>run</b>")
    text = svg.read_text()
    n_walls = len(run.trajectory["walls"])
    assert text.count('stroke="#333" stroke-width="3"') == n_walls
    assert text.count("<circle") >= run.run["n_peds"] + 2  # pedestrians, robot, goal ring
    assert 'attributeName="cx"' in text and "polyline" in text
    assert ">0 s</text>" in text and ">5 s</text>" in text  # the clock under the scene
    html = page.read_text()
    assert "a &lt;b&gt;run&lt;/b&gt;" in html and "<b>run</b>" not in html  # escaped
    for colour in STATE_COLOURS.values():
        assert colour in html
    assert run.run["outcome"] in html
    # play/pause, a time slider and a clock driving the SVG's own animation
    assert 'id="play"' in html and 'id="scrub"' in html and "setCurrentTime" in html


def test_a_collision_is_marked_where_and_when_it_happened(tmp_path):
    spec = get_episode("head_on-w1.8-d0.06-s1.0-v1")
    hit = simulate(spec, None, "Dummy", "orca", record=True)
    assert hit.run["outcome"] == "pedestrian_collision"
    (svg,) = write_replay(hit.trajectory, hit.run, tmp_path / "hit.svg", "Dummy")
    text = svg.read_text()
    assert f"pedestrian collision at {hit.run['outcome_time']:.1f} s" in text
    assert 'stroke="#d62728"' in text


def test_gif_has_frames(tmp_path, run):
    (gif,) = write_replay(run.trajectory, run.run, tmp_path / "r.gif", "run")
    with Image.open(gif) as im:
        assert im.n_frames > 20 and im.size[0] > 200


def test_unknown_suffix_is_a_clear_error(tmp_path, run):
    from popnavshift.errors import ConfigError

    with pytest.raises(ConfigError, match=r"\.svg, \.gif or \.html"):
        write_replay(run.trajectory, run.run, tmp_path / "r.mp4", "run")
