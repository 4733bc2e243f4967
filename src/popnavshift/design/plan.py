"""Run plans: a study → its runs, without the simulator.

A run is keyed by (episode, population, controller, backend, mapping);
``controller == "none"`` is the no-robot baseline. Parts may overlap (the
``matched`` part is inside ``main``); a run shared by several parts is run once
and belongs to the first part that plans it. The engine groups the runs into
batches and runs those the study folder does not hold yet
(:mod:`popnavshift.engine.batch_plan`); the read side selects a part's runs with the
same plan (:mod:`popnavshift.read.folder`).
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

from ..episodes.specs import seed_set_id
from ..errors import UnknownNameError
from ..hashing import digest
from ..tables import NO_ROBOT
from .part import EpisodeSelection
from .study import Study


@dataclass(frozen=True, order=True)
class Run:
    episode: str
    population: str
    controller: str
    backend: str
    mapping: str
    part: str

    @property
    def key(self) -> tuple[str, str, str, str, str]:
        return (self.episode, self.population, self.controller, self.backend, self.mapping)

    @property
    def id(self) -> str:
        """The ``run_id`` column: 16 hex digits of the key's hash, the same in every study."""
        return digest(list(self.key))[:16]


def select_episodes(selection: EpisodeSelection, episodes: Iterable) -> list:
    """The episode specs of ``episodes`` matched by ``selection``, in grid order."""
    eps = list(episodes)
    if selection.ids is not None:
        by_id = {e.id: e for e in eps}

        for i in selection.ids:
            if i not in by_id:
                raise UnknownNameError("episode", i, by_id)
        return [by_id[i] for i in selection.ids]

    def keep(values, x) -> bool:
        if values is None:
            return True
        if isinstance(x, str):
            return x in values
        return any(abs(float(v) - float(x)) < 1e-9 for v in values)

    return [
        e
        for e in eps
        if keep(selection.scenes, e.scene)
        and keep(selection.widths, e.width)
        and keep(selection.densities, e.density)
        and keep(selection.robot_speeds, e.robot_speed)
        and keep(selection.variants, e.variant)
    ]


def plan_study(study: Study, episodes: Iterable) -> list[Run]:
    """Every distinct run of ``study`` in a deterministic order."""
    eps = list(episodes)
    seen: set[tuple] = set()
    runs: list[Run] = []
    for part_name, part in study.parts.items():
        controllers = ((NO_ROBOT,) if part.baseline else ()) + part.controllers
        base = [e.id for e in select_episodes(part.episodes, eps)]
        extra = [seed_set_id(i, s) for s in part.seeds if s != study.seed for i in base]
        for episode in base + extra:
            for mapping in part.mappings:
                for backend in part.backends:
                    for pop in part.planned_populations:
                        for ctrl in controllers:
                            run = Run(episode, pop, ctrl, backend, mapping, part_name)
                            if run.key not in seen:
                                seen.add(run.key)
                                runs.append(run)
    return runs


def count_runs(study: Study, episodes: Iterable) -> dict[str, dict[str, int]]:
    """Per part: robot runs, no-robot runs, total (shared runs counted in every part),
    plus ``distinct`` — what a run of the whole study executes."""
    eps = list(episodes)
    out: dict[str, dict[str, int]] = {}
    for name, part in study.parts.items():
        n_sets = 1 + len([s for s in part.seeds if s != study.seed])
        n_eps = len(select_episodes(part.episodes, eps)) * n_sets
        per = n_eps * len(part.backends) * len(part.planned_populations) * len(part.mappings)
        robot = per * len(part.controllers)
        none = per if part.baseline else 0
        out[name] = {
            "episodes": n_eps,
            "robot_runs": robot,
            "no_robot_runs": none,
            "total": robot + none,
        }
    runs = plan_study(study, eps)
    robot = sum(r.controller != NO_ROBOT for r in runs)
    out["distinct"] = {"robot_runs": robot, "no_robot_runs": len(runs) - robot, "total": len(runs)}
    return out
