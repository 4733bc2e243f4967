"""Plug-ins: controllers, pedestrian backends and respondents from outside this package.

A plug-in is named, in a study file or on the command line, in one of three ways:

1. a registered name: the built-ins (``reactive``, ``orca``, ``rule``) and, for
   controllers, every navground behaviour type (``HRVO``, ``SocialForce``, ``HL``);
2. an entry point of the group ``popnavshift.controllers`` (``popnavshift.backends``,
   ``popnavshift.respondents``) declared by an installed package;
3. a Python object ``package.module:Class``.

A controller class only has to subclass navground's ``core.Behavior``
(:class:`BehaviorClass` wraps it in the controller contract); a class that
already implements that contract (``build``, ``after_placement``, ``describe``)
is used as it is. Controller parameters are part of the controller's identity:
``controller_id("HRVO", {"tau": 0.5})`` is ``'HRVO{"tau":0.5}'``, so two
parameterisations never share a run and a runs table's ``controller`` column is
enough to rebuild the controller (:func:`make_controller` parses it).
"""

from __future__ import annotations

import difflib
import functools
import hashlib
import importlib
import inspect
import json
import re
import sys
from collections.abc import Mapping
from importlib.metadata import entry_points
from pathlib import Path
from typing import TYPE_CHECKING, Any

from .errors import ConfigError
from .hashing import canonical_json, digest

if TYPE_CHECKING:
    from navground import core

    from .registry import Registry
    from .responses.respondent import Respondent
    from .sim.backends import PedestrianBackend
    from .sim.controllers import ControllerFactory

_DOTTED = r"[A-Za-z_]\w*(?:\.[A-Za-z_]\w*)*"
OBJECT_SPEC = re.compile(rf"^{_DOTTED}:{_DOTTED}$")
FACTORY_METHODS = ("build", "after_placement", "describe")
BACKEND_METHODS = ("behavior", "describe")


# ------------------------------------------------------------------ names and specs
def is_object_spec(name: str) -> bool:
    """``package.module:Class`` rather than a registered name."""
    return ":" in name


def load_object(spec: str, kind: str) -> Any:
    """The object ``package.module:Attr`` (attributes may be dotted).

    Raises :class:`ConfigError` when the spec is malformed, the module does not
    import (with the import's own message) or has no such attribute.
    """
    if not OBJECT_SPEC.match(spec):
        raise ConfigError(f"{kind} {spec!r} is not a Python object spec",
                          hint="write it as package.module:Class")
    module_name, _, attr = spec.partition(":")
    try:
        obj: Any = importlib.import_module(module_name)
    except Exception as exc:  # ImportError, or anything the module raises on import
        raise ConfigError(f"cannot import {module_name}: {type(exc).__name__}: {exc}",
                          hint="is the package installed, or its folder on PYTHONPATH?") from exc
    for part in attr.split("."):
        if not hasattr(obj, part):
            close = difflib.get_close_matches(part, [n for n in dir(obj) if not n.startswith("_")])
            raise ConfigError(f"{module_name} has no attribute {part!r} ({kind} {spec!r})",
                              hint=f"did you mean {close[0]!r}?" if close else None)
        obj = getattr(obj, part)
    return obj


def _registered(registry: Registry, name: str) -> Any:
    """``registry.get(name)``, first looking the entry points up again by name: a
    registry reads its group once, and a package installed (or a folder put on
    ``sys.path``) after that would otherwise stay invisible."""
    if name not in registry:
        for ep in entry_points(group=registry.group, name=name):
            try:
                registry.register(name, ep.load())
            except Exception as exc:
                raise ConfigError(f"{registry.kind} entry point {name!r} ({ep.value}) failed "
                                  f"to load: {type(exc).__name__}: {exc}") from exc
            break
    return registry.get(name)


def _describe(obj: Any) -> str:
    if isinstance(obj, type):
        return f"class {obj.__module__}.{obj.__qualname__}"
    return f"{type(obj).__name__} {obj!r}"


# ------------------------------------------------------------------------ controllers
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


def make_controller(identity: str, params: Mapping[str, Any] | None = None) -> ControllerFactory:
    """A ControllerFactory for a controller id (name, entry point or class spec, with
    optional JSON parameters) and extra ``params``. A registered factory keeps its own
    ``name`` (navground types build by it); tables use the full id
    (:func:`popnavshift.sim.run.resolve_controller`)."""
    from .sim.controllers import CONTROLLERS

    name, own = parse_controller_id(identity)
    if own and params:
        raise ConfigError(f"controller {identity!r} already carries parameters; "
                          "give them either in the name or separately")
    given = dict(own or params or {})
    full = controller_id(name, given)
    if is_object_spec(name):
        obj = load_object(name, "controller")
    else:
        importlib.import_module("popnavshift.sim.controllers.builtin")
        obj = _registered(CONTROLLERS, name)
    if isinstance(obj, type) and _is_behavior_class(obj):
        return BehaviorClass(full, obj, **given)
    if is_object_spec(name) and not (isinstance(obj, type) and _has(obj, FACTORY_METHODS)):
        raise ConfigError(
            f"controller {name!r} is {_describe(obj)}, not a navground Behavior",
            hint="a controller class must subclass navground.core.Behavior, "
                 "or implement build, after_placement and describe")
    factory = obj(**given)
    if not _has(factory, FACTORY_METHODS):
        raise ConfigError(f"controller {name!r} built {_describe(factory)}, which has no "
                          f"{', '.join(m for m in FACTORY_METHODS if not hasattr(factory, m))}")
    return factory


def _has(obj: Any, methods: tuple[str, ...]) -> bool:
    return all(callable(getattr(obj, m, None)) for m in methods)


def _is_behavior_class(obj: type) -> bool:
    from navground import core

    return issubclass(obj, core.Behavior)


class BehaviorClass:
    """Controller factory of a ``core.Behavior`` subclass.

    ``build`` calls ``cls(kinematics, radius)``, sets the cell speed as optimal
    speed and applies ``params``: ``horizon``, ``safety_margin`` and
    ``rotation_tau`` as attributes, anything else as a navground property the
    class registered (``@core.register``), read back after setting.
    """

    def __init__(self, name: str, cls: type[core.Behavior], **params: Any) -> None:
        from .sim.controllers.navground_type import BASE_PARAMS

        self.name, self.cls = name, cls
        props = _properties(cls)
        unknown = sorted(set(params) - set(props) - set(BASE_PARAMS))
        if unknown:
            allowed = sorted({*props, *BASE_PARAMS})
            raise ConfigError(f"controller {name!r} has no parameter {unknown[0]!r}; "
                              f"allowed: {', '.join(allowed)}")
        self.params = dict(params)

    def build(self, kinematics: core.Kinematics, radius: float, speed: float) -> core.Behavior:
        from .sim.controllers.navground_type import apply_params

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
    from navground import core

    type_name = getattr(cls, "_type", None)
    return dict(core.Behavior.type_properties.get(type_name, {})) if type_name else {}


# ------------------------------------------------------------- backends, respondents
def make_backend(name: str) -> PedestrianBackend:
    """A pedestrian backend by registered name, entry point or ``package.module:Class``.

    A class must provide ``name``, ``horizon`` [m], ``behavior(kinematics, radius)``
    and ``describe()``; it is instantiated without arguments."""
    from .sim.backends import BACKENDS

    obj = load_object(name, "backend") if is_object_spec(name) else _registered(BACKENDS, name)
    if not (isinstance(obj, type) and _has(obj, BACKEND_METHODS)):
        raise ConfigError(f"backend {name!r} is {_describe(obj)}, not a pedestrian backend",
                          hint="a backend class has name, horizon, behavior(kinematics, radius) "
                               "and describe()")
    return obj()


def make_respondent(name: str, **options: Any) -> Respondent:
    """A respondent by registered name, entry point or ``package.module:Class``
    (a subclass of :class:`popnavshift.responses.respondent.Respondent`)."""
    from .errors import UnknownNameError
    from .responses.collect import make_respondent as make_registered
    from .responses.respondent import RESPONDENTS, Respondent

    if not is_object_spec(name):
        try:
            return make_registered(name, **options)
        except UnknownNameError:
            _registered(RESPONDENTS, name)  # an entry point added since (or the same error)
            return make_registered(name, **options)
    obj = load_object(name, "respondent")
    if not (isinstance(obj, type) and issubclass(obj, Respondent)):
        raise ConfigError(f"respondent {name!r} is {_describe(obj)}, not a Respondent",
                          hint="subclass popnavshift.responses.respondent.Respondent")
    return obj(**options)


def controller_stamp(factory: Any) -> str:
    """Hash of a controller's ``describe()`` and the source of the module defining its
    behaviour class (or factory). Code in other modules it imports is not covered."""
    cls = getattr(factory, "cls", type(factory))
    try:
        source = inspect.getsource(sys.modules[cls.__module__])
    except (KeyError, TypeError, OSError):  # no source: a compiled or interactive class
        source = ""
    return digest([factory.describe(), source])


#: modules under sim/ that no run executes (the benchmark, the contract check)
_NOT_SIMULATION = frozenset({"sim/bench.py", "sim/bench_profile.py", "sim/check.py"})


@functools.cache
def simulator_stamp() -> str:
    """Hash of the simulator's own code (``popnavshift.sim`` with the built-in
    controllers, ``popnavshift.episodes``) and navground's version: a change to
    either makes every stored run stale."""
    import navground

    root = Path(__file__).parent
    files = sorted(p for sub in ("sim", "episodes") for p in (root / sub).rglob("*.py")
                   if p.relative_to(root).as_posix() not in _NOT_SIMULATION)
    sources = [[p.relative_to(root).as_posix(), hashlib.sha256(p.read_bytes()).hexdigest()]
               for p in files]
    return digest([getattr(navground, "__version__", ""), sources])


def run_code_stamp(controller: str) -> str:
    """Stamp of the code a run of ``controller`` (an id, or "none") executes: the
    simulator, plus the controller's own module for a controller."""
    if controller == "none":
        return simulator_stamp()
    return digest([simulator_stamp(), controller_stamp(make_controller(controller))])
