"""Estimator registry: name -> class, with lazy imports so ``import wearpose.estimators`` stays cheap."""

from __future__ import annotations

import importlib
import importlib.util
from typing import Callable, TypeVar

from wearpose.errors import ConfigError

T = TypeVar("T")

#: Built-in estimators, imported on first use: name -> "module:Class".
#: A name whose module is not present in this build is not listed (see :func:`list_estimators`);
#: each method's subpackage owns its lines here.
_BUILTIN: dict[str, str] = {
    "empose": "wearpose.estimators.empose.estimator:EmposeEstimator",
    "empose-resnet": "wearpose.estimators.empose.baselines:ResNetEstimator",
    "empose-birnn": "wearpose.estimators.empose.baselines:BiRNNEstimator",
    "empose-twostage": "wearpose.estimators.empose.twostage:TwoStageEstimator",
    "empose-lbfgs": "wearpose.estimators.empose.optimization:LbfgsEstimator",
    "pip": "wearpose.estimators.pip.estimator:PipEstimator",
    "birae": "wearpose.estimators.birae.estimator:BiraeEstimator",
    "miposer": "wearpose.estimators.miposer.estimator:MiposerEstimator",
    "imuposer": "wearpose.estimators.miposer.baselines:ImuPoserEstimator",
    "segments": "wearpose.estimators.segments.estimator:SegmentsEstimator",
}
_REGISTRY: dict[str, type] = {}


def register_estimator(name: str) -> Callable[[type[T]], type[T]]:
    """Class decorator adding an :class:`~wearpose.estimators.base.Estimator` under ``name``."""
    def deco(cls: type[T]) -> type[T]:
        _REGISTRY[name] = cls
        return cls
    return deco


def _available(target: str) -> bool:
    try:
        return importlib.util.find_spec(target.split(":")[0]) is not None
    except ModuleNotFoundError:  # parent package absent
        return False


def list_estimators() -> tuple[str, ...]:
    """Names of the estimators available in this build (built-in ones whose module exists, plus registered)."""
    return tuple(sorted({n for n, t in _BUILTIN.items() if _available(t)} | set(_REGISTRY)))


def get_estimator(name: str) -> type:
    """The estimator class registered as ``name`` (ConfigError listing the known names)."""
    if name not in _REGISTRY and name in _BUILTIN and _available(_BUILTIN[name]):
        mod, cls = _BUILTIN[name].split(":")
        _REGISTRY.setdefault(name, getattr(importlib.import_module(mod), cls))
    try:
        return _REGISTRY[name]
    except KeyError:
        raise ConfigError(f"unknown estimator {name!r}; available: {', '.join(list_estimators())}") from None
