"""Calibration: EM-POSE subject offsets, sensor-to-segment and world alignment from a T-/I-pose
(BiRAE Eq. 2a-2d, TransPose/PIP), heading reset for drifting 6-axis IMUs, MI-Poser's T-pose
arm-span scale and alignment, and hand-eye calibration ``A X = Y B`` (MI-Poser App. B, Shah 2013).

Recording level: :func:`calibrate` (dispatch by method name), :func:`store_calibration`,
:func:`apply_calibration`. Tensor level: one function per procedure (module docs give the
equations, frames and units). Results: :class:`CalibrationResult` (JSON via ``to_dict``).
See ``docs/calibration.md``.
"""

from wearpose.calibration._common import CalibrationError, DegenerateCalibrationError, chordal_mean
from wearpose.calibration.api import apply_calibration, calibrate, fit_imu_noise, store_calibration
from wearpose.calibration.empose import empose_offsets, fit_offsets, per_frame_offsets
from wearpose.calibration.handeye import axyb_closed_form, handeye_transforms, solve_axyb
from wearpose.calibration.miposer import apply_miposer, em_to_world, miposer_tpose
from wearpose.calibration.result import METHODS, CalibrationResult
from wearpose.calibration.segment import (
    IPOSE_ANGLE, POSES, bone_orientations, calibration_pose, heading_correction, heading_reset, pose_targets,
    segment_calibration,
)

__all__ = [
    "calibrate", "fit_imu_noise", "store_calibration", "apply_calibration", "CalibrationResult", "METHODS",
    "CalibrationError", "DegenerateCalibrationError", "chordal_mean",
    "per_frame_offsets", "fit_offsets", "empose_offsets",
    "segment_calibration", "bone_orientations", "heading_reset", "heading_correction", "calibration_pose",
    "pose_targets", "POSES", "IPOSE_ANGLE",
    "miposer_tpose", "apply_miposer", "em_to_world",
    "solve_axyb", "axyb_closed_form", "handeye_transforms",
]
