"""Pose estimators: the shared protocol, checkpoints, registry, and one subpackage per method.

Public API: :class:`Estimator`, :class:`PoseTrack`, :class:`PoseFrame`, :class:`SensorFrame`,
:func:`iter_frames`, :func:`get_estimator` / :func:`register_estimator` / :func:`list_estimators`,
:class:`Checkpoint`, :func:`save_checkpoint`, :func:`load_checkpoint`, :func:`fingerprint`,
:class:`CheckpointMismatchError`. Methods: ``empose`` (:mod:`wearpose.estimators.empose`).
"""

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
