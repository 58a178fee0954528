"""Evaluation: metrics as the papers define them (see :mod:`wearpose.evaluate.metrics`).

Functions return SI units (m, rad, m/s^3); :func:`to_report_units`, :func:`compute_all` and
:func:`format_table` produce report units (mm, deg, cm, km/s^3) at the edge.
"""

from wearpose.evaluate import metrics
from wearpose.evaluate.metrics import *  # noqa: F403 - the metrics API, listed once in metrics.__all__

__all__ = list(metrics.__all__)
