"""Where the full stack's time goes: a cProfile pass grouped into categories.

:func:`profile_full_stack` profiles :func:`.run.simulate` over a bench sample and
groups self times by :data:`CATEGORY_RULES` (world build, navground update,
response layer, robot controller, loop bookkeeping, metrics, result tables); see
:func:`profile_categories` for how functions that match no rule are shared out.
"""

from __future__ import annotations

import cProfile
import pstats
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

from navground import sim

from .run import simulate

TOP_ENTRIES = 12  # functions listed in the profile summary


#: (category, file suffix or "" for builtins, function names); first match wins; an
#: empty set of names matches every function of files under that path.
#: Functions matching none inherit their callers' categories (see profile_categories).
CATEGORY_RULES: tuple[tuple[str, str, frozenset[str]], ...] = (
    ("world build", "sim/world.py", frozenset({"build_world"})),
    ("world build", "sim/run.py", frozenset({"resolve_controller"})),
    ("world build", "sim/slots.py", frozenset({"slot_profiles"})),
    ("world build", "sim/pedestrians.py", frozenset({"__init__"})),
    ("navground update (C++)", "sim/bench_profile.py", frozenset({"_world_update"})),
    # World.run of a quiet stretch (its recording callback included, see sim/quiet.py)
    ("navground update (C++)", "~",
     frozenset({"<built-in method navground.sim._navground_sim.run>"})),
    ("response layer kernel", "sim/quiet.py", frozenset({"replay_quiet"})),
    ("loop bookkeeping", "sim/quiet.py", frozenset({"quiet_steps", "robot_touched"})),
    ("loop bookkeeping", "sim/loop.py", frozenset({"_stretch"})),
    # the per-step numba kernel: pose copy, exits, goal entry and the response layer
    ("response layer kernel", "sim/pedestrians.py", frozenset({"_respond", "advance"})),
    # … and, with a loop driver, the same kernel followed by the driver's sensing
    ("response layer kernel", "sim/loop.py", frozenset({"advance_driven"})),
    ("response layer writes", "sim/pedestrians.py", frozenset({"step", "write"})),
    ("robot controller (Python)", "", frozenset({"compute_cmd_internal"})),
    ("robot controller (Python)", "sim/loop.py", frozenset({"_drive"})),
    ("robot controller (Python)", "sim/controllers/", frozenset()),
    ("metrics", "sim/metrics.py", frozenset()),
    ("loop bookkeeping", "sim/loop.py",
     frozenset({"execute", "_robot_contacts", "_robot_arrived"})),
    ("loop bookkeeping", "sim/pedestrians.py", frozenset({"crossed_exit"})),
    ("loop bookkeeping", "sim/world.py", frozenset({"remove_agent", "stop_agent"})),
    ("result tables", "sim/run.py", frozenset({"simulate"})),
)


def _rule(func: tuple[str, int, str]) -> str | None:
    filename, _, name = func
    path = filename.replace("\\", "/")
    for category, suffix, names in CATEGORY_RULES:
        if names and name in names and path.endswith(suffix):
            return category
        if not names and f"/{suffix}" in path:
            return category
    return None


def profile_categories(stats: pstats.Stats) -> dict[str, float]:
    """Self time [s] per category; unmatched functions split by caller edge.

    cProfile records, per caller, how much of a function's self time was spent
    under that caller; a function matching no :data:`CATEGORY_RULES` entry
    passes that time on to its callers' categories (one level of context, as
    cProfile keeps no more). Functions without callers go to "other".
    """
    table = stats.stats  # type: ignore[attr-defined]  # pstats keeps it undocumented
    memo: dict[tuple, dict[str, float]] = {}

    def mix(func: tuple, seen: frozenset) -> dict[str, float]:
        """Category shares (summing to 1) of ``func``'s self time."""
        if func in memo:
            return memo[func]
        own = _rule(func)
        callers = table[func][4] if func in table else {}
        if own is not None or not callers or func in seen:
            return {own or "other": 1.0}
        total = sum(edge[2] for edge in callers.values()) or float(len(callers))
        out: dict[str, float] = {}
        for caller, edge in callers.items():
            weight = (edge[2] or (0.0 if total != len(callers) else 1.0)) / total
            for cat, share in mix(caller, seen | {func}).items():
                out[cat] = out.get(cat, 0.0) + weight * share
        memo[func] = out
        return out

    result: dict[str, float] = {}
    for func, (_, _, tt, _, _) in table.items():
        for cat, share in mix(func, frozenset()).items():
            result[cat] = result.get(cat, 0.0) + tt * share
    return dict(sorted(result.items(), key=lambda kv: -kv[1]))


def _label(func: tuple[str, int, str]) -> str:
    filename, line, name = func
    if filename == "~":
        return name
    short = filename.replace("\\", "/").split("/site-packages/")[-1].split("/src/")[-1]
    return f"{short}:{line}({name})"


@contextmanager
def _visible_world_update() -> Iterator[None]:
    """Route ``World.update`` through a Python function while profiling.

    cProfile keys C functions by name: pybind11's ``World.update`` and
    ``ExperimentalRun.update`` collide, and half the calls with their time end
    up in the caller's self time. A Python wrapper gets its own entry; its self
    time is navground's step (plus the trampolines into Python controllers).
    """
    native = sim.World.update

    def _world_update(self: sim.World, time_step: float) -> None:
        native(self, time_step)

    setattr(sim.World, "update", _world_update)  # noqa: B010  (shadows the inherited method)
    try:
        yield
    finally:
        delattr(sim.World, "update")


def profile_full_stack(specs, slots, conditions, backends) -> dict[str, Any]:
    """cProfile the full stack once over the sample; ms per run by category and top functions."""
    per_condition: dict[str, dict[str, float]] = {}
    combined: pstats.Stats | None = None
    n_total = 0
    for condition in conditions:
        prof = cProfile.Profile()
        with _visible_world_update():
            for spec in specs:
                for backend in backends:
                    prof.enable()
                    simulate(spec, slots[spec.id], condition, backend)
                    prof.disable()
        n = len(specs) * len(backends)
        stats = pstats.Stats(prof)
        per_condition[condition] = {c: 1e3 * t / n
                                    for c, t in profile_categories(stats).items()}
        n_total += n
        if combined is None:
            combined = stats
        else:
            combined.add(stats)
    assert combined is not None
    table = combined.stats  # type: ignore[attr-defined]
    top = sorted(table.items(), key=lambda kv: -kv[1][2])[:TOP_ENTRIES]
    total = sum(v[2] for v in table.values())
    return {
        "runs": n_total,
        "profiled_ms": 1e3 * total / n_total,
        "categories": {c: 1e3 * t / n_total for c, t in profile_categories(combined).items()},
        "per_condition": per_condition,
        "top": [{"function": _label(f), "ms": 1e3 * v[2] / n_total,
                 "calls": v[1] / n_total, "share": v[2] / total} for f, v in top],
    }


__all__ = ["CATEGORY_RULES", "profile_categories", "profile_full_stack"]
