"""The methods and their estimators, read from each method's one declaration.

A method declares itself once, as ``METHOD = MethodSpec(...)`` in its subpackage's
``__init__.py`` (:mod:`wearpose.estimators.method`). The registry finds the declarations of

1. every subpackage of :mod:`wearpose.estimators` that has a ``METHOD`` (the built-in methods:
   a new subpackage is found with no line added here);
2. the ``wearpose.methods`` entry points of installed packages (a method outside this package:
   ``[project.entry-points."wearpose.methods"] mine = "mypkg.mymethod:METHOD"``);
3. :func:`register_method` calls (a test's method, a notebook).

Reading a declaration imports no estimator: classes are imported on first use
(:func:`get_estimator`), so ``import wearpose.estimators`` and ``wearpose --help`` stay cheap.
"""

from __future__ import annotations

import importlib
import pkgutil
from importlib.metadata import entry_points
from typing import Callable, TypeVar

from wearpose.errors import ConfigError
from wearpose.estimators.method import EstimatorEntry, MethodSpec, Training, resolve, target_available
import wearpose.estimators as pkg

T = TypeVar("T")

#: Entry-point group of methods declared by other installed packages.
ENTRY_POINT_GROUP = "wearpose.methods"

_METHODS: dict[str, MethodSpec] = {}
_DISCOVERED: list[bool] = []
#: Classes added with :func:`register_estimator` (or imported once): name -> class.
_REGISTRY: dict[str, type] = {}


def register_method(spec: MethodSpec, *, replace: bool = False) -> MethodSpec:
    """Add ``spec`` (its training command, estimators, protocols and demos with it).

    Raises:
        ConfigError: a method or estimator of that name is declared already (unless ``replace``).
    """
    if not isinstance(spec, MethodSpec):
        raise ConfigError(f"register_method: expected a wearpose.estimators.method.MethodSpec, got {type(spec).__name__}")
    _discover()
    if not replace:
        if spec.name in _METHODS and _METHODS[spec.name] != spec:
            raise ConfigError(f"method {spec.name!r} is declared already (by {_METHODS[spec.name].summary!r})")
        taken = {e.name for m in _METHODS.values() if m.name != spec.name for e in m.estimators}
        clash = sorted(taken & {e.name for e in spec.estimators})
        if clash:
            raise ConfigError(f"method {spec.name!r}: estimator names {clash} belong to another method")
        taken = {c for m in _METHODS.values() if m.name != spec.name for c in m.training_commands()}
        clash = sorted(taken & set(spec.training_commands()))
        if clash:
            raise ConfigError(f"method {spec.name!r}: training commands {clash} belong to another method")
    old = _METHODS.get(spec.name)
    for e in old.estimators if old else ():
        _REGISTRY.pop(e.name, None)
    _METHODS[spec.name] = spec
    return spec


def unregister_method(name: str) -> None:
    """Remove method ``name`` and its estimators (tests that registered one)."""
    spec = _METHODS.pop(name, None)
    for e in spec.estimators if spec else ():
        _REGISTRY.pop(e.name, None)


def _discover() -> None:
    """Read the built-in subpackages' and the entry points' declarations, once per process."""
    if _DISCOVERED:
        return
    _DISCOVERED.append(True)

    for m in sorted(pkgutil.iter_modules(pkg.__path__), key=lambda m: m.name):
        if m.ispkg:
            spec = getattr(importlib.import_module(f"{pkg.__name__}.{m.name}"), "METHOD", None)
            if isinstance(spec, MethodSpec):
                _METHODS.setdefault(spec.name, spec)
    for ep in entry_points(group=ENTRY_POINT_GROUP):
        spec = ep.load()
        if not isinstance(spec, MethodSpec):
            raise ConfigError(f"entry point {ep.name} = {ep.value!r} ({ENTRY_POINT_GROUP}): expected a MethodSpec, "
                              f"got {type(spec).__name__}")
        _METHODS.setdefault(spec.name, spec)


def list_methods(trainable: bool = False) -> tuple[str, ...]:
    """Names of the declared methods (only those with a training entry when ``trainable``)."""
    _discover()
    return tuple(sorted(n for n, m in _METHODS.items() if m.training is not None or not trainable))


def list_trainings() -> dict[str, Training]:
    """``wearpose train`` command name -> its :class:`Training`, of every declared method
    (:meth:`MethodSpec.training_commands`), sorted by name."""
    _discover()
    out = {c: t for m in _METHODS.values() for c, t in m.training_commands().items()}
    return dict(sorted(out.items()))


def get_method(name: str) -> MethodSpec:
    """The declaration of method ``name`` (ConfigError listing the known ones)."""
    _discover()
    try:
        return _METHODS[name]
    except KeyError:
        raise ConfigError(f"unknown method {name!r}; declared: {', '.join(list_methods())}") from None


def find_estimator(name: str) -> tuple[MethodSpec, EstimatorEntry]:
    """The method that ships estimator ``name``, and its entry (ConfigError when none does)."""
    _discover()
    for m in _METHODS.values():
        for e in m.estimators:
            if e.name == name:
                return m, e
    raise ConfigError(f"unknown estimator {name!r}; available: {', '.join(list_estimators())}")


def register_estimator(name: str) -> Callable[[type[T]], type[T]]:
    """Class decorator adding an :class:`~wearpose.estimators.base.Estimator` under ``name``
    (the declared classes use it too, so importing a class registers it)."""
    def deco(cls: type[T]) -> type[T]:
        _REGISTRY[name] = cls
        return cls
    return deco


def list_estimators() -> tuple[str, ...]:
    """Names of the estimators available in this build: those of the declared methods whose
    module exists, plus any registered with :func:`register_estimator`."""
    _discover()
    declared = {e.name for m in _METHODS.values() for e in m.estimators if target_available(e.target)}
    return tuple(sorted(declared | set(_REGISTRY)))


def get_estimator(name: str) -> type:
    """The estimator class registered as ``name`` (ConfigError listing the known names)."""
    if name not in _REGISTRY:
        _discover()
        entry = next((e for m in _METHODS.values() for e in m.estimators if e.name == name), None)
        if entry is not None and target_available(entry.target):
            _REGISTRY.setdefault(name, resolve(entry.target))
    try:
        return _REGISTRY[name]
    except KeyError:
        raise ConfigError(f"unknown estimator {name!r}; available: {', '.join(list_estimators())}") from None
