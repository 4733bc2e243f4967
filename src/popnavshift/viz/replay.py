"""Render one run as an animated SVG, a GIF, and an HTML page around the SVG.

Input is the trajectory dict of :meth:`popnavshift.sim.run.SimResult.trajectory`
(poses per step, pedestrian state flags, walls, obstacles). Pedestrians are
coloured by state (walking, reacting, yielding, detouring) or by a profile
parameter; the robot is drawn with its path and goal. The SVG animates with SMIL
(no JavaScript), so it plays in any browser and in the HTML report; the HTML page adds
play/pause, a time slider and a clock (a few lines of script driving the SVG's own
animation clock).
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import matplotlib
import numpy as np
from jinja2 import Environment, select_autoescape
from markupsafe import escape

from ..errors import ConfigError
from ..io import write_atomic, write_text

STATE_COLOURS = {
    "walking": "#4C72B0",
    "reacting": "#DD8452",
    "yielding": "#C44E52",
    "detouring": "#8172B3",
}
ROBOT_COLOUR = "#2ca02c"
SCALE = 40.0  # SVG pixels per metre


def _state_names(flags: np.ndarray, bits: Mapping[str, int]) -> np.ndarray:
    """Per step and pedestrian, the most specific state name (detouring > yielding > reacting)."""
    names = np.full(flags.shape, "walking", dtype=object)
    for state in ("reacting", "yielding", "detouring"):
        names[(flags & bits[state]) != 0] = state
    return names


def _bounds(traj: Mapping[str, Any]) -> tuple[float, float, float, float]:
    pts = [traj["walls"][:, :2], traj["walls"][:, 2:]]
    for key in ("ped_pose", "robot_pose"):
        arr = traj.get(key)
        if arr is not None:
            xy = arr[..., :2].reshape(-1, 2)
            pts.append(xy[np.isfinite(xy).all(axis=1)])
    allp = np.concatenate([p for p in pts if len(p)])
    lo, hi = allp.min(axis=0) - 1.0, allp.max(axis=0) + 1.0
    return float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1])


def _fmt(values) -> str:
    return ";".join(f"{v:.2f}" for v in values)


COLLISION_COLOUR = "#d62728"
COLLISIONS = {"pedestrian_collision": "pedestrian collision",
              "world_collision": "wall or obstacle contact"}


def render_svg(
    traj: Mapping[str, Any],
    title: str = "",
    stride: int = 2,
    colour_by: str = "state",
    profiles: np.ndarray | None = None,
    outcome: tuple[str, float] | None = None,
) -> str:
    """An animated SVG (SMIL) of the run; ``stride`` subsamples steps (0.1 s each).

    Under the scene a bar advances with the run's time over a scale in seconds; with
    ``outcome`` (the run's outcome and its time [s]) a collision is marked where the robot
    was, from the moment it happened."""
    x0, y0, x1, y1 = _bounds(traj)
    width, height = (x1 - x0) * SCALE, (y1 - y0) * SCALE

    def X(x):
        return (np.asarray(x) - x0) * SCALE

    def Y(y):  # SVG y grows downward
        return (y1 - np.asarray(y)) * SCALE

    steps = np.arange(0, len(traj["time"]), stride)
    dur = f"{traj['time'][steps[-1]] + 0.1 * stride:.1f}s"
    parts = [
        f'<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 {width:.0f} {height + 40:.0f}" '
        f'width="100%" style="max-width:{width:.0f}px;height:auto" font-family="sans-serif">',
        '<rect width="100%" height="100%" fill="#fafafa"/>',
    ]
    for wx0, wy0, wx1, wy1 in traj["walls"]:
        parts.append(
            f'<line x1="{X(wx0):.1f}" y1="{Y(wy0):.1f}" x2="{X(wx1):.1f}" '
            f'y2="{Y(wy1):.1f}" stroke="#333" stroke-width="3"/>'
        )
    for ox, oy, r in traj["obstacles"]:
        parts.append(f'<circle cx="{X(ox):.1f}" cy="{Y(oy):.1f}" r="{r * SCALE:.1f}" fill="#999"/>')
    robot = traj.get("robot_pose")
    if robot is not None:
        ok = np.isfinite(robot[:, 0])
        pts = " ".join(
            f"{a:.1f},{b:.1f}" for a, b in zip(X(robot[ok, 0]), Y(robot[ok, 1]), strict=True)
        )
        gx, gy = traj["robot_goal"]
        parts.append(
            f'<polyline points="{pts}" fill="none" stroke="{ROBOT_COLOUR}" '
            'stroke-opacity="0.35" stroke-width="2"/>'
        )
        parts.append(
            f'<circle cx="{X(gx):.1f}" cy="{Y(gy):.1f}" r="6" fill="none" '
            f'stroke="{ROBOT_COLOUR}" stroke-width="2"/>'
        )
    states = _state_names(traj["ped_flags"], traj["flag_bits"])
    peds = traj["ped_pose"]
    for k in range(peds.shape[1]):
        if colour_by == "state" or profiles is None:
            parts.append(
                _agent(
                    peds[steps, k],
                    X,
                    Y,
                    traj["ped_radius"],
                    dur,
                    fills=[STATE_COLOURS[s] for s in states[steps, k]],
                )
            )
        else:  # a profile value in [0, 1] per pedestrian (e.g. z_speed)
            colour = _hex(matplotlib.colormaps["viridis"](float(profiles[k])))
            parts.append(_agent(peds[steps, k], X, Y, traj["ped_radius"], dur, fill=colour))
    if robot is not None:
        parts.append(_agent(robot[steps], X, Y, traj["robot_radius"], dur, fill=ROBOT_COLOUR))
    if outcome is not None and outcome[0] in COLLISIONS and robot is not None:
        parts.append(_collision_marker(robot, outcome, X, Y, traj["robot_radius"], dur))
    parts.append(
        f'<rect x="0" y="{height + 18:.0f}" height="6" width="0" fill="#555">'
        f'<animate attributeName="width" from="0" to="{width:.0f}" dur="{dur}" '
        'repeatCount="indefinite"/></rect>'
    )
    parts += _time_scale(float(dur[:-1]), width, height + 24)
    if title:
        parts.append(f'<text x="6" y="{height + 13:.0f}" font-size="12">{_esc(title)}</text>')
    parts.append("</svg>")
    return "\n".join(parts)


def _time_scale(seconds: float, width: float, y: float) -> list[str]:
    """Ticks every 5 s under the progress bar, labelled in seconds (the run's clock)."""
    out = []
    for t in np.arange(0.0, seconds + 1e-9, 5.0):
        x = width * t / seconds
        anchor = "start" if t == 0 else "end" if t + 5 > seconds else "middle"
        out.append(f'<line x1="{x:.1f}" y1="{y:.0f}" x2="{x:.1f}" y2="{y + 4:.0f}" '
                   'stroke="#555"/>')
        out.append(f'<text x="{x:.1f}" y="{y + 14:.0f}" font-size="10" text-anchor="{anchor}" '
                   f'fill="#555">{t:.0f} s</text>')
    return out


def _collision_marker(robot: np.ndarray, outcome: tuple[str, float], X, Y, radius: float,
                      dur: str) -> str:
    """A red ring and label where the robot was at its collision, shown from that time on
    (in step with the looping animation)."""
    kind, when = outcome
    step = min(int(round(when / 0.1)), len(robot) - 1)
    ok = np.flatnonzero(np.isfinite(robot[: step + 1, 0]))
    if not ok.size:
        return ""
    x, y = robot[ok[-1], 0], robot[ok[-1], 1]
    frac = min(max(when / float(dur[:-1]), 0.0), 1.0)
    show = (f'<animate attributeName="opacity" values="0;0;1;1" keyTimes="0;{frac:.4f};'
            f'{frac:.4f};1" dur="{dur}" repeatCount="indefinite"/>')
    return (f'<g opacity="0"><circle cx="{X(x):.1f}" cy="{Y(y):.1f}" '
            f'r="{(radius * 1.8) * SCALE:.1f}" fill="none" stroke="{COLLISION_COLOUR}" '
            f'stroke-width="3"/><text x="{X(x):.1f}" y="{Y(y) - radius * 2 * SCALE:.1f}" '
            f'font-size="12" text-anchor="middle" fill="{COLLISION_COLOUR}">'
            f'{COLLISIONS[kind]} at {when:.1f} s</text>{show}</g>')


def _hex(rgba) -> str:
    return "#" + "".join(f"{int(round(255 * c)):02x}" for c in rgba[:3])


def _esc(text: str) -> str:
    return str(escape(text))


def _agent(
    pose: np.ndarray,
    X,
    Y,
    radius: float,
    dur: str,
    fill: str | None = None,
    fills: list[str] | None = None,
) -> str:
    visible = np.isfinite(pose[:, 0])
    xs = np.where(visible, X(np.nan_to_num(pose[:, 0])), -1000.0)
    ys = np.where(visible, Y(np.nan_to_num(pose[:, 1])), -1000.0)
    anim = (
        f'<animate attributeName="cx" values="{_fmt(xs)}" dur="{dur}" '
        'repeatCount="indefinite" calcMode="discrete"/>'
        f'<animate attributeName="cy" values="{_fmt(ys)}" dur="{dur}" '
        'repeatCount="indefinite" calcMode="discrete"/>'
    )
    if fills is not None:
        anim += (
            f'<animate attributeName="fill" values="{";".join(fills)}" dur="{dur}" '
            'repeatCount="indefinite" calcMode="discrete"/>'
        )
    colour = fill or (fills[0] if fills else "#4C72B0")
    return (
        f'<circle cx="{xs[0]:.1f}" cy="{ys[0]:.1f}" r="{radius * SCALE:.1f}" '
        f'fill="{colour}" fill-opacity="0.85" stroke="#222" stroke-width="1">{anim}</circle>'
    )


def render_gif(traj: Mapping[str, Any], path: Path, title: str = "", stride: int = 2) -> Path:
    """An animated GIF via matplotlib + Pillow (written atomically)."""
    matplotlib.use("Agg")  # before pyplot is imported: no display here
    matplotlib.rcParams["text.parse_math"] = False  # a label is data: "$" is no math
    import matplotlib.pyplot as plt
    from matplotlib.patches import Circle

    x0, y0, x1, y1 = _bounds(traj)
    fig, ax = plt.subplots(figsize=(min(12, (x1 - x0) / 2.5) + 2.2,
                                    min(8, (y1 - y0) / 2.5 + 0.6) + 0.4))
    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)
    ax.set_aspect("equal")
    for wx0, wy0, wx1, wy1 in traj["walls"]:
        ax.plot([wx0, wx1], [wy0, wy1], color="#333", lw=2)
    for ox, oy, r in traj["obstacles"]:
        ax.add_patch(Circle((ox, oy), r, color="#999"))
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    handles = [Circle((0, 0), 1, color=c, label=name) for name, c in STATE_COLOURS.items()]
    handles.append(Circle((0, 0), 1, color=ROBOT_COLOUR, label="robot"))
    ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.0, 1.0), fontsize=8,
              title="pedestrians by state", title_fontsize=8)
    states = _state_names(traj["ped_flags"], traj["flag_bits"])
    peds = traj["ped_pose"]
    robot = traj.get("robot_pose")
    circles = [
        ax.add_patch(Circle((0, 0), traj["ped_radius"], ec="#222")) for _ in range(peds.shape[1])
    ]
    rc = (
        ax.add_patch(Circle((0, 0), traj["robot_radius"], color=ROBOT_COLOUR))
        if robot is not None
        else None
    )
    label = ax.set_title(title)
    fig.tight_layout()
    steps = np.arange(0, len(traj["time"]), stride)

    def draw(i):
        s = steps[i]
        for k, c in enumerate(circles):
            ok = np.isfinite(peds[s, k, 0])
            c.set_visible(bool(ok))
            if ok:
                c.center = (peds[s, k, 0], peds[s, k, 1])
                c.set_facecolor(STATE_COLOURS[states[s, k]])
        if rc is not None:
            ok = np.isfinite(robot[s, 0])
            rc.set_visible(bool(ok))
            if ok:
                rc.center = (robot[s, 0], robot[s, 1])
        label.set_text(f"{title}  t = {traj['time'][s]:.1f} s")
        return circles

    from PIL import Image  # Pillow comes with matplotlib; only a GIF needs it

    frames = []
    for i in range(len(steps)):  # draw each frame and grab the canvas as an image
        draw(i)
        fig.canvas.draw()
        rgba = np.asarray(fig.canvas.buffer_rgba())  # type: ignore[attr-defined]  # Agg canvas
        frames.append(Image.fromarray(rgba).convert("P"))
    ms = int(100 * stride)  # real time: a step is 0.1 s
    write_atomic(
        path,
        lambda tmp: frames[0].save(
            tmp, format="GIF", save_all=True, append_images=frames[1:], duration=ms, loop=0
        ),
    )
    plt.close(fig)
    return Path(path)


_PAGE = """<!doctype html>
<html lang="en"><head><meta charset="utf-8"><title>{{ title }}</title>
<style>body{font-family:sans-serif;margin:2em;max-width:1200px}
table{border-collapse:collapse}td,th{border:1px solid #ccc;padding:2px 8px;text-align:left}
.key span{display:inline-block;width:12px;height:12px;border-radius:6px;margin:0 4px 0 12px}</style>
</head><body>
<h1>{{ title }}</h1>
<p class="key">{% for name, colour in states -%}
<span style="background:{{ colour }}"></span>{{ name }}{% endfor %}
<span style="background:{{ robot_colour }}"></span>robot (path faint, goal ring)
<span style="background:#d62728"></span>collision (ring, from its time on). Scale: the
scene is drawn to scale in metres; the bar under it is the run's time in seconds.</p>
<p class="controls"><button id="play" type="button">pause</button>
<input id="scrub" type="range" min="0" max="{{ duration }}" step="0.1" value="0"
 aria-label="time [s]" style="width:60%"> <span id="clock">t = 0.0 s</span> / {{ duration }} s</p>
<div id="scene">{{ svg | safe }}</div>
<script>
(function () {
  const svg = document.querySelector("#scene svg"), play = document.getElementById("play"),
        scrub = document.getElementById("scrub"), clock = document.getElementById("clock");
  const end = parseFloat(scrub.max);
  function show() {
    const t = svg.getCurrentTime() % end;
    clock.textContent = "t = " + t.toFixed(1) + " s";
    if (!svg.animationsPaused()) scrub.value = t;
    requestAnimationFrame(show);
  }
  play.addEventListener("click", function () {
    if (svg.animationsPaused()) { svg.unpauseAnimations(); play.textContent = "pause"; }
    else { svg.pauseAnimations(); play.textContent = "play"; }
  });
  scrub.addEventListener("input", function () {
    svg.pauseAnimations(); play.textContent = "play";
    svg.setCurrentTime(parseFloat(scrub.value));
  });
  requestAnimationFrame(show);
})();
</script>
<h2>Run</h2>
<table>{% for k, v in metrics %}<tr><th>{{ k }}</th><td>{{ v }}</td></tr>{% endfor %}</table>
</body></html>
"""


def run_outcome(metrics: Mapping[str, Any]) -> tuple[str, float] | None:
    """(outcome, its time [s]) of a run row, None when it has none."""
    kind, when = metrics.get("outcome"), metrics.get("outcome_time")
    if kind is None or when is None or not np.isfinite(float(when)):
        return None
    return str(kind), float(when)


def render_html(traj: Mapping[str, Any], metrics: Mapping[str, Any], title: str) -> str:
    """A page with the animated SVG, play/pause, a time slider and clock, a colour key and
    the run's metrics (all text escaped; the only script drives the SVG's own clock)."""
    env = Environment(autoescape=select_autoescape(default=True, default_for_string=True))
    stride = 2
    steps = np.arange(0, len(traj["time"]), stride)
    duration = round(float(traj["time"][steps[-1]] + 0.1 * stride), 1)
    return env.from_string(_PAGE).render(
        title=title, duration=duration,
        svg=render_svg(traj, title=title, stride=stride, outcome=run_outcome(metrics)),
        states=list(STATE_COLOURS.items()),
        robot_colour=ROBOT_COLOUR,
        metrics=[(k, _cell(v)) for k, v in metrics.items()],
    )


def _cell(v: Any) -> str:
    return f"{v:.3f}" if isinstance(v, float) else str(v)


def write_replay(
    traj: Mapping[str, Any], metrics: Mapping[str, Any], out: Path, title: str
) -> list[Path]:
    """Write ``out`` by its suffix: .svg, .gif or .html (an .html also gets the .svg beside it)."""
    out = Path(out)
    suffix = out.suffix.lower()
    if suffix == ".gif":
        return [render_gif(traj, out, title)]
    outcome = run_outcome(metrics)
    if suffix == ".svg":
        return [write_text(render_svg(traj, title=title, outcome=outcome), out)]
    if suffix in (".html", ".htm"):
        svg = write_text(render_svg(traj, title=title, outcome=outcome), out.with_suffix(".svg"))
        return [write_text(render_html(traj, metrics, title), out), svg]

    raise ConfigError(f"replay output {out}: use a .svg, .gif or .html file name")
