"""Register the built-in controllers and navground's behaviour types.

Importing this module fills :data:`CONTROLLERS`:

* ``BUILTINS``: ``reactive``, ``early_yield``, ``robot_orca`` (the paper's three, which
  ``popnavshift/paper.py`` names as study data) and any controller added beside them;
* every behaviour type registered in navground at import time under its
  navground name (``ORCA``, ``HRVO``, ``HL``, ``SocialForce``, ``Dummy``, ...),
  built by :class:`.navground_type.NavgroundType` with navground's defaults.

Navground types keep their bare names: a miss then gets the registry's
did-you-mean against them (``"HRV0"`` → ``'HRVO'``), and being capitalised they
cannot clash with the lower-case built-ins (a clash would keep the built-in).
The behaviours behind our own controllers are navground types too
(``PopNavShift*``) but are not exposed this way, since they need their
factory. A navground type registered later (a plugin, a Python class defined
after this import) becomes a controller when :func:`register_navground_types`
is called again.
"""

from __future__ import annotations

from functools import partial

from ...controller_ids import POLICY
from .navground_type import NavgroundType, navground_types
from .registry import CONTROLLERS

#: name → factory, as ``"module:Class"`` imported when the controller is first made:
#: listing the controllers (a did-you-mean, ``popnavshift evaluate hrvo``) then imports
#: none of them (numba, the episode grid), only navground's core
BUILTINS: dict[str, str] = {
    "reactive": "popnavshift.sim.controllers.reactive:Reactive",
    "early_yield": "popnavshift.sim.controllers.early_yield:EarlyYield",
    "robot_orca": "popnavshift.sim.controllers.robot_orca:RobotORCA",
}
#: a learned policy file (``popnavshift evaluate policy.onnx``), named by an id that holds its
#: file and hash (:func:`popnavshift.controller_ids.policy_id`): not a built-in of
#: ``BUILTINS``, which run with no parameters
LEARNED: dict[str, str] = {POLICY: "popnavshift.learn.policy:PolicyController"}
# what the package can build, not what the paper runs (popnavshift/paper.py)
#: the navground types behind our own controllers (``NAVGROUND_NAME`` of reactive.py and
#: early_yield.py, registered in navground when their module is first imported; a test
#: checks the two agree): they need their factory, so they are never bare controllers
OWN_BEHAVIORS = frozenset({"PopNavShiftReactive", "PopNavShiftEarlyYield"})


def register_navground_types() -> list[str]:
    """Register every navground behaviour type that is not yet a controller
    name; returns the names added (idempotent)."""
    known = set(CONTROLLERS.names())
    added = [t for t in navground_types() if t not in known and t not in OWN_BEHAVIORS]
    for type_name in added:
        CONTROLLERS.register(type_name, partial(NavgroundType, type_name))
    return added


for _name, _factory in {**BUILTINS, **LEARNED}.items():
    CONTROLLERS.register(_name, _factory)  # re-registering the same factory is a no-op
register_navground_types()
