"""Any registered navground behaviour type as a controller (e.g. ``HRVO``).

``NavgroundType("HRVO", safety_margin=0.1, max_neighbors=8)`` builds
``core.Behavior.make_type("HRVO")`` on the robot's kinematics and radius with
the cell speed as optimal speed. Parameters are the base-behaviour ones in
:data:`BASE_PARAMS` plus the type's own navground properties
(``core.Behavior.type_properties[type]``), set with ``behavior.set``. navground's
``set`` ignores unknown names and mistyped values silently, so names and types
are checked here and every value is read back after setting. Values of the
type's own properties get no range check: navground declares none.
"""

from __future__ import annotations

from typing import Any

from navground import core

from ...errors import ConfigError, UnknownNameError
from ._params import Param, check_value, set_property
from .robot_orca import first_command_workaround

BASE_PARAMS: dict[str, Param] = {
    "horizon": Param(5.0, 0.1, 50.0, doc="spatial horizon [m]"),
    "safety_margin": Param(0.0, 0.0, 2.0, doc="safety margin [m]"),
    "rotation_tau": Param(0.5, 0.01, 10.0, doc="heading relaxation time [s]"),
}
_KINDS = {"float": float, "int": int, "bool": bool, "str": str}


def apply_params(behavior: core.Behavior, params: dict[str, Any], controller: str) -> None:
    """Base parameters (:data:`BASE_PARAMS`) as attributes, anything else as a navground
    property, read back after setting (:func:`._params.set_property`)."""
    for key, value in params.items():
        if key in BASE_PARAMS:
            setattr(behavior, key, value)
        else:
            set_property(behavior, key, value, controller=controller)


def navground_types() -> list[str]:
    """Names of the behaviour types registered in navground right now."""
    return sorted(t for t in core.Behavior.types if t)


class NavgroundType:
    """Factory of one navground behaviour type with validated properties."""

    def __init__(self, type_name: str, **params: Any) -> None:
        if type_name not in navground_types():
            raise UnknownNameError("navground behavior type", type_name, navground_types())
        self.name = type_name
        self._props = core.Behavior.type_properties[type_name]
        allowed = sorted({*BASE_PARAMS, *self._props})
        self.params: dict[str, Any] = {}
        for key, value in params.items():
            if key in BASE_PARAMS:
                self.params[key] = check_value(type_name, key, value, BASE_PARAMS[key])
            elif key in self._props:
                self.params[key] = self._check_property(key, value)
            else:
                raise ConfigError(
                    f"controller {type_name!r} has no parameter {key!r}; "
                    f"allowed: {', '.join(allowed)}"
                )

    def _check_property(self, key: str, value: Any) -> Any:
        type_name = self._props[key].type_name
        kind = _KINDS.get(type_name)
        if kind is None:  # vectors and lists: left to the read-back check in build
            return value
        return check_value(self.name, key, value, Param(None, kind=kind))

    def build(self, kinematics: core.Kinematics, radius: float, speed: float) -> core.Behavior:
        behavior = core.Behavior.make_type(self.name)
        if behavior is None:  # unregistered since __init__
            raise UnknownNameError("navground behavior type", self.name, navground_types())
        behavior.kinematics = kinematics
        behavior.radius = radius
        behavior.optimal_speed = speed
        behavior.heading_behavior = core.Behavior.Heading.velocity
        base = {k: p.default for k, p in BASE_PARAMS.items()}
        apply_params(behavior, {**base, **self.params}, self.name)
        return behavior

    def after_placement(self, behavior: core.Behavior, dt: float) -> None:
        if isinstance(behavior, core.behaviors.ORCABehavior):
            first_command_workaround(behavior, dt)  # notes §7

    def describe(self) -> dict[str, Any]:
        defaults = {k: p.default for k, p in BASE_PARAMS.items()}
        props = {k: getattr(p.default_value, "tolist", lambda v=p.default_value: v)()
                 for k, p in self._props.items()}  # vectors come back as numpy arrays
        return {"controller": self.name, "navground_type": self.name,
                **defaults, **props, **self.params}


class BehaviorClass:
    """Controller factory of a ``core.Behavior`` subclass (a plug-in's class).

    ``build`` calls ``cls(kinematics, radius)``, sets the cell speed as optimal
    speed and applies ``params``: ``horizon``, ``safety_margin`` and
    ``rotation_tau`` as attributes, anything else as a navground property the
    class registered (``@core.register``), read back after setting.
    """

    def __init__(self, name: str, cls: type[core.Behavior], **params: Any) -> None:
        self.name, self.cls = name, cls
        props = _properties(cls)
        unknown = sorted(set(params) - set(props) - set(BASE_PARAMS))
        if unknown:
            allowed = sorted({*props, *BASE_PARAMS})
            raise ConfigError(f"controller {name!r} has no parameter {unknown[0]!r}; "
                              f"allowed: {', '.join(allowed)}")
        self.params = dict(params)

    def build(self, kinematics: core.Kinematics, radius: float, speed: float) -> core.Behavior:
        behavior = self.cls(kinematics, radius)
        behavior.optimal_speed = speed
        apply_params(behavior, self.params, self.name)
        return behavior

    def after_placement(self, behavior: core.Behavior, dt: float) -> None:
        """Nothing: a Python behaviour initialises itself on its first command."""

    def describe(self) -> dict[str, Any]:
        return {"controller": self.name,
                "class": f"{self.cls.__module__}:{self.cls.__qualname__}", **self.params}


def _properties(cls: type) -> dict[str, Any]:
    """The navground properties of a Behavior subclass declared with ``name=``.

    navground stores that name as ``cls._type``; a class declared without one
    has no registered properties."""
    type_name = getattr(cls, "_type", None)
    return dict(core.Behavior.type_properties.get(type_name, {})) if type_name else {}
