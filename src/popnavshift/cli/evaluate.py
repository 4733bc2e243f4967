"""``popnavshift evaluate``: one controller against the baselines, as a robustness card."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Annotated

import typer

from ..errors import ConfigError
from ..progress import console
from .app import (
    MAX_WORKERS,
    Replicates,
    SeedSets,
    app,
    check_controllers,
    check_workers,
    default_folder,
    extended,
    say,
)
from .simulation import ParamOpt, parse_params

#: The card's safety threshold (None: the card's default, evaluate.safety.SAFETY_THRESHOLD,
#: which the help states: tests/test_evaluate_safety.py checks they agree).
SafetyThreshold = Annotated[
    float | None,
    typer.Option(min=0.0, max=1.0, help="Unsafe when a counted failure (pedestrian "
                 "collisions with the robot moving, wall contacts, controller errors) is "
                 "above this share of the controller's runs with 95% confidence, safe when "
                 "every one is below it: the same rule for every controller (default: 0.01, "
                 "1% of its runs)."),
]
#: Options shared by compare and leaderboard (every card is made under them)
Workers = Annotated[int, typer.Option("--workers", "-w", min=1, max=MAX_WORKERS,
                                      help="Worker processes.")]
CardsBoot = Annotated[int, typer.Option(min=1, max=100_000,
                                        help="Bootstrap resamples of the cards.")]
CardsSeed = Annotated[int, typer.Option(min=0, help="Seed of the cards' bootstrap.")]
#: The study a controller is evaluated against (shared by evaluate and compare).
BaselineStudy = Annotated[
    str | None,
    typer.Option("--study", "-s", help="Baseline study: quick, paper or a YAML file "
                 "(default: the study `make run` wrote into ./study, else quick)."),
]


@app.command()
def evaluate(
    controller: Annotated[
        str,
        typer.Argument(
            help="A registered controller or navground behavior type (HRVO, SocialForce, …), "
            "an entry point of the popnavshift.controllers group, a Python class "
            "package.module:Class subclassing navground.core.Behavior, or a learned policy "
            "file: policy.onnx or a Stable-Baselines3 model.zip (docs/evaluate-your-"
            "controller.md)."
        ),
    ],
    study: BaselineStudy = None,
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
    n_boot: Annotated[int, typer.Option(min=1, max=100_000,
                                        help="Bootstrap resamples for the CIs.")] = 1000,
    seed: Annotated[int, typer.Option(min=0, help="Seed of the bootstrap.")] = 0,
    safety_threshold: SafetyThreshold = None,
    replicates: Replicates = None,
    seed_sets: SeedSets = None,
) -> None:
    """Evaluate CONTROLLER under every population of a study, next to the baselines.

    Runs only what is not cached (the baseline study's runs and no-robot runs are
    reused) and writes a one-page robustness card, card.html + card.png, with its verdict
    in card.json and every table it shows as CSV.

    Example: popnavshift evaluate my_pkg.controller:MyBehavior --study quick

    A learned policy is named by its file (popnavshift evaluate policy.onnx): its
    controller id holds the file's absolute path and sha256, so a changed file is
    another controller with runs of its own.
    """
    given = None if baselines is None else _baselines(baselines, ())
    controller = named(controller)[0]
    check_controllers(controller, *(given or ()))  # a misspelt name fails at once
    check_policies(controller, *(given or ()))
    from ..controller_ids import controller_id
    from ..engine.lock import study_lock
    from ..engine.ownership import claim_folder
    from ..evaluate.card_files import check_out, current_card
    from ..paper import PAPER_CONTROLLERS as BASELINES  # the cards' default baselines
    from .app import folder

    check_workers(workers)
    s, default_dir = _baseline_study(study)
    s = extended(s, replicates, seed_sets)
    if out is not None:  # before anything is made: never the study's folder, and writable
        check_out(out, study_dir or default_dir)
    base = folder(study_dir or default_dir)
    params = parse_params(param)
    if params and "{" in controller:
        raise ConfigError(f"controller {controller} takes no --param: its parameters are in "
                          "its name (a policy file's are its path and hash)")
    identity = controller_id(controller, params) if params else controller
    names = BASELINES if given is None else given
    with study_lock(base):  # the baseline study's folder gets runs and the card: one writer
        claim_folder(base, s, force=None, option="--study-dir")
        card, why = current_card(identity, s, base, out, baselines=names, n_boot=n_boot,
                                 seed=seed, safety_threshold=safety_threshold)
        if not why:  # nothing to run and nothing to write: the card stands
            console.print(f"card is current, reused → {say(card / 'card.html')}",
                          soft_wrap=True, highlight=False)
            return
        from ..evaluate.run import evaluate as run_evaluation
        from ..evaluate.run import make_card

        ev = run_evaluation(identity, s, base, out, baselines=names, workers=workers,
                            run_check=check, log=lambda msg: console.print(
                                say(msg), highlight=False, soft_wrap=True))
        if ev.counts["controller_errors"]:
            console.print(f"[yellow]warning[/]: the controller raised in "
                          f"{ev.counts['controller_errors']} of its "
                          f"{ev.counts['controller_runs']} runs (recorded as controller_error; "
                          "see the card)")
        with console.status("writing the card…"):
            html, png = make_card(ev, n_boot=n_boot, seed=seed,
                                  safety_threshold=safety_threshold)
    console.print(f"card → {say(html)}\nfigure → {say(png)}", soft_wrap=True, highlight=False)


@app.command()
def compare(
    controllers: Annotated[
        list[str],
        typer.Argument(help="Controllers to put side by side: any name `evaluate` takes "
                       "(reactive, early_yield, robot_orca, HRVO, package.module:Class, "
                       "policy.onnx, model.zip, …)."),
    ],
    study: BaselineStudy = None,
    study_dir: Annotated[
        Path | None,
        typer.Option("--study-dir", "-d", help="Folder of the study; evaluated controllers' "
                     "cards in STUDY_DIR/evaluate are reused (default: as for evaluate)."),
    ] = None,
    out: Annotated[
        Path | None,
        typer.Option("--out", "-o", help="The page, FILE.html; FILE.csv, .md, .tex and .png "
                     "go beside it (default: STUDY_DIR/compare/compare.html)."),
    ] = None,
    workers: Workers = 2,
    n_boot: CardsBoot = 1000,
    seed: CardsSeed = 0,
    safety_threshold: SafetyThreshold = None,
    baselines: Annotated[
        str | None,
        typer.Option(help="Comma-separated controllers each card compares with "
                     "(default: the built-in controllers)."),
    ] = None,
    replicates: Replicates = None,
    seed_sets: SeedSets = None,
) -> None:
    """Put the robustness cards of several controllers side by side: one page, one table.

    A controller without a card in STUDY_DIR/evaluate is evaluated first (cached runs
    are reused); an existing card is read when it was made under the same rules
    (--n-boot, --seed, --safety-threshold, --baselines, the study's configuration, its
    runs and the code), and made again otherwise, with one line saying why.

    Example: popnavshift compare reactive early_yield robot_orca HRVO
    """
    controllers = named(*controllers)
    check_controllers(*controllers)  # a misspelt name fails at once
    check_policies(*controllers)
    _side_by_side(controllers, study, study_dir, out, "compare", workers=workers, n_boot=n_boot,
                  seed=seed, safety_threshold=safety_threshold, baselines=baselines,
                  replicates=replicates, seed_sets=seed_sets)


@app.command()
def leaderboard(
    extra: Annotated[
        list[str] | None,
        typer.Argument(help="Plug-ins, package.module:Class controllers or learned policy "
                       "files (policy.onnx, model.zip) to add to the rows (the study's "
                       "controllers and every navground behaviour are always in)."),
    ] = None,
    study: BaselineStudy = None,
    study_dir: Annotated[
        Path | None,
        typer.Option("--study-dir", "-d", help="Folder of the study; its cards in "
                     "STUDY_DIR/evaluate are reused (default: as for evaluate).")] = None,
    out: Annotated[
        Path | None,
        typer.Option("--out", "-o", help="The page, FILE.html; FILE.csv, .md, .tex and .png "
                     "go beside it (default: STUDY_DIR/leaderboard/leaderboard.html).")] = None,
    workers: Workers = 2,
    n_boot: CardsBoot = 1000,
    seed: CardsSeed = 0,
    safety_threshold: SafetyThreshold = None,
    replicates: Replicates = None,
    seed_sets: SeedSets = None,
) -> None:
    """Every controller you can name, in one table: the study's controllers, every
    behaviour registered in navground (Dummy, HL, HRVO, ORCA, SocialForce, and any a
    plug-in registers) and the plug-ins given, each with its robustness verdict against
    its own null runs and its safety label under one rule.

    Each controller is evaluated as `evaluate` does (cached runs and current cards are
    reused; a new controller runs on the study's populations and their nulls) and the rows
    are written as one page with CSV, Markdown and a LaTeX table for a paper. Some
    navground names are left out: the empty name (the base Behavior), PyDummy (the same
    motion as Dummy) and navground-learning's Policy and GroupPolicy (no policy of their
    own: name a policy by its file).

    Example: popnavshift leaderboard my_pkg.controller:MyBehavior policy.onnx
    """
    extra = named(*(extra or ()))
    check_controllers(*extra)  # a misspelt name fails at once
    check_policies(*extra)
    _side_by_side(tuple(extra), study, study_dir, out, "leaderboard", workers=workers,
                  n_boot=n_boot, seed=seed, safety_threshold=safety_threshold, baselines=None,
                  replicates=replicates, seed_sets=seed_sets)


def _side_by_side(names: Sequence[str], study: str | None, study_dir: Path | None,
                  out: Path | None, kind: str, *, workers: int, n_boot: int, seed: int,
                  safety_threshold: float | None, baselines: str | None,
                  replicates: int | None, seed_sets: int | None) -> None:
    """``compare`` (``names``: the controllers) or ``leaderboard`` (``names``: the extra
    rows): evaluate, compare and write the page STUDY_DIR/<kind>/<kind>.html or ``out``."""
    from ..engine.lock import study_lock
    from ..engine.ownership import claim_folder
    from ..evaluate import BASELINES
    from ..evaluate.compare import compare as run_compare
    from ..evaluate.compare_page import check_page, write_comparison
    from ..evaluate.leaderboard import build_leaderboard
    from .app import folder

    check_workers(workers)
    s, default_dir = _baseline_study(study)
    s = extended(s, replicates, seed_sets)
    page = out or (study_dir or default_dir) / kind / f"{kind}.html"
    check_page(page, ours=out is None)  # before any work: writable, over nothing else
    base = folder(study_dir or default_dir)
    with study_lock(base):  # cards are evaluated into the baseline folder: one writer
        claim_folder(base, s, force=None, option="--study-dir")
        run = build_leaderboard if kind == "leaderboard" else run_compare
        comparison = run(names, s, base, workers=workers, n_boot=n_boot,
                         seed=seed, safety_threshold=safety_threshold,
                         baselines=_baselines(baselines, BASELINES),
                         log=lambda msg: console.print(say(msg), highlight=False,
                                                       soft_wrap=True))
        with console.status(f"writing the {kind}…"):
            paths = write_comparison(comparison, page)
    console.print(f"page → {say(paths['html'])}\ntable → {say(paths['csv'])} "
                  f"(also {paths['md'].suffix} and {paths['tex'].suffix})", soft_wrap=True,
                  highlight=False)


def _baselines(option: str | None, default: tuple[str, ...]) -> tuple[str, ...]:
    """``--baselines a,b`` as names (the default when not given)."""
    if option is None:
        return default
    return tuple(named(*(b.strip() for b in option.split(",") if b.strip())))


def named(*specs: str) -> list[str]:
    """The controllers named on the command line, a policy file (``*.onnx``, ``*.zip``) as
    its controller id (its absolute path and content hash,
    :func:`popnavshift.controller_ids.policy_id`; a missing file is one line)."""
    from ..controller_ids import is_policy_file, policy_id

    return [policy_id(s) if is_policy_file(s) else s for s in specs]


def check_policies(*identities: str) -> None:
    """Load every learned policy among ``identities`` once, before any folder is touched:
    a file that is not a model, or whose observation or action is not a PopNavShift
    policy's, or a zip without torch installed, is one line here
    (:mod:`popnavshift.learn.policy`). Other controllers are made where they run."""
    from ..controller_ids import policy_file

    policies = [i for i in identities if policy_file(i) is not None]
    if policies:
        from ..sim.controllers import CONTROLLERS

        for identity in policies:
            CONTROLLERS.make(identity)


MADE_STUDY = Path("study")  # where `make run` writes the paper study


def _baseline_study(name: str | None):
    """The study to evaluate against and its default folder: the one named, else the
    study `make run` left in ./study (its manifest holds the configuration), else quick."""
    from ..design.study import load_study, study_from_dict
    from ..read.checks import read_manifest

    manifest = MADE_STUDY / "manifest.json"
    if name is None and manifest.exists():
        cfg = (read_manifest(MADE_STUDY) or {}).get("study_config")
        if cfg:
            return study_from_dict(cfg, str(manifest)), MADE_STUDY
    s = load_study(name or "quick")
    return s, default_folder(s.name)
