"""Code stamps: which code a run executes, so that edited code is never reused.

A batch's id hashes the code stamps of the controllers it runs
(:func:`popnavshift.engine.batches.batches`), and the compacted tables record them
(:meth:`popnavshift.engine.store.RunStore.carried`): a change to the simulator or
to a controller's module reruns exactly the runs that execute it.
"""

from __future__ import annotations

import functools
import hashlib
import inspect
import sys
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import navground

from ..hashing import digest
from ..sim.controllers import CONTROLLERS
from ..tables import NO_ROBOT

#: modules under sim/ that are not the simulation: the benchmark and the contract check,
#: which no run executes, and the controller registry's wiring (the registry, the list of
#: built-ins, the package's protocols), which names and finds a controller: what a run
#: executes of a controller is its own module and description, in its own stamp
#: (:func:`controller_stamp`), so renaming or registering one reruns nothing else
_NOT_SIMULATION = frozenset({"sim/bench.py", "sim/bench_profile.py", "sim/check.py",
                             "sim/controllers/registry.py", "sim/controllers/builtin.py",
                             "sim/controllers/__init__.py"})
_PACKAGE = Path(__file__).resolve().parents[1]


def controller_stamp(factory: Any) -> str:
    """Hash of a controller's ``describe()`` and the source of the module defining its
    behaviour class (or factory). Code in other modules it imports is not covered."""
    cls = getattr(factory, "cls", type(factory))
    try:
        source = inspect.getsource(sys.modules[cls.__module__])
    except (KeyError, TypeError, OSError):  # no source: a compiled or interactive class
        source = ""
    return digest([factory.describe(), source])


@functools.cache
def simulator_stamp() -> str:
    """Hash of the simulator's own code (``popnavshift.sim`` with the built-in
    controllers, ``popnavshift.episodes``) and navground's version: a change to
    either makes every stored run stale."""
    files = sorted(p for sub in ("sim", "episodes") for p in (_PACKAGE / sub).rglob("*.py")
                   if p.relative_to(_PACKAGE).as_posix() not in _NOT_SIMULATION)
    sources = [[p.relative_to(_PACKAGE).as_posix(), hashlib.sha256(p.read_bytes()).hexdigest()]
               for p in files]
    return digest([getattr(navground, "__version__", ""), sources])


def run_code_stamp(controller: str) -> str:
    """Stamp of the code a run of ``controller`` (an id, or "none") executes: the
    simulator, plus the controller's own module for a controller."""
    if controller == NO_ROBOT:
        return simulator_stamp()
    return digest([simulator_stamp(), controller_stamp(CONTROLLERS.make(controller))])


def code_stamps(controllers: Iterable[str]) -> dict[str, str]:
    """``{controller id: run_code_stamp}`` for every distinct id, sorted."""
    return {c: run_code_stamp(c) for c in sorted(set(controllers))}
