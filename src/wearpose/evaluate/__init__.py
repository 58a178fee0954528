"""Evaluation: metrics as the papers define them (see :mod:`wearpose.evaluate.metrics`).

Functions return SI units (m, rad, m/s^3); :func:`to_report_units`, :func:`compute_all` and
:func:`format_table` produce report units (mm, deg, cm, km/s^3) at the edge.
"""

from wearpose.evaluate.metrics import (
    ALL_JOINTS,
    BIRAE_JOINT_GROUPS,
    METRIC_UNITS,
    TranslationErrorCurve,
    compute_all,
    cumulative_translation_error,
    format_table,
    global_angular_error,
    jerk,
    jitter,
    joint_angle_errors,
    joint_position_errors,
    mask_joint_rotations,
    mesh_error,
    mpjae,
    mpjae_groups,
    mpjpe,
    pa_mpjpe,
    positional_error,
    procrustes_align,
    root_relative_global_rotations,
    sip_error,
    StanceSpeed,
    stance_foot_speed,
    to_report_units,
)

__all__ = [
    "ALL_JOINTS", "BIRAE_JOINT_GROUPS", "METRIC_UNITS", "TranslationErrorCurve",
    "compute_all", "cumulative_translation_error", "format_table", "global_angular_error",
    "jerk", "jitter", "joint_angle_errors", "joint_position_errors", "mask_joint_rotations",
    "mesh_error", "mpjae", "mpjae_groups", "mpjpe", "pa_mpjpe", "positional_error",
    "procrustes_align", "root_relative_global_rotations", "sip_error", "stance_foot_speed", "StanceSpeed",
    "to_report_units",
]
