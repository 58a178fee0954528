"""Segment estimator for dense kits (no weights): each instrumented body segment takes its
sensor's calibrated orientation; see :mod:`wearpose.estimators.segments.estimator`.

This file is the method's declaration (:data:`METHOD`); the names below are imported on first use.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from wearpose.estimators.method import EstimatorEntry, MethodSpec, lazy_exports

if TYPE_CHECKING:
    from wearpose.estimators.segments.estimator import SEGMENT_JOINTS, SegmentsEstimator

METHOD = MethodSpec(
    name="segments",
    summary="segment orientations from calibrated IMUs on dense kits (no weights, nothing to train)",
    estimators=(EstimatorEntry("segments", "wearpose.estimators.segments.estimator:SegmentsEstimator"),),
)

__all__ = ["METHOD", "SegmentsEstimator", "SEGMENT_JOINTS"]

__getattr__ = lazy_exports(__name__, {"SegmentsEstimator": "estimator", "SEGMENT_JOINTS": "estimator"})
