"""Physical cells and seeded episode specs (SPEC §6).

A :class:`Cell` fixes scene, width [m], density [1/m²] and robot speed [m/s]; 104
cells × 3 variants = 312 :class:`EpisodeSpec`. A spec is plain frozen data drawn
once from ``numpy.random.default_rng(stable_seed(...))``: every run of an episode
(any population, controller, backend, or no robot) starts from the same
pedestrian states. Draw order (fixed, whatever the scene): obstacle side,
passing side, walking directions, start positions, slot draws u_k.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from functools import cache, lru_cache

import numpy as np
import pandas as pd

from ..errors import ConfigError, InputError, UnknownNameError
from ..hashing import stable_seed
from ..tables import PARAMS
from .scenes import (
    ROBOT_GOAL,
    ROBOT_START,
    SCENES,
    Layout,
    distance_to_walls,
    inside_polygon,
    layout,
    polygon_edges,
)

WIDTHS: tuple[float, ...] = (1.8, 2.4, 3.0, 4.2)  # [m]
DENSITIES: tuple[float, ...] = (0.06, 0.12, 0.20)  # [pedestrians / m² of walkable area]
ROBOT_SPEEDS: tuple[float, ...] = (0.6, 1.0)  # [m/s]
VARIANTS: tuple[int, ...] = (1, 2, 3)
PED_RADIUS = 0.25  # [m]
GOAL_BEYOND_EXIT = 2.0  # [m] goals lie past the exit line so nobody brakes before it
WALL_GAP = 0.05  # [m] minimal initial free space between a pedestrian and a wall
PED_GAP = 0.1  # [m] minimal initial free space between two pedestrians
OBSTACLE_GAP = 0.1  # [m] minimal initial free space between a pedestrian and an obstacle
VIA_GAP = 0.2  # [m] free space between a pedestrian passing at its via point and the obstacle
VIA_LEAD = 0.5  # [m] a via point lies this far past the obstacle; it is left this far before it
ROBOT_KEEP_OUT = 1.6  # [m] minimal initial centre distance pedestrian–robot (0.6 m of radii + 1 m)
HEAD_ON_X = (14.0, 20.0)  # [m] start range of the head-on pedestrian (route ≤ 20 m)
HEAD_ON_Y = 0.2  # [m] its lateral start offset is drawn in [−0.2, 0.2]
BATCH = 32  # candidate start positions drawn at once
MAX_BATCHES = 1000


@dataclass(frozen=True)
class Cell:
    """One physical cell; ``key`` reads like ``sidewalk-w1.8-d0.12-s0.6``."""

    scene: str
    width: float
    density: float
    robot_speed: float

    @property
    def key(self) -> str:
        return f"{self.scene}-w{self.width!r}-d{self.density!r}-s{self.robot_speed!r}"


@dataclass(frozen=True)
class EpisodeSpec:
    """Everything a run needs besides profiles, controller and backend (lengths in m).

    Pedestrian k walks in unit direction ``ped_directions[k]`` and has arrived
    once ``position · direction ≥ ped_exits[k]``; its navground goal is
    ``ped_goals[k]``, 2 m past that line. It heads first for ``ped_vias[k]``
    (beside an obstacle on its lane; equal to the goal when nothing blocks the
    lane) and for the goal once ``position · direction ≥ via · direction − 0.5``.
    ``passing_side`` (+1 left, −1 right of the walking direction) is the side
    pedestrians step to; ``slot_draws`` are
    the u_k ∈ [0, 1) that pick each slot's population member.
    """

    id: str
    scene: str
    width: float
    density: float
    robot_speed: float
    variant: int
    seed: int
    walls: tuple[tuple[float, float, float, float], ...]
    obstacles: tuple[tuple[float, float, float], ...]
    walkable_area: float
    robot_start: tuple[float, float]
    robot_goal: tuple[float, float]
    ped_starts: tuple[tuple[float, float], ...]
    ped_goals: tuple[tuple[float, float], ...]
    ped_vias: tuple[tuple[float, float], ...]
    ped_directions: tuple[tuple[float, float], ...]
    ped_exits: tuple[float, ...]
    passing_side: int
    slot_draws: tuple[float, ...]

    @property
    def n_peds(self) -> int:
        return len(self.ped_starts)

    @property
    def cell(self) -> Cell:
        return Cell(self.scene, self.width, self.density, self.robot_speed)

    def to_dict(self) -> dict:
        """Plain JSON-able dict (its :func:`popnavshift.hashing.digest` is the provenance)."""
        return asdict(self)


def all_cells() -> list[Cell]:
    """The 104 cells: 4 scenes × 4 widths × 3 densities × 2 speeds + head_on (lowest density)."""
    cells = []
    for scene in SCENES:
        densities = DENSITIES[:1] if scene == "head_on" else DENSITIES
        for width in WIDTHS:
            for density in densities:
                for speed in ROBOT_SPEEDS:
                    cells.append(Cell(scene, width, density, speed))
    return cells


def pedestrian_count(cell: Cell, area: float) -> int:
    """round(density × area), at least 1 (head_on: exactly 1); halves round up.

    ``area`` [m²] is the walkable area of the band a pedestrian starts in (the
    last 20 m of its route; both directions' bands have the same area).
    """
    if cell.scene == "head_on":
        return 1
    return max(1, math.floor(cell.density * area + 0.5))


def make_episode(cell: Cell, variant: int, seed: int = 0) -> EpisodeSpec:
    """Draw variant ``variant`` of ``cell`` under study ``seed``."""
    ep_seed = stable_seed(
        "episode", seed, cell.scene, cell.width, cell.density, cell.robot_speed, variant
    )
    rng = np.random.default_rng(ep_seed)
    obstacle_side = int(rng.choice([-1, 1]))
    passing_side = int(rng.choice([-1, 1]))
    lay = layout(cell.scene, cell.width, obstacle_side)
    n = pedestrian_count(cell, lay.walkable_area)
    if cell.scene == "head_on":
        signs = np.array([-1.0])
    else:  # balanced flows: ⌈n/2⌉ one way, ⌊n/2⌋ the other, which way gets ⌈⌉ drawn
        signs = rng.permutation(np.where(np.arange(n) < (n + 1) // 2, 1.0, -1.0))
        signs = signs * rng.choice([-1.0, 1.0])
    starts = _place(rng, lay, signs)
    slot_draws = rng.random(n)
    axis = np.zeros((n, 2))
    axis[:, lay.flow_axis] = 1.0
    directions = axis * signs[:, None] + 0.0  # + 0.0 turns −0.0 into 0.0
    exits = np.where(signs > 0, lay.exits[1], -lay.exits[0]) + 0.0
    goals = _goals(lay, starts, directions, exits)
    vias = _vias(lay, starts, signs, goals)
    return EpisodeSpec(
        id=f"{cell.key}-v{variant}",
        scene=cell.scene,
        width=cell.width,
        density=cell.density,
        robot_speed=cell.robot_speed,
        variant=variant,
        seed=ep_seed,
        walls=tuple((float(a), float(b), float(c), float(d)) for a, b, c, d in lay.walls),
        obstacles=tuple((float(x), float(y), float(r)) for x, y, r in lay.obstacles),
        walkable_area=round(lay.walkable_area, 6),
        robot_start=ROBOT_START,
        robot_goal=ROBOT_GOAL,
        ped_starts=_tuples(starts),
        ped_goals=_tuples(goals),
        ped_vias=_tuples(vias),
        ped_directions=_tuples(directions),
        ped_exits=tuple(float(e) for e in exits),
        passing_side=passing_side,
        slot_draws=tuple(float(u) for u in slot_draws),
    )


def _tuples(a: np.ndarray) -> tuple:
    return tuple((float(x), float(y)) for x, y in a)


def _goals(lay: Layout, starts, directions, exits) -> np.ndarray:
    """Goal = exit line + 2 m along the flow, same lateral coordinate as the start.

    In the bottleneck the lateral coordinate is clipped into the narrow section.
    """
    goals = starts.copy()
    ax = lay.flow_axis
    goals[:, ax] = directions[:, ax] * (exits + GOAL_BEYOND_EXIT)
    if lay.scene == "bottleneck":
        lim = lay.width / 2 - PED_RADIUS - 0.1
        goals[:, 1 - ax] = np.clip(goals[:, 1 - ax], -lim, lim)
    return goals


def _vias(lay: Layout, starts: np.ndarray, signs: np.ndarray, goals: np.ndarray) -> np.ndarray:
    """Via points routing pedestrians around an obstacle on their lane (else the goal).

    ORCA is a local planner and stalls behind a disc that sits on its straight
    line. A pedestrian whose lane passes within r_o + r_p + 0.2 m of an obstacle
    still ahead gets a via point beside the obstacle, on the side nearer its lane
    if that gap fits, otherwise on the other side, ``VIA_LEAD`` past the obstacle's
    far edge (it switches to its goal ``VIA_LEAD`` before the via point, so the
    via target is never reached and never brakes the pedestrian).
    """
    vias = goals.copy()
    half = lay.width / 2 - PED_RADIUS - WALL_GAP  # lateral limit of a pedestrian centre
    for ox, oy, r in lay.obstacles:
        offset = r + PED_RADIUS + VIA_GAP
        for k, sign in enumerate(signs):
            lane = goals[k, 1]
            if abs(lane - oy) >= offset or (ox - starts[k, 0]) * sign <= r:
                continue
            near = 1.0 if lane > oy or (lane == oy and oy < 0) else -1.0
            for side in (near, -near):
                if abs(oy + side * offset) <= half:
                    vias[k] = (ox + sign * (r + PED_RADIUS + VIA_LEAD), oy + side * offset)
                    break
    return vias


def _place(rng: np.random.Generator, lay: Layout, signs: np.ndarray) -> np.ndarray:
    """Rejection-sample non-overlapping start positions, one pedestrian at a time.

    Uniform over the scene's region within the pedestrian's band (the last 20 m
    before its exit); the head-on pedestrian starts in ``HEAD_ON_X`` × [−0.2, 0.2].
    Candidates come in batches of :data:`BATCH`; the first that keeps every gap is taken.
    """
    region = np.asarray(lay.region)
    lo, hi = region.min(axis=0), region.max(axis=0)
    placed = np.empty((0, 2))
    for sign in signs:
        box_lo, box_hi = lo.copy(), hi.copy()
        box_lo[lay.flow_axis], box_hi[lay.flow_axis] = lay.band(sign)
        if lay.scene == "head_on":
            box_lo = np.array([HEAD_ON_X[0], -HEAD_ON_Y])
            box_hi = np.array([HEAD_ON_X[1], HEAD_ON_Y])
        for _ in range(MAX_BATCHES):
            q = rng.uniform(box_lo, box_hi, size=(BATCH, 2))
            q = q[_static_ok(q, lay)]
            if len(placed):
                gaps = np.linalg.norm(q[:, None, :] - placed[None, :, :], axis=2)
                q = q[np.all(gaps >= 2 * PED_RADIUS + PED_GAP, axis=1)]
            if len(q):
                placed = np.vstack([placed, q[:1]])
                break
        else:
            raise InputError(f"{lay.scene} w={lay.width}: could not place {len(signs)} pedestrians")
    return placed


def _static_ok(q: np.ndarray, lay: Layout) -> np.ndarray:
    """Mask of candidates (n, 2) inside the region, clear of its edges, walls, obstacles, robot."""
    ok = inside_polygon(q, lay.region)
    boundary = [*lay.walls, *polygon_edges(lay.region)]  # region edges: e.g. the open corners
    ok &= distance_to_walls(q, boundary) >= PED_RADIUS + WALL_GAP
    for ox, oy, r in lay.obstacles:
        ok &= np.hypot(q[:, 0] - ox, q[:, 1] - oy) >= r + PED_RADIUS + OBSTACLE_GAP
    ok &= np.hypot(q[:, 0] - ROBOT_START[0], q[:, 1] - ROBOT_START[1]) >= ROBOT_KEEP_OUT
    return ok


@lru_cache(maxsize=8)
def _episodes(seed: int) -> tuple[EpisodeSpec, ...]:
    return tuple(make_episode(c, v, seed) for c in all_cells() for v in VARIANTS)


def all_episodes(seed: int = 0) -> list[EpisodeSpec]:
    """The 312 episodes of study ``seed``, ordered by cell (as :func:`all_cells`) then variant."""
    return list(_episodes(int(seed)))


#: An episode id may name another seed set: ``sidewalk-w1.8-d0.12-s0.6-v1@s2``.
SEED_SET_SEP = "@s"


def seed_set_id(episode_id: str, seed: int) -> str:
    """The id of ``episode_id`` drawn with study seed ``seed`` (a repeat of the variant)."""
    return f"{episode_id}{SEED_SET_SEP}{int(seed)}"


def seed_set_of(episode_id: str, study_seed: int = 0) -> int:
    """The seed set an episode id was drawn with: ``k`` for ``…@s<k>``, else the study's."""
    base, sep, seed_text = episode_id.partition(SEED_SET_SEP)
    return int(seed_text) if sep and seed_text.isdigit() else int(study_seed)


def get_episode(episode_id: str, seed: int = 0) -> EpisodeSpec:
    """The episode called ``episode_id`` (e.g. ``sidewalk-w1.8-d0.12-s0.6-v1``).

    A suffix ``@s<k>`` draws the same cell and variant with study seed ``k`` instead of
    ``seed`` (the seed sets of a study part, SPEC §8 robustness).
    """
    base, sep, seed_text = episode_id.partition(SEED_SET_SEP)
    if sep:
        if not seed_text.isdigit():
            raise ConfigError(f"episode {episode_id!r}: seed set must be {SEED_SET_SEP}<integer>")
        episode_id, seed = base, int(seed_text)
    known = _episode_cells()
    if episode_id not in known:
        raise UnknownNameError("episode", episode_id, known)
    cell, variant = known[episode_id]
    return make_episode(cell, variant, int(seed))


@cache
def _episode_cells() -> dict[str, tuple[Cell, int]]:
    """Episode id (without seed set) → (cell, variant); built once per process."""
    return {f"{c.key}-v{v}": (c, v) for c in all_cells() for v in VARIANTS}


def episodes_table(episodes) -> pd.DataFrame:
    """One row per episode: id, scene, width, density, robot_speed, variant, n_peds, seed."""
    return pd.DataFrame(
        {
            "id": [e.id for e in episodes],
            "scene": [e.scene for e in episodes],
            "width": np.array([e.width for e in episodes], dtype=float),
            "density": np.array([e.density for e in episodes], dtype=float),
            "robot_speed": np.array([e.robot_speed for e in episodes], dtype=float),
            "variant": np.array([e.variant for e in episodes], dtype=np.int64),
            "n_peds": np.array([e.n_peds for e in episodes], dtype=np.int64),
            "seed": np.array([e.seed for e in episodes], dtype=np.int64),
        }
    )


def assign_slots(spec: EpisodeSpec, members: pd.DataFrame) -> pd.DataFrame:
    """Slot k gets member ⌊u_k · n⌋ of ``members`` sorted by persona_id (SPEC §5).

    ``members`` are one population's rows (columns persona_id and the 7 PARAMS;
    others are carried along). Returns one row per slot, ``slot`` first.
    """
    missing = [c for c in ("persona_id", *PARAMS) if c not in members.columns]
    if missing:
        raise InputError(f"population members: missing column(s) {', '.join(missing)}")
    if "population" in members.columns and members["population"].nunique() > 1:
        raise InputError(
            "population members: expected one population, got "
            f"{sorted(members['population'].unique())}"
        )
    if members.empty:
        raise InputError("population members: the table is empty")
    ordered = members.sort_values("persona_id", kind="stable").reset_index(drop=True)
    out = ordered.iloc[slot_members(spec, len(ordered))].reset_index(drop=True)
    out.insert(0, "slot", np.arange(spec.n_peds, dtype=np.int64))
    return out


def slot_members(spec: EpisodeSpec, n_members: int) -> np.ndarray:
    """(n_peds,) index of each slot's member among ``n_members`` sorted by persona_id:
    ⌊u_k · n⌋ (see :func:`assign_slots`)."""
    u = np.asarray(spec.slot_draws, dtype=float)
    return np.minimum((u * n_members).astype(np.int64), n_members - 1)


__all__ = [
    "Cell",
    "EpisodeSpec",
    "all_cells",
    "all_episodes",
    "assign_slots",
    "episodes_table",
    "get_episode",
    "make_episode",
    "slot_members",
]
