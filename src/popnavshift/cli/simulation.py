"""Simulation commands: episodes, simulate, replay, bench."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated, Any

import typer
from rich.table import Table

from ..errors import ConfigError, UnknownNameError
from ..progress import console
from .app import app, check_controllers, prose, say, stdout

StudyDir = Annotated[
    Path,
    typer.Option(
        "--dir",
        "-d",
        help="Study folder whose populations.parquet supplies the profiles (built with the "
        "default settings if missing).",
    ),
]
EpisodeOpt = Annotated[
    str, typer.Option("--episode", "-e", help="Episode id, e.g. sidewalk-w1.8-d0.12-s0.6-v1.")
]
PopulationOpt = Annotated[
    str, typer.Option("--population", "-p", help="Population name, e.g. matched_deadline.")
]
ControllerOpt = Annotated[
    str,
    typer.Option(
        "--controller",
        "-c",
        help="reactive, early_yield, robot_orca, any navground behavior type (HRVO, "
        "SocialForce, …), or none for the no-robot baseline.",
    ),
]
BackendOpt = Annotated[
    str, typer.Option("--backend", "-b", help="Pedestrian dynamics: orca or hl.")
]
ParamOpt = Annotated[
    list[str] | None,
    typer.Option("--param", help="Controller parameter KEY=VALUE; repeat the option."),
]


#: what ``replay --out`` can write, checked before the run is simulated
REPLAY_SUFFIXES = (".html", ".htm", ".svg", ".gif")


def parse_params(items: list[str] | None) -> dict[str, Any]:
    """``["a=1", "b=true"]`` → ``{"a": 1, "b": True}`` (JSON values, else strings)."""
    out: dict[str, Any] = {}
    for item in items or []:
        key, sep, raw = item.partition("=")
        if not sep or not key:
            raise ConfigError(f"--param {item!r}: expected KEY=VALUE")
        if key in out:
            raise ConfigError(f"--param {key!r} is given twice", hint="give each KEY once")
        try:
            out[key] = json.loads(raw)
        except json.JSONDecodeError:
            out[key] = raw
    return out


def _rebuild(folder: Path, episode: str, population: str, mapping: str, controller: str,
             backend: str, seed: int, record: bool = False):
    """Simulate one run of the study in ``folder`` (its populations are built with the
    default settings if missing) by :func:`popnavshift.engine.rebuild.rebuild_run`."""
    from ..design.study import Study
    from ..engine.lock import study_lock
    from ..engine.rebuild import population_members, rebuild_run
    from ..engine.runner import population_settings, run_stages
    from ..episodes.specs import get_episode
    from ..errors import InputError, UnknownNameError
    from ..pipeline import read_table
    from ..populations.build import POPULATIONS

    get_episode(episode, seed=seed)  # an unknown episode is the first error
    if population not in POPULATIONS:
        raise UnknownNameError("population", population, POPULATIONS)
    if not (folder / "populations.parquet").exists():
        console.print(f"building the default populations in {say(folder)} …")
        folder.mkdir(parents=True, exist_ok=True)
        with study_lock(folder):
            run_stages(folder, population_settings(Study(name="default", parts={})), True)
    pops = read_table(folder / "populations.parquet", "populations")
    try:
        population_members(pops, mapping, population)
    except InputError:
        raise ConfigError(
            f"{folder}/populations.parquet has no {population!r} for mapping {mapping}"
        ) from None
    key = {"episode": episode, "population": population, "controller": controller,
           "backend": backend, "mapping": mapping}
    return rebuild_run(key, pops, seed, record=record)


def _controller(name: str, params: dict[str, Any]) -> str:
    """The controller id of ``name`` with ``params`` (``none``: the no-robot baseline)."""
    from ..controller_ids import controller_id

    if name == "none":
        if params:
            raise ConfigError("--param makes no sense with --controller none")
        return name
    check_controllers(name)  # a misspelt name fails before the study folder is read
    return controller_id(name, params)  # names, entry points, package.module:Class


@app.command()
def episodes(
    json_out: Annotated[bool, typer.Option("--json", help="Print the counts as JSON.")] = False,
    seed: Annotated[int, typer.Option(min=0, help="Study seed (episode draws).")] = 0,
    scene: Annotated[str | None, typer.Option(help="Only this scene type.")] = None,
) -> None:
    """List the physical cells and episodes (type, width, density, robot speed, variant, peds)."""
    from ..episodes.specs import all_cells, all_episodes, episodes_table

    table = episodes_table(all_episodes(seed))
    cells = [c for c in all_cells() if scene is None or c.scene == scene]
    if scene is not None:
        scenes = sorted(table["scene"].unique())
        if scene not in scenes:
            raise UnknownNameError("scene", scene, scenes)
        table = table[table["scene"] == scene]
    if json_out:
        counts = {
            "cells": len(cells),
            "episodes": len(table),
            "by_scene": table.groupby("scene").size().to_dict(),
            "pedestrians": int(table["n_peds"].sum()),
        }
        typer.echo(json.dumps(counts, indent=2))
        return
    # the id is what `simulate` and `replay` take: never cut it; it already names the
    # scene, width, density, speed and variant, so a narrow terminal shows it alone
    wide = stdout.width >= 100
    t = Table()
    t.add_column("episode (the id for simulate -e / replay -e)", no_wrap=True, min_width=32)
    heads = ("scene", "width [m]", "density [/m²]", "robot [m/s]", "variant") if wide else ()
    for h in heads:
        t.add_column(say(h))
    t.add_column("peds", justify="right")
    for r in table.itertuples():
        cols = (r.scene, f"{r.width:g}", f"{r.density:g}", f"{r.robot_speed:g}",
                str(r.variant)) if wide else ()
        t.add_row(say(r.id), *cols, str(r.n_peds))
    stdout.print(t)
    stdout.print(f"{len(cells)} cells, {len(table)} episodes shown")


@app.command()
def simulate(
    episode: EpisodeOpt,
    population: PopulationOpt = "mixed",
    controller: ControllerOpt = "robot_orca",
    backend: BackendOpt = "orca",
    param: ParamOpt = None,
    mapping: Annotated[str, typer.Option(help="Mapping A–D.")] = "A",
    study_dir: StudyDir = Path("study"),
    seed: Annotated[int, typer.Option(min=0, help="Study seed (episode draws).")] = 0,
    json_out: Annotated[bool, typer.Option("--json", help="Print the rows as JSON.")] = False,
) -> None:
    """Run one episode under one population and controller; print its metrics.

    Example: popnavshift simulate -e bottleneck-w1.8-d0.2-s1.0-v1 -p matched_deadline -c reactive
    """
    ident = _controller(controller, parse_params(param))
    result = _rebuild(study_dir, episode, population, mapping, ident, backend, seed)
    if json_out:
        typer.echo(
            json.dumps(
                {"run": result.run, "pedestrians": result.pedestrians.to_dict("records")},
                default=float,
                indent=2,
            )
        )
        return
    t = Table("metric", "value", title=say(f"{episode} · {population} · {controller} · {backend}"))
    for k, v in result.run.items():
        t.add_row(say(k), f"{v:.3f}" if isinstance(v, float) else say(v))
    console.print(t)
    peds = result.pedestrians
    arrived = peds["arrived"].mean() if len(peds) else float("nan")
    console.print(
        f"{len(peds)} pedestrians, {arrived:.0%} arrived, mean travel time "
        f"{peds['travel_time'].mean():.2f} s"
    )


@app.command()
def replay(
    episode: EpisodeOpt,
    out: Annotated[
        Path,
        typer.Option(
            "--out", "-o", help="Output file: .html (page + .svg), .svg (animated) or .gif."
        ),
    ],
    population: PopulationOpt = "mixed",
    controller: ControllerOpt = "robot_orca",
    backend: BackendOpt = "orca",
    param: ParamOpt = None,
    mapping: Annotated[str, typer.Option(help="Mapping A–D.")] = "A",
    study_dir: StudyDir = Path("study"),
    seed: Annotated[int, typer.Option(min=0, help="Study seed (episode draws).")] = 0,
) -> None:
    """Render one run as an animated SVG/GIF or an HTML page you can watch.

    Pedestrians are coloured by state: walking, reacting, yielding, detouring.
    """
    from ..viz.replay import write_replay

    if out.is_dir() or out.suffix.lower() not in REPLAY_SUFFIXES:
        raise ConfigError(f"--out {out}: expected a file ending in "
                          f"{', '.join(REPLAY_SUFFIXES)}"
                          f"{' (it is a folder)' if out.is_dir() else ''}")
    ident = _controller(controller, parse_params(param))
    result = _rebuild(study_dir, episode, population, mapping, ident, backend, seed, record=True)
    title = f"{episode} · {population} · {controller} · {backend} → {result.run['outcome']}"
    assert result.trajectory is not None
    paths = write_replay(result.trajectory, result.run, out, title)
    console.print("wrote " + ", ".join(say(p) for p in paths))


@app.command()
def bench(
    n_per_scene: Annotated[int, typer.Option(min=1, help="Episodes per scene type.")] = 3,
    repeats: Annotated[int, typer.Option(min=1, help="Timing repeats per episode.")] = 1,
    profile: Annotated[bool, typer.Option(help="Also profile the full stack.")] = False,
    json_path: Annotated[Path | None, typer.Option("--json", help="Also write JSON here.")] = None,
) -> None:
    """Time the full stack against bare navground on the same worlds (episodes/s, ratio)."""
    from ..sim.bench import format_bench, run_bench

    result = run_bench(n_per_scene=n_per_scene, repeats=repeats, profile=profile)
    prose(say(format_bench(result), lines=True))  # the command's output: stdout, its lines
    if json_path is not None:
        from ..io import write_json

        write_json({"summary": result.summary, "table": result.table.to_dict("records")}, json_path)
