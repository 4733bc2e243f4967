"""Which runs a card needs, and how they are gathered from the study and the card's own.

A card judges a controller's orderings against each baseline with the study's own tests
(:mod:`.robustness`), so the controller runs wherever the study's headline comparisons
and their nulls run: the **evaluation parts** (:func:`evaluation_parts`) — the main part
and every part whose role is ``other`` but the noise floor's split halves (in the paper
study: ``main``, the size-matched null, the matched pair on its seed sets and its swap
null). The robustness parts (mappings, profile structure, backends, a second
respondent) and the split halves are left out: the card's verdicts do not rest on them.

Runs are keyed as the study's (:mod:`popnavshift.design.plan`), so a controller the study
itself runs (a baseline) is never run again, and the controller's own runs are carried
by every later card of the same controller and code (:mod:`popnavshift.engine.run_inputs`).
"""

from __future__ import annotations

import pandas as pd

from ..design.part import Part
from ..design.plan import Run, plan_study
from ..design.study import Study
from ..episodes.specs import all_episodes
from ..errors import InputError
from ..populations.identity import spec_of
from ..tables import RUN_KEY

Tables = tuple[pd.DataFrame, pd.DataFrame]  # runs, pedestrians


def evaluation_parts(study: Study) -> tuple[str, ...]:
    """The parts a card runs the controller on (module doc), the main part first."""
    main, _ = study.require_main()
    specs = study.population_specs()
    others = [name for name, part in study.parts.items()
              if name != main and study.role(name) == "other"
              and not all(spec_of(specs, p).role == "half" for p in part.planned_populations)]
    return (main, *others)


def _with_controllers(study: Study, names: tuple[str, ...],
                      controllers: tuple[str, ...], baseline: bool | None) -> Study:
    """``study`` reduced to the parts ``names``, each running ``controllers`` (and the
    no-robot baseline when ``baseline``; None keeps each part's own)."""
    def part(p: Part) -> Part:
        return p.model_copy(update={"controllers": controllers,
                                    "baseline": p.baseline if baseline is None else baseline})
    return study.model_copy(update={"parts": {n: part(study.parts[n]) for n in names}})


def plan_extra(study: Study, names: tuple[str, ...], controllers: tuple[str, ...]) -> list[Run]:
    """The runs of ``controllers`` on the parts ``names`` that the study does not plan
    itself: each controller a part does not run, and the no-robot runs of a part without
    them."""
    eps = all_episodes(seed=study.seed)
    have = {r.key for r in plan_study(study, eps)}
    wanted = plan_study(_with_controllers(study, names, controllers, True), eps)
    return [r for r in wanted if r.key not in have]


def card_tables_of(study: Study, names: tuple[str, ...], controllers: tuple[str, ...],
                   sources: list[Tables]) -> Tables:
    """Runs and pedestrians of ``controllers`` and no robot on the parts ``names``, taken
    from ``sources`` (the study's tables and the card's own), each with the ``part`` of
    the first of ``names`` that plans it; InputError when a planned run is in none."""
    planned = plan_study(_with_controllers(study, names, controllers, True),
                         all_episodes(seed=study.seed))
    keys = pd.DataFrame([(*r.key, r.part) for r in planned], columns=[*RUN_KEY, "part"])
    runs = _pick(keys, [r for r, _ in sources])
    peds = _pick(keys, [p for _, p in sources])
    if len(runs) != len(keys):
        raise InputError(f"{len(keys) - len(runs)} of the {len(keys)} runs the card "
                         "needs are missing from the study tables",
                         hint="run the study again; finished work is kept")
    return runs, peds


def _pick(keys: pd.DataFrame, tables: list[pd.DataFrame]) -> pd.DataFrame:
    """The rows of ``tables`` (disjoint: the study's, the card's own) whose run key is in
    ``keys``, with ``keys``' part."""
    return pd.concat([t.drop(columns="part").merge(keys, on=list(RUN_KEY)) for t in tables],
                     ignore_index=True)


def main_part_rows(runs: pd.DataFrame, study: Study) -> pd.Series:
    """Which rows of a card's table are the main part's runs (those its first tables —
    outcomes, safety, ranks, crossovers — describe)."""
    return runs["part"].eq(study.require_main()[0])


