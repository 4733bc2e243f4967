"""The controller registry: the one ``make`` of a controller id.

A controller is named, in a study file or on the command line, by a registered
name (the built-ins of :mod:`.builtin` and every navground behaviour type), an
entry point of the group ``popnavshift.controllers``, or a Python object
``package.module:Class`` (see :mod:`popnavshift.registry`). A class only has to
subclass navground's ``core.Behavior`` (:class:`.navground_type.BehaviorClass`
wraps it in the controller contract); a class that already implements that
contract (``build``, ``after_placement``, ``describe``) is used as it is.

Controller parameters are part of the controller's identity
(:mod:`popnavshift.controller_ids`): a runs table's ``controller`` column is enough to
rebuild the controller (``CONTROLLERS.make`` parses it).
"""

from __future__ import annotations

from typing import Any

from navground import core

from ...controller_ids import controller_id, parse_controller_id
from ...errors import ConfigError
from ...registry import Registry, describe_object, has_methods, is_object_spec
from .navground_type import BehaviorClass

FACTORY_METHODS = ("build", "after_placement", "describe")


class ControllerRegistry(Registry[Any]):
    """:class:`Registry` whose specs are controller ids and whose ``make`` accepts a
    navground ``Behavior`` class as well as a controller factory."""

    def __init__(self) -> None:
        super().__init__("controller")

    def check(self, spec: str, obj: Any) -> None:
        """A ``package.module:Class`` must be a Behavior or a controller factory class;
        a registered factory is checked by what it builds (:meth:`make`)."""
        if not is_object_spec(spec) or _is_behavior_class(obj):
            return
        if not (isinstance(obj, type) and has_methods(obj, FACTORY_METHODS)):
            raise ConfigError(
                f"controller {spec!r} is {describe_object(obj)}, not a navground Behavior",
                hint="a controller class must subclass navground.core.Behavior, "
                     "or implement build, after_placement and describe")

    def check_name(self, name: str) -> None:
        """As :meth:`Registry.check_name`, for a controller id (``HRVO{"tau":0.5}`` is
        checked by its name); a ``package.module:Class`` is checked when it is made
        (importing it is the check)."""
        base, _ = parse_controller_id(name)
        if not is_object_spec(base):
            super().check_name(base)

    def make(self, spec: str, **params: Any) -> Any:
        """A controller factory for a controller id (name, entry point or class spec,
        with optional JSON parameters) and extra ``params``. A registered factory keeps
        its own ``name`` (navground types build by it); tables use the full id."""
        name, own = parse_controller_id(spec)
        if own and params:
            raise ConfigError(f"controller {spec!r} already carries parameters; "
                              "give them either in the name or separately")
        given = dict(own or params)
        obj = self.resolve(name)
        if _is_behavior_class(obj):  # named by its full id, as in the tables
            return BehaviorClass(controller_id(name, given), obj, **given)
        factory = super().make(name, **given)
        if not has_methods(factory, FACTORY_METHODS):
            missing = ", ".join(m for m in FACTORY_METHODS if not hasattr(factory, m))
            raise ConfigError(f"controller {name!r} built {describe_object(factory)}, "
                              f"which has no {missing}")
        return factory


def _is_behavior_class(obj: Any) -> bool:
    return isinstance(obj, type) and issubclass(obj, core.Behavior)


#: the controller registry (the built-ins are added by :mod:`.builtin`, which
#: ``popnavshift.sim.controllers`` imports)
CONTROLLERS = ControllerRegistry()
