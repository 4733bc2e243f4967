"""``popnavshift evaluate``: one controller against the baselines, as a robustness card."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from ..progress import console
from .app import MAX_WORKERS, app, check_workers, default_folder, say
from .simulation import ParamOpt, parse_params


@app.command()
def evaluate(
    controller: Annotated[
        str,
        typer.Argument(
            help="A registered controller or navground behavior type (HRVO, SocialForce, …), "
            "an entry point of the popnavshift.controllers group, or a Python class "
            "package.module:Class subclassing navground.core.Behavior."
        ),
    ],
    study: Annotated[
        str | None,
        typer.Option("--study", "-s", help="Baseline study: quick, paper or a YAML file "
                     "(default: the study `make run` wrote into ./study, else quick)."),
    ] = None,
    study_dir: Annotated[
        Path | None,
        typer.Option(
            "--study-dir",
            "-d",
            help="Folder of the baseline study; its finished runs are reused "
            "(default: the folder of `popnavshift run <name>`: ./study for paper, else "
            "./study-<name>).",
        ),
    ] = None,
    out: Annotated[
        Path | None,
        typer.Option(
            "--out", "-o", help="Folder of the card (default: STUDY_DIR/evaluate/<controller>)."
        ),
    ] = None,
    baselines: Annotated[
        str | None,
        typer.Option(help="Comma-separated controllers to compare with "
                     "(default: the built-in controllers)."),
    ] = None,
    param: ParamOpt = None,
    workers: Annotated[
        int, typer.Option("--workers", "-w", min=1, max=MAX_WORKERS, help="Worker processes.")
    ] = 2,
    check: Annotated[
        bool, typer.Option(help="Run the controller contract checker first.")
    ] = True,
    n_boot: Annotated[int, typer.Option(min=1, help="Bootstrap resamples for the CIs.")] = 1000,
    seed: Annotated[int, typer.Option(min=0, help="Seed of the bootstrap.")] = 0,
    safety_threshold: Annotated[
        float | None,
        typer.Option(min=0.0, max=1.0, help="Also read unsafe when pedestrian collisions, "
                     "wall contacts or controller errors exceed this share of the controller's "
                     "runs, whatever the baselines do (off by default: the verdict compares "
                     "each failure with the least safe baseline on the same runs)."),
    ] = None,
) -> None:
    """Evaluate CONTROLLER under every population of a study, next to the baselines.

    Runs only what is not cached (the baseline study's runs and no-robot runs are
    reused) and writes a one-page robustness card, card.html + card.png.

    Example: popnavshift evaluate my_pkg.controller:MyBehavior --study quick
    """
    from ..evaluate import BASELINES, make_card
    from ..evaluate import evaluate as run_evaluation
    from ..sim.controllers.registry import controller_id
    from .app import folder

    check_workers(workers)
    s, default_dir = _baseline_study(study)
    base = folder(study_dir or default_dir)
    params = parse_params(param)
    identity = controller_id(controller, params) if params else controller
    names = BASELINES if baselines is None else tuple(
        b.strip() for b in baselines.split(",") if b.strip())
    ev = run_evaluation(identity, s, base, out, baselines=names, workers=workers,
                        run_check=check,
                        log=lambda msg: console.print(say(msg), highlight=False, soft_wrap=True))
    if ev.counts["controller_errors"]:
        console.print(f"[yellow]warning[/]: the controller raised in "
                      f"{ev.counts['controller_errors']} of its {ev.counts['controller_runs']} "
                      "runs (recorded as controller_error; see the card)")
    with console.status("writing the card…"):
        html, png = make_card(ev, n_boot=n_boot, seed=seed, safety_threshold=safety_threshold)
    console.print(f"card → {say(html)}\nfigure → {say(png)}", soft_wrap=True, highlight=False)


MADE_STUDY = Path("study")  # where `make run` writes the paper study


def _baseline_study(name: str | None):
    """The study to evaluate against and its default folder: the one named, else the
    study `make run` left in ./study (its manifest holds the configuration), else quick."""
    import json

    from ..engine.study import load_study, study_from_dict

    manifest = MADE_STUDY / "manifest.json"
    if name is None and manifest.exists():
        cfg = json.loads(manifest.read_text("utf-8")).get("study_config")
        if cfg:
            return study_from_dict(cfg, str(manifest)), MADE_STUDY
    s = load_study(name or "quick")
    return s, default_folder(s.name)
