"""Speed of the full simulation stack against bare navground on the same worlds.

``run_bench(n_per_scene, seed, repeats, profile)`` → :class:`BenchResult` with one
row per condition (controller × backend) and an overall summary; the target is a
full stack within :data:`TARGET_RATIO` × bare navground.

* **Sample** (:func:`bench_sample`): ``n_per_scene`` episodes of each of the five
  scenes. Pick k of a scene cycles every factor independently: width
  ``WIDTHS[r mod 4]``, density ``densities[r mod n_d]``, robot speed
  ``speeds[(r + c) mod 2]``, variant ``VARIANTS[(r + c) mod 3]`` with
  r = k mod (4·n_d), c = k div (4·n_d). Consecutive picks differ in every factor,
  and picks 0 … N−1 enumerate all N episodes of the scene without repetition.
* **Full stack**: :func:`popnavshift.sim.run.simulate` (world build, response
  layer, robot controller, loop bookkeeping, metrics and per-run result columns) with the
  slots of a synthetic population (:data:`POPULATION_SIZE` members, profiles
  uniform over ``PARAM_RANGES``, drawn from ``seed``; slots assigned outside the
  timing, as the :class:`~popnavshift.sim.slots.SlotProfiles` a study worker
  builds once per population and batch).
* **Bare navground**: the same world (:func:`.world.build_world`: walls,
  obstacles, starts, speeds, radii, pedestrian behaviours) with no Python during
  the run: every robot condition gets the native C++ ``robot_orca``, pedestrians
  follow their via point and goal with a C++ ``WaypointsTask`` instead of the
  response layer, and ``world.run(steps, 0.1)`` does exactly as many steps as
  the full run of the same condition did. Matching the step count instead of
  re-implementing the early exit (which needs Python every step) makes the ratio
  the cost of the same number of navground updates with and without our layer.
  Bare worlds keep arrived agents standing at their goals (the full stack
  removes them), which makes bare navground slower (measured on this sample:
  2.7 vs 2.1 ms per 400 ORCA steps), so the ratios err in the full stack's favour.
* **Timing**: numba kernels are warmed up first; each full run is followed by its
  bare run (which needs the full run's step count), so machine load hits both;
  with ``repeats`` > 1 each episode's median is kept. Times include world build.
* **Profile** (``profile=True``): a separate cProfile pass over the full stack
  (cProfile inflates Python-heavy parts), its self-times grouped by
  :func:`.bench_profile.profile_categories`.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd
from navground import sim

from ..episodes import SCENES, VARIANTS, Cell, EpisodeSpec, all_cells, assign_slots, make_episode
from ..errors import ConfigError
from ..hashing import stable_seed
from ..tables import PARAM_RANGES, PARAMS
from .backends import BACKENDS
from .bench_profile import profile_full_stack
from .constants import DT
from .controllers import CONTROLLERS
from .controllers.builtin import BUILTINS
from .run import simulate
from .slots import SlotProfiles, slot_profiles
from .world import build_world

TARGET_RATIO = 1.3  # full stack within this factor of bare navground, overall (issue #15)
PART_TARGET_RATIO = 2.0  # … and within this one in every condition and every scene
CONDITIONS: tuple[str, ...] = ("none", *BUILTINS)  # no robot, then the built-ins
BACKEND_NAMES: tuple[str, ...] = ("orca", "hl")
POPULATION_SIZE = 64  # members of the synthetic population
VIA_TOLERANCE = 0.5  # [m] bare pedestrians switch to their goal this close to the via point


@dataclass
class BenchResult:
    """``table``: one row per condition × backend; ``summary``: overall figures.

    ``runs`` has one row per timed run (episode, condition, backend, repeat,
    steps, full_ms, bare_ms).
    """

    table: pd.DataFrame
    summary: dict[str, Any]
    runs: pd.DataFrame = field(repr=False)


def bench_sample(n_per_scene: int = 3, seed: int = 0,
                 scenes: tuple[str, ...] = SCENES) -> list[EpisodeSpec]:
    """The fixed stratified sample: ``n_per_scene`` episodes per scene (see module doc)."""
    unknown = [s for s in scenes if s not in SCENES]
    if unknown:
        raise ConfigError(f"unknown scene(s) {unknown}; known: {', '.join(SCENES)}")
    out = []
    for scene in scenes:
        cells = [c for c in all_cells() if c.scene == scene]
        widths = sorted({c.width for c in cells})
        densities = sorted({c.density for c in cells})
        speeds = sorted({c.robot_speed for c in cells})
        total = len(cells) * len(VARIANTS)
        if not 1 <= n_per_scene <= total:
            raise ConfigError(f"n_per_scene must be in [1, {total}] for {scene}, "
                              f"got {n_per_scene}")
        block = len(widths) * len(densities)
        for k in range(n_per_scene):
            r, c = k % block, k // block
            cell = Cell(scene, widths[r % len(widths)], densities[r % len(densities)],
                        speeds[(r + c) % len(speeds)])
            out.append(make_episode(cell, VARIANTS[(r + c) % len(VARIANTS)], seed))
    return out


def synthetic_population(seed: int = 0, size: int = POPULATION_SIZE) -> pd.DataFrame:
    """``size`` members with profiles uniform over ``PARAM_RANGES`` (columns persona_id, PARAMS)."""
    rng = np.random.default_rng(stable_seed("bench-population", seed))
    members = pd.DataFrame({"persona_id": [f"bench{i:03d}" for i in range(size)]})
    for p in PARAMS:
        lo, hi = PARAM_RANGES[p]
        members[p] = rng.uniform(lo, hi, size)
    return members


def bare_world(spec: EpisodeSpec, speeds: np.ndarray, backend: str,
               robot: bool) -> sim.World:
    """``spec``'s world with C++ components only: C++ ORCA robot, WaypointsTask routes."""
    controller = CONTROLLERS.make("robot_orca") if robot else None
    sw = build_world(spec, speeds, controller, BACKENDS.make(backend))
    for agent, via, goal in zip(sw.peds, spec.ped_vias, spec.ped_goals, strict=True):
        waypoints = [via, goal] if via != goal else [goal]
        agent.task = sim.tasks.WaypointsTask(waypoints=waypoints, loop=False,
                                             tolerance=VIA_TOLERANCE)
    return sw.world


def _time_full(spec: EpisodeSpec, slots: SlotProfiles, condition: str,
               backend: str) -> tuple[float, int]:
    t0 = time.perf_counter_ns()
    result = simulate(spec, slots, condition, backend)
    return (time.perf_counter_ns() - t0) * 1e-6, int(result.run["steps"])


def _time_bare(spec: EpisodeSpec, speeds: np.ndarray, condition: str, backend: str,
               steps: int) -> float:
    t0 = time.perf_counter_ns()
    world = bare_world(spec, speeds, backend, condition != "none")
    world.run(steps, DT)
    return (time.perf_counter_ns() - t0) * 1e-6


def _study_slots(spec: EpisodeSpec, population: pd.DataFrame) -> SlotProfiles:
    """The slots of ``spec`` in the form a study worker passes them to ``simulate``
    (built once per population and batch there, so outside the timing here)."""
    values, ids = slot_profiles(spec, assign_slots(spec, population))
    return SlotProfiles(values, ids)


def _warm_up(spec: EpisodeSpec, slots: SlotProfiles, conditions, backends) -> None:
    """Load (or compile) every numba kernel and import every module before timing."""
    speeds = slots.values[:, 0]
    for condition in conditions:
        for backend in backends:
            simulate(spec, slots, condition, backend)
            bare_world(spec, speeds, backend, condition != "none").run(20, DT)


def run_bench(
    n_per_scene: int = 3,
    seed: int = 0,
    repeats: int = 1,
    profile: bool = False,
    *,
    conditions: tuple[str, ...] = CONDITIONS,
    backends: tuple[str, ...] = BACKEND_NAMES,
    scenes: tuple[str, ...] = SCENES,
) -> BenchResult:
    """Time the full stack and bare navground on :func:`bench_sample` episodes.

    Every episode runs once per condition × backend and repeat (full and bare
    interleaved). ``table``: condition, backend, episodes, steps (mean),
    full_ms / bare_ms (mean per episode [ms]), full_eps / bare_eps (episodes/s),
    ratio (full / bare). ``summary``: the same overall, the target and, with
    ``profile``, the cProfile breakdown of the full stack. ``conditions``,
    ``backends`` and ``scenes`` restrict the grid (quick checks, tests).
    """
    if repeats < 1:
        raise ConfigError(f"repeats must be >= 1, got {repeats}")
    unknown = [c for c in conditions if c not in CONDITIONS]
    unknown += [b for b in backends if b not in BACKEND_NAMES]
    if unknown:
        raise ConfigError(f"unknown bench condition or backend {unknown}; "
                          f"known: {', '.join(CONDITIONS + BACKEND_NAMES)}")
    specs = bench_sample(n_per_scene, seed, scenes)
    population = synthetic_population(seed)
    slots = {s.id: _study_slots(s, population) for s in specs}
    _warm_up(specs[0], slots[specs[0].id], conditions, backends)
    rows = []
    for rep in range(repeats):
        for spec in specs:
            speeds = slots[spec.id].values[:, 0]
            for condition in conditions:
                for backend in backends:
                    full_ms, steps = _time_full(spec, slots[spec.id], condition, backend)
                    bare_ms = _time_bare(spec, speeds, condition, backend, steps)
                    rows.append((spec.id, spec.scene, condition, backend, rep, steps,
                                 full_ms, bare_ms))
    runs = pd.DataFrame(rows, columns=["episode", "scene", "condition", "backend", "repeat",
                                       "steps", "full_ms", "bare_ms"])
    table, summary = _aggregate(runs, conditions, backends)
    if profile:
        summary["profile"] = profile_full_stack(specs, slots, conditions, backends)
    return BenchResult(table, summary, runs)


def _aggregate(runs: pd.DataFrame, conditions, backends) -> tuple[pd.DataFrame, dict[str, Any]]:
    """Per-episode medians over repeats, then means per condition × backend and overall."""
    per_ep = runs.groupby(["episode", "scene", "condition", "backend"], sort=False).agg(
        steps=("steps", "first"), full_ms=("full_ms", "median"), bare_ms=("bare_ms", "median")
    ).reset_index()
    rows = []
    for condition in conditions:
        for backend in backends:
            sel = per_ep[(per_ep["condition"] == condition) & (per_ep["backend"] == backend)]
            rows.append({"condition": condition, "backend": backend, **_rates(sel)})
    table = pd.DataFrame(rows)
    summary: dict[str, Any] = {
        **_rates(per_ep),
        "target_ratio": TARGET_RATIO,
        "by_scene": {s: _rates(g) for s, g in per_ep.groupby("scene", sort=False)},
        "by_condition": {c: _rates(g) for c, g in per_ep.groupby("condition", sort=False)},
        "sample": list(dict.fromkeys(runs["episode"])),
        "repeats": int(runs["repeat"].max()) + 1,
    }
    parts = {**{f"condition {k}": v for k, v in summary["by_condition"].items()},
             **{f"scene {k}": v for k, v in summary["by_scene"].items()}}
    worst = max(parts, key=lambda k: parts[k]["ratio"])
    summary["worst_part"] = {"name": worst, "ratio": parts[worst]["ratio"]}
    summary["part_target_ratio"] = PART_TARGET_RATIO
    summary["within_target"] = bool(summary["ratio"] <= TARGET_RATIO
                                    and parts[worst]["ratio"] <= PART_TARGET_RATIO)
    return table, summary


def _rates(df: pd.DataFrame) -> dict[str, Any]:
    """episodes, mean steps, mean ms per episode, episodes/s and full/bare ratio of ``df``."""
    full, bare = float(df["full_ms"].mean()), float(df["bare_ms"].mean())
    return {"episodes": len(df), "steps": float(df["steps"].mean()), "full_ms": full,
            "bare_ms": bare, "full_eps": 1e3 / full, "bare_eps": 1e3 / bare,
            "ratio": full / bare}


def format_bench(result: BenchResult) -> str:
    """Plain-text report: the condition table, overall figures, scenes and the profile."""
    s = result.summary
    lines = [f"{'condition':<12} {'backend':<7} {'eps':>4} {'steps':>6} {'full ms':>8} "
             f"{'bare ms':>8} {'full ep/s':>9} {'bare ep/s':>9} {'ratio':>6}"]
    for r in result.table.itertuples():
        lines.append(f"{r.condition:<12} {r.backend:<7} {r.episodes:>4d} {r.steps:>6.0f} "
                     f"{r.full_ms:>8.2f} {r.bare_ms:>8.2f} {r.full_eps:>9.1f} "
                     f"{r.bare_eps:>9.1f} {r.ratio:>6.2f}")
    verdict = "within" if s["within_target"] else "OVER"
    lines.append(f"{'overall':<20} {s['episodes']:>4d} {s['steps']:>6.0f} {s['full_ms']:>8.2f} "
                 f"{s['bare_ms']:>8.2f} {s['full_eps']:>9.1f} {s['bare_eps']:>9.1f} "
                 f"{s['ratio']:>6.2f}")
    lines.append(f"target: {s['target_ratio']}x overall and {s['part_target_ratio']}x in every "
                 f"condition and scene; worst: {s['worst_part']['name']} "
                 f"{s['worst_part']['ratio']:.2f}x ({verdict})")
    lines.append("by condition: " + ", ".join(
        f"{k} {v['ratio']:.2f}x" for k, v in s["by_condition"].items()))
    lines.append("")
    lines.append("by scene: " + ", ".join(
        f"{k} {v['full_ms']:.1f}/{v['bare_ms']:.1f} ms ({v['ratio']:.2f}x)"
        for k, v in s["by_scene"].items()))
    if "profile" in s:
        p = s["profile"]
        lines.append("")
        lines.append(f"profile (cProfile, {p['runs']} full runs, {p['profiled_ms']:.2f} ms/run "
                     "under the profiler):")
        for cat, ms in p["categories"].items():
            lines.append(f"  {cat:<24} {ms:>7.2f} ms/run  {ms / p['profiled_ms']:>6.1%}")
        lines.append("  per condition [ms/run]: " + "; ".join(
            f"{c}: " + ", ".join(f"{k} {v:.2f}" for k, v in list(cats.items())[:3])
            for c, cats in p["per_condition"].items()))
        lines.append("  top functions by self time:")
        for e in p["top"]:
            lines.append(f"    {e['ms']:>7.3f} ms/run {e['calls']:>7.0f} calls/run  "
                         f"{e['function']}")
    return "\n".join(lines)


__all__ = [
    "CONDITIONS",
    "TARGET_RATIO",
    "BenchResult",
    "bare_world",
    "bench_sample",
    "format_bench",
    "run_bench",
    "synthetic_population",
]
