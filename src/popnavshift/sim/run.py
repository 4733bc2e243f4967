"""Simulate one episode: the stepping loop, the robot's outcome and the run's metrics.

``simulate(spec, slots, controller, backend)`` → :class:`SimResult` with one run row
and one row per pedestrian (SPEC §6–7). The loop steps navground at ``DT`` for at
most 45 s and stops early once the robot is done (or absent) and every pedestrian
has left the scene. Outcome = the robot's first event:

* ``success``: within 0.3 m of its goal; the robot then leaves the scene;
* ``pedestrian_collision`` / ``world_collision``: a new robot contact with a
  pedestrian / a wall or obstacle (both in one step counts as pedestrian); the
  robot then stops in place and pedestrians carry on;
* ``timeout``: none of these within 45 s;
* ``controller_error``: the controller raised (:class:`ControllerError`); recorded by
  the study engine with :func:`failed_result`, not by :func:`simulate`.

Without a robot the outcome is ``none`` and robot metrics are NaN.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Any, cast

import numpy as np
import pandas as pd
from navground import sim

from ..episodes.specs import EpisodeSpec
from ..errors import ConfigError, PopNavShiftError
from ..tables import PARAMS, PEDESTRIAN_METRICS
from .backends import BACKENDS
from .constants import DT, ROBOT_RADIUS, TIME_LIMIT
from .controllers import CONTROLLERS, LoopDriver
from .loop import StepLoop
from .metrics import pedestrian_metrics, robot_metrics
from .pedestrians import ResponseLayer
from .quiet import NotQuiet
from .slots import SlotProfiles, slot_profiles
from .trace import Trace
from .world import SimWorld, build_world


@dataclass
class SimResult:
    """``run``: one row (dict); ``ped_columns``: one row per slot, as columns;
    ``trajectory``: replay arrays. :attr:`pedestrians` is the DataFrame of
    ``ped_columns``; the study engine joins the columns of a whole batch into one
    table instead (:func:`pedestrian_table`), a DataFrame per run costs ~1 ms."""

    run: dict
    ped_columns: dict
    trajectory: dict | None = None

    @functools.cached_property
    def pedestrians(self) -> pd.DataFrame:
        return pedestrian_table([self.ped_columns])


def pedestrian_table(columns: list[dict], keys: dict[str, list] | None = None) -> pd.DataFrame:
    """One DataFrame from the ``ped_columns`` of several runs, plus ``keys``: extra
    columns with one value per run (repeated over its pedestrians)."""
    sizes = [len(c["slot"]) for c in columns]
    table: dict[str, Any] = {}
    for name in columns[0] if columns else _PED_COLUMNS:
        parts = [c[name] for c in columns]
        if name in _PER_RUN:
            table[name] = pd.Series(np.repeat(np.array(parts, dtype=object), sizes), dtype=str)
        elif name == "persona_id":
            table[name] = pd.Series([x for part in parts for x in part], dtype=str)
        else:
            table[name] = np.concatenate(parts) if parts else np.empty(0)
    for name, values in (keys or {}).items():
        array = np.asarray(values)  # ints stay int64 (seed_set); text stays Python str
        table[name] = np.repeat(array.astype(object) if array.dtype.kind in "US" else array, sizes)
    return pd.DataFrame(table)


def simulate(
    spec: EpisodeSpec,
    slots: pd.DataFrame | SlotProfiles | None,
    controller,
    backend: str = "orca",
    *,
    record: bool = False,
    stretches: bool = True,
) -> SimResult:
    """Run ``spec`` with slot profiles ``slots`` (see :func:`episodes.assign_slots`).

    ``slots`` None gives every pedestrian the mid-range profile; a
    :class:`SlotProfiles` is used as it is. ``controller`` is a
    controller id (see :func:`resolve_controller`), a ControllerFactory, or
    None/"none" for the no-robot baseline. ``record`` adds a trajectory for replays.
    ``stretches`` False steps every step from Python (:mod:`.quiet` lets navground
    run the steps that need nothing from the loop; the results are the same).
    Raises :class:`ControllerError` when the controller raises (see
    :func:`failed_result` for the row a study records instead).
    """
    profiles, persona_ids = slot_profiles(spec, slots)
    factory, controller_name = resolve_controller(controller)
    ped_backend = BACKENDS.make(backend)
    try:
        trace = _run(spec, profiles, factory, controller_name, ped_backend, record,
                     stretches=stretches and not record)
    except NotQuiet:  # a quiet stretch was not: the run again, step by step
        trace = _run(spec, profiles, factory, controller_name, ped_backend, record,
                     stretches=False)
    run = {
        **_episode_columns(spec),
        "controller": controller_name,
        "backend": backend,
        "outcome": trace.outcome,
        **robot_metrics(trace),
        "peds_arrived": int(np.sum(trace.arrival_step >= 0)),
        "steps": trace.steps,
    }
    peds = _pedestrian_columns(spec, controller_name, backend, trace, profiles, persona_ids)
    return SimResult(run, peds, trace.trajectory(spec) if record else None)


def _run(spec: EpisodeSpec, profiles: np.ndarray, factory, controller_name: str,
         ped_backend, record: bool, stretches: bool) -> Trace:
    """Build the run's world and step it; a controller's exception becomes a
    :class:`ControllerError`."""
    sw: SimWorld | None = None
    driver: LoopDriver | None = None
    try:
        if hasattr(factory, "loop_driver"):
            driver = factory.loop_driver()
        sw = build_world(spec, profiles[:, 0], driver or factory, ped_backend)
        if driver is not None:  # navground hands behaviours its float32 time step
            driver.start(cast(sim.Agent, sw.robot), sw.world, float(np.float32(DT)))
        layer = ResponseLayer(sw.ped_behaviors, spec, profiles, ROBOT_RADIUS)
        return StepLoop(spec, sw, layer, driver, record, stretches).execute()
    except NotQuiet:
        raise
    except Exception as exc:
        robot = sw.robot_behavior if sw is not None else None
        blamed = _blame_controller(exc, controller_name, (factory, robot, driver))
        if blamed is None:
            raise
        raise blamed from exc
    finally:  # the recording callback (see StepLoop.execute) would keep world and run alive:
        if sw is not None:  # a reference cycle through C++ that Python cannot collect
            sw.world.reset_callbacks()


def _episode_columns(spec: EpisodeSpec) -> dict:
    return {
        "episode": spec.id,
        "scene": spec.scene,
        "width": spec.width,
        "density": spec.density,
        "robot_speed": spec.robot_speed,
        "variant": spec.variant,
        "n_peds": spec.n_peds,
    }


_PER_RUN = ("episode", "controller", "backend")  # one value per run in ped_columns
_PED_COLUMNS = (*_PER_RUN, "slot", "persona_id", *(c.name for c in PEDESTRIAN_METRICS),
                *PARAMS)


def _pedestrian_columns(spec: EpisodeSpec, controller: str, backend: str, trace: Trace,
                        profiles: np.ndarray, persona_ids: list[str]) -> dict:
    """The run's pedestrian rows as columns (see :func:`pedestrian_table`)."""
    columns = {
        "episode": spec.id,
        "controller": controller,
        "backend": backend,
        "slot": np.arange(len(persona_ids), dtype=np.int64),
        "persona_id": persona_ids,
        **pedestrian_metrics(trace),
        **{p: profiles[:, j] for j, p in enumerate(PARAMS)},
    }
    assert tuple(columns) == _PED_COLUMNS
    return columns


def resolve_controller(controller):
    """(factory or None, name) for a controller id (a registered name, an entry point or
    ``package.module:Class``, optionally with JSON parameters; see
    :mod:`popnavshift.sim.controllers.registry`), a factory object, or None/"none"."""
    if controller is None or controller == "none":
        return None, "none"
    if isinstance(controller, str):
        return CONTROLLERS.make(controller), controller
    if not (hasattr(controller, "build") and hasattr(controller, "after_placement")):
        raise ConfigError(
            "controller must be a name, a ControllerFactory or None, "
            f"got {type(controller).__name__}"
        )
    return controller, str(getattr(controller, "name", type(controller).__name__))


class ControllerError(PopNavShiftError):
    """The robot's controller raised while it was built, placed or stepped."""


def _blame_controller(exc: Exception, controller_name: str,
                      suspects: tuple) -> ControllerError | None:
    """A ControllerError for ``exc`` if a method of one of ``suspects`` (the
    controller factory, the robot's behaviour) is on its traceback; else None:
    the error is ours and must crash. Configuration errors are never a run outcome."""
    if isinstance(exc, PopNavShiftError):
        return None
    blamed, step = False, None
    tb = exc.__traceback__
    while tb is not None:
        owner = tb.tb_frame.f_locals.get("self")
        blamed = blamed or any(owner is s for s in suspects if s is not None)
        if isinstance(owner, StepLoop) and "step" in tb.tb_frame.f_locals:
            step = tb.tb_frame.f_locals["step"]
        tb = tb.tb_next
    if not blamed:
        return None
    when = "while building the robot" if step is None else f"at t = {step * DT:.1f} s"
    return ControllerError(
        f"controller {controller_name!r} raised {type(exc).__name__} {when}: {exc}")


def failed_result(spec: EpisodeSpec, controller: str, backend: str) -> SimResult:
    """The result recorded for a run whose controller raised: outcome
    ``controller_error``, robot time the 45 s of a failure, other robot metrics NaN,
    no pedestrian rows (their run did not finish)."""
    empty = Trace(0, np.zeros((1, 0, 2)), 0, np.zeros(0, np.int64), np.ones(0), False)
    run = {
        **_episode_columns(spec),
        "controller": controller,
        "backend": backend,
        "outcome": "controller_error",
        **robot_metrics(empty),
        "robot_time": TIME_LIMIT,
        "peds_arrived": 0,
        "steps": 0,
    }
    peds = _pedestrian_columns(spec, controller, backend, empty, np.zeros((0, len(PARAMS))), [])
    return SimResult(run, peds)


