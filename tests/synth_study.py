"""Synthetic study tables (runs + pedestrians, the real schema) where the answer is known.

Every (cell, variant, population, controller) run gets pedestrian delays
``mu[cell, controller] + effect(population, cell, controller) + noise`` and a robot
time ``25 + tmu[cell, controller] + effect(...) + noise``; every population draws
its own noise (as different personas in the same slots would). A population whose
``effect`` is zero everywhere differs from another only by noise, so its reversal
rates are pure noise; an injected ``effect`` of opposite sign under two populations
is a true crossover.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
import pandas as pd

from popnavshift.analysis import cell_key
from popnavshift.populations.identity import PopulationSpec, null_populations
from popnavshift.tables import NO_ROBOT

Effect = Callable[[int, str], float]  # (cell index, controller) → added delay [s]
CONTROLLERS = ("a", "b", "c")


def no_effect(cell: int, controller: str) -> float:
    return 0.0


def synthetic_study(populations: dict[str, Effect], *, n_cells: int = 12, variants: int = 6,
                    n_peds: int = 8, noise: float = 0.6, seed: int = 0,
                    controllers: Sequence[str] = CONTROLLERS,
                    seed_sets: int = 1) -> tuple[pd.DataFrame, pd.DataFrame]:
    """(runs, pedestrians) of ``n_cells`` sidewalk cells × ``variants`` variants per seed
    set × ``populations`` × ``controllers`` and the no-robot baseline.

    Episodes of seed set k > 0 are named ``<cell>-v<i>@s<k>`` (as the study engine does).
    """
    rng = np.random.default_rng(seed)
    cells = synthetic_cells(n_cells)
    mu = rng.uniform(0.5, 2.0, size=(n_cells, len(controllers)))
    tmu = rng.uniform(0.0, 4.0, size=(n_cells, len(controllers)))
    runs, peds = [], []
    for ci, cell in enumerate(cells):
        for k in range(seed_sets):
            for v in range(1, variants + 1):
                ep = f"{cell_key(*cell)}-v{v}" + (f"@s{k}" if k else "")
                for pop, effect in populations.items():
                    base_t = 20.0 + rng.normal(0, 1.0, n_peds)
                    for j, ctrl in enumerate((NO_ROBOT, *controllers)):
                        robot = ctrl != NO_ROBOT
                        e = effect(ci, ctrl) if robot else 0.0
                        delay = (mu[ci, j - 1] + e + rng.normal(0, noise, n_peds)) if robot \
                            else np.zeros(n_peds)
                        rt = 25.0 + tmu[ci, j - 1] + e + rng.normal(0, noise) if robot else 0.0
                        runs.append({"part": "main", "episode": ep, "seed_set": k,
                                     "scene": cell[0],
                                     "width": cell[1], "density": cell[2],
                                     "robot_speed": cell[3], "variant": v, "population": pop,
                                     "controller": ctrl, "backend": "orca", "mapping": "A",
                                     "outcome": "success" if robot else "none",
                                     "robot_time": rt if robot else np.nan,
                                     "robot_min_clearance": 0.8 if robot else np.nan,
                                     "robot_path_length": 20.0 if robot else np.nan,
                                     "robot_stop_time": 0.5 if robot else np.nan,
                                     "error": None})
                        for s in range(n_peds):
                            t = base_t[s] + delay[s]
                            peds.append({"part": "main", "episode": ep, "seed_set": k,
                                         "population": pop,
                                         "controller": ctrl, "backend": "orca", "mapping": "A",
                                         "slot": s, "persona_id": f"p{s}", "arrived": True,
                                         "travel_time": t, "walk_distance": 1.3 * t})
    return pd.DataFrame(runs), pd.DataFrame(peds)


def synthetic_cells(n_cells: int) -> list[tuple[str, float, float, float]]:
    """The (scene, width, density, robot speed) of synthetic cell 0 … n_cells − 1."""
    widths, densities = (1.8, 2.4, 3.0, 4.2), (0.06, 0.12, 0.2)
    return [("sidewalk", widths[i % 4], densities[(i // 4) % 3], (0.6, 1.0)[i // 12 % 2])
            for i in range(n_cells)]


def crossover(cells: Sequence[int], size: float, sign: float, controller: str = "a") -> Effect:
    """``controller`` is ``sign · size`` s slower (delay and robot time) in ``cells``."""
    chosen = set(cells)

    def effect(cell: int, ctrl: str) -> float:
        return sign * size if (cell in chosen and ctrl == controller) else 0.0

    return effect


#: the cells where :func:`swap_study` injects its crossover
CROSS_CELLS = (0, 1, 2, 3, 4, 5)


def swap_study(n_null: int, *, inject: float, seed: int, shifted: str = "a", **kw):
    """The matched pair (controller ``shifted`` slower by ∓inject in CROSS_CELLS) and
    ``n_null`` swap permutations, whose arms mix the two directions and so carry no shift."""
    pops = {"matched_base": crossover(CROSS_CELLS, inject, -1.0, shifted),
            "matched_deadline": crossover(CROSS_CELLS, inject, +1.0, shifted)}
    for k in range(1, n_null + 1):
        pops[PopulationSpec.swap(k, "a").name] = no_effect
        pops[PopulationSpec.swap(k, "b").name] = no_effect
    return synthetic_study(pops, seed=seed, **kw)


def design_specs(runs: pd.DataFrame, kind: str, of: Sequence[str] = ()) -> list[PopulationSpec]:
    """The populations of ``runs`` as a study would index them: the replicates of a
    ``kind`` null design standing in for ``of`` that ``runs`` hold, the rest conditions."""
    names = set(runs["population"])
    nulls = [s for s in null_populations(kind, 99, tuple(of)) if s.name in names]
    return nulls + [PopulationSpec(n) for n in sorted(names - {s.name for s in nulls})]
