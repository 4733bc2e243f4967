"""Cells and units: the keys every analysis table is grouped and compared on.

A cell is (scene, width, density, robot_speed), written as the episode module's
``Cell.key`` and derived from the runs table's columns, never parsed from an
episode id. A unit is a cell under one pedestrian backend and mapping: controllers
are compared only within one unit. Cell metrics have the key (unit, population,
controller).
"""

from __future__ import annotations

import pandas as pd

from ..errors import InputError

CELL_COLUMNS: tuple[str, ...] = ("scene", "width", "density", "robot_speed")
#: One comparable unit: a physical cell under one pedestrian backend and mapping.
UNIT: tuple[str, ...] = ("backend", "mapping", "cell")
#: Key of the cell-metrics table.
CELL_KEY: tuple[str, ...] = (*UNIT, "population", "controller")


def cell_key(scene: str, width: float, density: float, robot_speed: float) -> str:
    """``"sidewalk-w1.8-d0.12-s0.6"``, the format of :class:`popnavshift.episodes.Cell`.

    Floats are converted to Python floats first: ``repr(np.float64(1.8))`` is
    ``"np.float64(1.8)"`` under numpy 2.
    """
    return f"{scene}-w{float(width)!r}-d{float(density)!r}-s{float(robot_speed)!r}"


def episode_cells(runs: pd.DataFrame) -> pd.DataFrame:
    """One row per episode: ``episode, cell, scene, width, density, robot_speed, variant``.

    Raises :class:`InputError` when an episode appears with two different cells.
    """
    cols = ["episode", *CELL_COLUMNS, "variant"]
    eps = runs[cols].drop_duplicates().reset_index(drop=True)
    dup = eps["episode"].duplicated()
    if dup.any():
        bad = eps.loc[dup, "episode"].iloc[0]
        raise InputError(f"runs table: episode {bad!r} has rows with different cell columns")
    rows = list(eps[list(CELL_COLUMNS)].itertuples(index=False, name=None))
    eps.insert(1, "cell", [cell_key(*r) for r in rows])
    return eps
