"""Registries by name, in the spirit of Gymnasium's ``register``/``make``.

Each pluggable kind has one :class:`Registry`, next to its contract:

* controllers — :data:`popnavshift.sim.controllers.CONTROLLERS`;
* pedestrian backends — :data:`popnavshift.sim.backends.BACKENDS`;
* respondents — :data:`popnavshift.responses.respondent.RESPONDENTS`;
* mappings — :data:`popnavshift.profiles.mappings.MAPPINGS`.

``make(spec, **kwargs)`` accepts three kinds of ``spec``:

1. a registered name (``reactive``, ``orca``, ``rule``, ``A``); an entry may be the
   factory itself or a ``"package.module:Attr"`` string imported on first use;
2. the name of an entry point in the group ``popnavshift.<kind>s`` of an installed
   package, imported when first made (looked up again by name on a miss, so a package
   installed after the first lookup is found);
3. a Python object ``package.module:Attr``.

A miss raises :class:`UnknownNameError` with a did-you-mean; an object that is not
of the kind (``requires``/``base``) or a parameter the factory does not take is a
one-line :class:`ConfigError`.
"""

from __future__ import annotations

import difflib
import functools
import importlib
import inspect
import re
import types
import typing
from collections.abc import Callable, Iterator
from importlib.metadata import EntryPoint, entry_points
from typing import Any, Generic, TypeVar

from .errors import ConfigError, UnknownNameError

T = TypeVar("T")

_DOTTED = r"[A-Za-z_]\w*(?:\.[A-Za-z_]\w*)*"
OBJECT_SPEC = re.compile(rf"^{_DOTTED}:{_DOTTED}$")


def is_object_spec(spec: str) -> bool:
    """``package.module:Attr`` rather than a registered name."""
    return ":" in spec


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


def describe_object(obj: Any) -> str:
    """``class pkg.mod.Name`` for a class, else its type and repr (for messages)."""
    if isinstance(obj, type):
        return f"class {obj.__module__}.{obj.__qualname__}"
    return f"{type(obj).__name__} {obj!r}"


def has_methods(obj: Any, methods: tuple[str, ...]) -> bool:
    return all(callable(getattr(obj, m, None)) for m in methods)


class Registry(Generic[T]):
    """Name → factory of one kind; ``kind`` is singular and used in messages.

    ``requires`` (method names) and ``base`` (a class) say what an entry must be: a
    class with those methods, or a subclass of ``base``; ``noun`` and ``hint`` word
    the error when it is not. ``construct`` False: the entry is the product itself
    (a mapping function), returned by :meth:`make` without a call.
    """

    def __init__(self, kind: str, *, group: str | None = None, requires: tuple[str, ...] = (),
                 base: type | None = None, noun: str | None = None, hint: str | None = None,
                 construct: bool = True) -> None:
        self.kind = kind
        self.group = group or f"popnavshift.{kind}s"
        self.requires, self.base, self.construct = requires, base, construct
        self.noun = noun or (base.__name__ if base is not None else kind)
        self.hint = hint
        self._entries: dict[str, Any] = {}
        self._loaded_entry_points = False

    def register(self, name: str, factory: Callable[..., T] | str | None = None):
        """Register ``factory`` (or a ``"package.module:Attr"`` string imported on first
        use) under ``name``; usable as a decorator."""

        def _add(f: Any) -> Any:
            if name in self._entries and self._entries[name] is not f:
                raise ConfigError(f"{self.kind} {name!r} is already registered")
            self._entries[name] = f
            return f

        return _add(factory) if factory is not None else _add

    def _load_entry_points(self) -> None:
        """Add the group's entry points by name; each is imported when first made, so
        listing the names (a did-you-mean, ``--help``) imports no outside package."""
        if self._loaded_entry_points:
            return
        self._loaded_entry_points = True
        for ep in entry_points(group=self.group):
            self._entries.setdefault(ep.name, ep)

    def _load_entry_point(self, ep: Any) -> Any:
        try:
            return ep.load()
        except Exception as exc:  # an outside package failed to import
            raise ConfigError(f"{self.kind} entry point {ep.name!r} ({ep.value}) failed "
                              f"to load: {type(exc).__name__}: {exc}") from exc

    def names(self) -> list[str]:
        self._load_entry_points()
        return sorted(self._entries)

    def get(self, name: str) -> Any:
        """The entry registered as ``name``, loading an entry point of that name installed
        since the group was first read (raises UnknownNameError with a hint)."""
        self.check_name(name)
        entry = self._entries[name]
        if isinstance(entry, EntryPoint):  # an outside package's, imported now
            entry = self._entries[name] = self._load_entry_point(entry)
        if isinstance(entry, str):  # "package.module:Attr", imported now
            entry = self._entries[name] = load_object(entry, self.kind)
        return entry

    def check_name(self, name: str) -> None:
        """UnknownNameError (with a did-you-mean, case aside) unless ``name`` is registered
        or an entry point of the group, one installed since the group was first read
        included. Imports nothing: a command checks its names before its heavy work."""
        self._load_entry_points()
        if name not in self._entries:
            for ep in entry_points(group=self.group, name=name):
                self._entries[name] = ep
                break
        if name not in self._entries:
            raise UnknownNameError(self.kind, name, self._entries)

    def resolve(self, spec: str) -> Any:
        """The registered entry, entry point or ``package.module:Attr`` object ``spec``
        names, checked to be of this kind."""
        obj = load_object(spec, self.kind) if is_object_spec(spec) else self.get(spec)
        self.check(spec, obj)
        return obj

    def check(self, spec: str, obj: Any) -> None:
        """ConfigError unless ``obj`` is a class of this kind (see the class doc)."""
        ok = ((not self.requires or (isinstance(obj, type) and has_methods(obj, self.requires)))
              and (self.base is None or (isinstance(obj, type) and issubclass(obj, self.base))))
        if not ok:
            raise ConfigError(f"{self.kind} {spec!r} is {describe_object(obj)}, "
                              f"not a {self.noun}", hint=self.hint)

    def make(self, spec: str, **kwargs: Any) -> T:
        """The ``spec``'s product: its factory called with ``kwargs`` (checked against
        the factory's parameters), or the entry itself for a non-constructing kind."""
        obj = self.resolve(spec)
        if not self.construct:
            if kwargs:
                raise ConfigError(f"{self.kind} {spec!r} takes no parameters")
            return obj
        return call_checked(self.kind, spec, obj, kwargs)

    def __contains__(self, name: object) -> bool:
        self._load_entry_points()
        return name in self._entries

    def __iter__(self) -> Iterator[str]:
        return iter(self.names())


def call_checked(kind: str, name: str, factory: Callable[..., T], kwargs: dict) -> T:
    """``factory(**kwargs)``, but a parameter the factory does not take is a
    :class:`ConfigError` naming it and the accepted ones (e.g. a typo in a study file),
    not a ``TypeError`` traceback."""
    try:
        signature = _signature(factory)
    except (TypeError, ValueError):  # builtins without a signature: just call
        return factory(**kwargs)
    try:
        bound = signature.bind(**kwargs)
    except TypeError:
        accepted = [
            p
            for p, v in signature.parameters.items()
            if v.kind in (v.KEYWORD_ONLY, v.POSITIONAL_OR_KEYWORD)
        ]
        bad = [k for k in kwargs if k not in accepted]
        missing = [p for p, v in signature.parameters.items() if p not in kwargs
                   and v.default is v.empty and v.kind in (v.KEYWORD_ONLY,
                                                          v.POSITIONAL_OR_KEYWORD)]
        if not bad and missing:  # a required parameter not given
            raise ConfigError(f"{kind} {name!r} needs the parameter"
                              f"{'s' if len(missing) > 1 else ''} {', '.join(missing)}"
                              ) from None
        bad = bad or list(kwargs) or [""]
        close = difflib.get_close_matches(bad[0], accepted, n=1)
        raise ConfigError(
            f"{kind} {name!r} takes no parameter {bad[0]!r}; parameters: "
            f"{', '.join(accepted) or 'none'}",
            hint=f"did you mean {close[0]!r}?" if close else None,
        ) from None
    check_types(kind, name, factory, signature, bound.arguments)
    return factory(**kwargs)


#: the simple annotations a parameter's value is checked against (:func:`check_types`), and
#: the words of a message
_SIMPLE: dict[Any, str] = {int: "an integer", float: "a number", str: "a text",
                           bool: "true or false", type(None): "null"}


def check_types(kind: str, name: str, factory: Callable, signature: inspect.Signature,
                given: dict[str, Any]) -> None:
    """ConfigError when a value in ``given`` does not match its parameter's simple
    annotation (``int``, ``float``, ``str``, ``bool``, ``None`` or a union of them: a YAML
    date, a list or a boolean where a number is expected), here rather than deep in a
    stage that already ran. Other annotations are the factory's to check."""
    for param, value in given.items():
        p = signature.parameters.get(param)
        if p is None or p.kind is p.VAR_KEYWORD:
            continue
        allowed = _simple_types(_annotation(factory, p.annotation))
        if allowed and not _matches(value, allowed):
            words = " or ".join(dict.fromkeys(_SIMPLE[t] for t in allowed))
            raise ConfigError(f"{kind} {name!r}: parameter {param!r} must be {words}; got "
                              f"{value!r}")


def _annotation(factory: Callable, annotation: Any) -> Any:
    """``annotation``, evaluated in the factory's module when it is a string (postponed
    annotations, as ``typing.get_type_hints`` does); ``inspect.Parameter.empty`` (not
    checked) when it cannot be."""
    if not isinstance(annotation, str):
        return annotation
    module = inspect.getmodule(factory)
    try:
        return eval(annotation, dict(vars(module)) if module else {})  # noqa: S307
    except Exception:  # a name the module does not hold at run time: not checked
        return inspect.Parameter.empty


def _simple_types(annotation: Any) -> tuple[type, ...]:
    """The simple types ``annotation`` allows; () when it is anything else (or none)."""
    if annotation is None or annotation is inspect.Parameter.empty:
        return ()
    members = typing.get_args(annotation) if isinstance(
        annotation, types.UnionType) or typing.get_origin(annotation) is typing.Union else (
        annotation,)
    members = tuple(type(None) if m is None else m for m in members)
    return members if members and all(m in _SIMPLE for m in members) else ()


def _matches(value: Any, allowed: tuple[type, ...]) -> bool:
    if isinstance(value, bool):  # a bool is an int to Python, never to a study file
        return bool in allowed
    if isinstance(value, int) and float in allowed:
        return True
    return isinstance(value, tuple(t for t in allowed if t is not bool))


def _signature(factory: Callable) -> inspect.Signature:
    """``inspect.signature``, once per factory: a study makes a controller and a backend
    for every run, and reading a class's signature costs ~0.2 ms. A factory that cannot
    be hashed (a callable instance, say) is read every time."""
    try:
        return _cached_signature(factory)
    except TypeError:  # unhashable, or no signature (then this raises it again)
        return inspect.signature(factory)


@functools.lru_cache(maxsize=256)
def _cached_signature(factory: Callable) -> inspect.Signature:
    return inspect.signature(factory)
