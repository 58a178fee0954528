"""Estimator registry: name -> class, with lazy imports so ``import wearpose.estimators`` stays cheap."""

from __future__ import annotations

import importlib
from typing import Callable, TypeVar

from wearpose.errors import ConfigError

T = TypeVar("T")

#: Built-in estimators, imported on first use: name -> "module:Class".
_BUILTIN: dict[str, str] = {"empose": "wearpose.estimators.empose.estimator:EmposeEstimator",
                            "empose-resnet": "wearpose.estimators.empose.baselines:ResNetEstimator",
                            "empose-birnn": "wearpose.estimators.empose.baselines:BiRNNEstimator"}
_REGISTRY: dict[str, type] = {}


def register_estimator(name: str) -> Callable[[type[T]], type[T]]:
    """Class decorator adding an :class:`~wearpose.estimators.base.Estimator` under ``name``."""
    def deco(cls: type[T]) -> type[T]:
        _REGISTRY[name] = cls
        return cls
    return deco


def list_estimators() -> tuple[str, ...]:
    return tuple(sorted(set(_BUILTIN) | set(_REGISTRY)))


def get_estimator(name: str) -> type:
    """The estimator class registered as ``name`` (ConfigError listing the known names)."""
    if name not in _REGISTRY and name in _BUILTIN:
        mod, cls = _BUILTIN[name].split(":")
        _REGISTRY.setdefault(name, getattr(importlib.import_module(mod), cls))
    try:
        return _REGISTRY[name]
    except KeyError:
        raise ConfigError(f"unknown estimator {name!r}; available: {', '.join(list_estimators())}") from None
