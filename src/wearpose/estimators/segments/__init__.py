"""Segment estimator for dense kits (no weights): each instrumented body segment takes its
sensor's calibrated orientation; see :mod:`wearpose.estimators.segments.estimator`."""

from wearpose.estimators.segments.estimator import SEGMENT_JOINTS, SegmentsEstimator

__all__ = ["SegmentsEstimator", "SEGMENT_JOINTS"]
