"""The leaderboard: every controller a researcher can name in one table, each with its two
verdicts, decided the same way.

The rows are, in this order and each once: the study's own controllers (its main part's),
every behaviour type registered in navground (:func:`leaderboard_controllers`; two of
navground's names are not controllers of their own, :data:`NOT_CONTROLLERS`), and any
plug-in or ``package.module:Class`` named. Each is evaluated against the study's
controllers (its card, :mod:`.run`: cached, so a controller already evaluated simulates
nothing, and a current card is reused) and the rows are put side by side as
:func:`.compare.compare` does: robustness against the controller's own null runs,
safety under one absolute rule, the outcome metrics and the ranks with their range over
populations. ``popnavshift leaderboard`` writes it as a page, CSV, Markdown and LaTeX;
:func:`leaderboard` returns the table.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import pandas as pd

from ..controller_ids import named_controller
from ..design.study import Study
from .compare import Comparison, Log, compare
from .run import BASELINES

#: navground behaviour types left out of "every behaviour", and why: neither is a
#: controller of its own
NOT_CONTROLLERS: dict[str, str] = {
    "": "navground's base Behavior, registered under the empty name: no motion rule of its own",
    "PyDummy": "navground's example of a behaviour written in Python: the same motion as Dummy",
    "Policy": "navground-learning's policy behaviour, registered when it is imported: with no "
              "policy of its own it does not move; a learned policy is a row by its file "
              "(popnavshift leaderboard policy.onnx)",
    "GroupPolicy": "navground-learning's policy behaviour for a group of agents: no policy "
                   "of its own",
}


def navground_controllers() -> list[str]:
    """Every behaviour type registered in navground now (plug-ins that register a type
    included), but :data:`NOT_CONTROLLERS` and the types behind our own controllers
    (registered once their module is imported; they are rows as ``reactive`` and
    ``early_yield``), sorted."""
    from ..sim.controllers.builtin import OWN_BEHAVIORS
    from ..sim.controllers.navground_type import navground_types

    return [t for t in navground_types() if t not in NOT_CONTROLLERS and t not in OWN_BEHAVIORS]


def leaderboard_controllers(study: Study, extra: Sequence[str] = ()) -> tuple[str, ...]:
    """The leaderboard's rows (module doc): the study's main-part controllers, every
    navground behaviour type, then ``extra``; each controller id once."""
    main = study.parts[study.require_main()[0]].controllers
    names = [*main, *navground_controllers(), *extra]
    return tuple(dict.fromkeys(named_controller(n) for n in names))


def build_leaderboard(extra: Sequence[str], study: Study, base_folder: Path, *,
                      workers: int = 2, n_boot: int = 1000, seed: int = 0,
                      safety_threshold: float | None = None,
                      baselines: Sequence[str] = BASELINES, show_progress: bool = True,
                      log: Log | None = None) -> Comparison:
    """Evaluate every leaderboard row (cached) and compare them (:func:`.compare.compare`);
    ``extra``: the controllers added to the study's and navground's."""
    return compare(leaderboard_controllers(study, extra), study, base_folder, workers=workers,
                   n_boot=n_boot, seed=seed, safety_threshold=safety_threshold,
                   baselines=baselines, show_progress=show_progress, log=log,
                   kind="leaderboard")


def leaderboard(study: str | Path = "study", extra: Sequence[str] = (), *, workers: int = 2,
                n_boot: int = 1000, seed: int = 0,
                safety_threshold: float | None = None) -> pd.DataFrame:
    """The leaderboard of the study in folder ``study`` (written by ``popnavshift run``;
    its configuration is read from its manifest) as one DataFrame, a row per controller
    (module doc; the columns of ``popnavshift leaderboard``'s CSV, ``docs/data.md``).
    ``extra``: plug-ins or ``package.module:Class`` controllers to add. The study's runs
    and current cards are reused; what is missing is simulated first.

    Example::

        import popnavshift
        board = popnavshift.leaderboard("study")
        board[["controller", "robustness", "safety", "mean_delay", "rank_mean_delay"]]
    """
    from ..design.study import study_from_dict
    from ..engine.lock import study_lock
    from ..engine.ownership import claim_folder
    from ..errors import InputError
    from ..read.checks import read_manifest

    base = Path(study)
    config = (read_manifest(base) or {}).get("study_config")
    if not config:
        raise InputError(f"{base}: no finished study here (no manifest.json with its "
                         "configuration)", hint="run it first: popnavshift run paper")
    s = study_from_dict(config, str(base / "manifest.json"))
    with study_lock(base):
        claim_folder(base, s, force=None, option="study")
        board = build_leaderboard(extra, s, base, workers=workers, n_boot=n_boot, seed=seed,
                                  safety_threshold=safety_threshold, show_progress=False)
    return board.table
