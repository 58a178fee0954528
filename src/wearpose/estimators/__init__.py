"""Pose estimators: the shared protocol, checkpoints, registry, and one subpackage per method.

Public API: :class:`Estimator`, :class:`PoseTrack`, :class:`PoseFrame`, :class:`SensorFrame`,
:func:`iter_frames`, :func:`get_estimator` / :func:`register_estimator` / :func:`list_estimators`,
:class:`Checkpoint`, :func:`save_checkpoint`, :func:`load_checkpoint`, :func:`fingerprint`,
:class:`CheckpointMismatchError`. Methods: one subpackage each, declared by its ``METHOD``
(:mod:`wearpose.estimators.method`, read by :mod:`wearpose.estimators.registry`).

The names are imported on first use: reading the method declarations (``wearpose train
--help``) must not import torch (measured for building ``wearpose train empose``: 31 s at
load 17 with this file importing the protocol eagerly, 1.5 s lazily at load 9; 0.9 s before
the declarations, which did not read the estimators package at all).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from wearpose.estimators.method import lazy_exports

if TYPE_CHECKING:
    from wearpose.estimators.base import Estimator, PoseFrame, PoseTrack, SensorFrame, iter_frames
    from wearpose.estimators.checkpoint import (
        Checkpoint, CheckpointMismatchError, fingerprint, load_checkpoint, save_checkpoint,
    )
    from wearpose.estimators.registry import get_estimator, list_estimators, register_estimator

__all__ = [
    "Estimator", "PoseTrack", "PoseFrame", "SensorFrame", "iter_frames",
    "Checkpoint", "CheckpointMismatchError", "fingerprint", "load_checkpoint", "save_checkpoint",
    "get_estimator", "list_estimators", "register_estimator",
]

__getattr__ = lazy_exports(__name__, {
    **dict.fromkeys(("Estimator", "PoseTrack", "PoseFrame", "SensorFrame", "iter_frames"), "base"),
    **dict.fromkeys(("Checkpoint", "CheckpointMismatchError", "fingerprint", "load_checkpoint", "save_checkpoint"),
                    "checkpoint"),
    **dict.fromkeys(("get_estimator", "list_estimators", "register_estimator"), "registry"),
})
