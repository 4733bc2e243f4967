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

from collections.abc import Callable
from functools import partial
from typing import Any

from . import early_yield, reactive
from .navground_type import NavgroundType, navground_types
from .registry import CONTROLLERS
from .robot_orca import RobotORCA

BUILTINS: dict[str, Callable[..., Any]] = {
    "reactive": reactive.Reactive,
    "early_yield": early_yield.EarlyYield,
    "robot_orca": RobotORCA,
}
# what the package can build, not what the paper runs (popnavshift/paper.py)
OWN_BEHAVIORS = frozenset({reactive.NAVGROUND_NAME, early_yield.NAVGROUND_NAME})


def register_navground_types() -> list[str]:
    """Register every navground behaviour type that is not yet a controller
    name; returns the names added (idempotent)."""
    known = set(CONTROLLERS.names())
    added = [t for t in navground_types() if t not in known and t not in OWN_BEHAVIORS]
    for type_name in added:
        CONTROLLERS.register(type_name, partial(NavgroundType, type_name))
    return added


for _name, _factory in BUILTINS.items():
    CONTROLLERS.register(_name, _factory)  # re-registering the same factory is a no-op
register_navground_types()
