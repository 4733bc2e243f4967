"""Controller ids: a controller's name and parameters as one string, the ``controller``
column of the run tables.

Controller parameters are part of the controller's identity:
``controller_id("HRVO", {"tau": 0.5})`` is ``'HRVO{"tau":0.5}'``, so two
parameterisations never share a run, and the id is enough to rebuild the controller
(:data:`popnavshift.sim.controllers.CONTROLLERS` parses it). Pure string handling: a
study file is read and planned without the simulator.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from typing import Any

from .errors import ConfigError
from .hashing import canonical_json


def controller_id(name: str, params: Mapping[str, Any] | None = None) -> str:
    """The controller column value: ``name``, or ``name`` + canonical JSON of ``params``."""
    if not name or "{" in name:
        raise ConfigError(f"controller name must be non-empty and without '{{', got {name!r}")
    if not params:
        return name
    try:
        json.dumps(dict(params), allow_nan=False)
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"controller {name!r}: parameters must be JSON values: {exc}") from None
    return name + canonical_json(dict(params))


def parse_controller_id(identity: str) -> tuple[str, dict[str, Any]]:
    """Inverse of :func:`controller_id`: ``'HRVO{"tau":0.5}'`` → ``("HRVO", {"tau": 0.5})``."""
    name, brace, rest = identity.partition("{")
    if not brace:
        return identity, {}
    try:
        params = json.loads(brace + rest)
    except json.JSONDecodeError:
        params = None
    if not name or not isinstance(params, dict):
        raise ConfigError(f"controller {identity!r}: expected NAME or NAME{{JSON parameters}}")
    return name, params
