"""Named static poses of the skeleton: the calibration poses (T-pose, I-pose).

A body-level fact, not a calibration step: the recording format prepends a T-pose
(:func:`wearpose.recording.prepend_tpose`), the simulator and the training data play it, and
calibration fits sensors to it, so it lives below all of them.
"""

from __future__ import annotations

import math

import torch

from wearpose.body.skeleton import JOINT_INDEX
from wearpose.errors import ConfigError
from wearpose.geometry import rotation_z

#: Calibration poses :func:`calibration_pose` knows.
POSES: tuple[str, ...] = ("tpose", "ipose")
#: I-pose arm angle: rotation of each upper arm down from the T-pose, about the body's forward
#: axis. 80 deg leaves the arms hanging just clear of the hips (our assumption; the papers give
#: no number). Pass ``ipose_angle`` to match a protocol.
IPOSE_ANGLE = math.radians(80.0)


def calibration_pose(pose: str, ipose_angle: float = IPOSE_ANGLE) -> torch.Tensor:
    """Local joint rotations ``(24, 3, 3)`` float64 of a calibration pose, root orientation identity.

    ``"tpose"``: SMPL zero pose (arms along +-X, facing +Z). ``"ipose"``: zero pose with the
    shoulders (SMPL joints 16/17) rotated down by ``ipose_angle`` (radians) about +-Z.

    Raises:
        ConfigError: an unknown pose name (the known ones are :data:`POSES`).
    """
    P = torch.eye(3, dtype=torch.float64).repeat(24, 1, 1)
    if pose == "tpose":
        return P
    if pose == "ipose":
        a = torch.tensor(float(ipose_angle), dtype=torch.float64)
        P[JOINT_INDEX["left_shoulder"]] = rotation_z(-a)  # +X (left arm) -> down
        P[JOINT_INDEX["right_shoulder"]] = rotation_z(a)
        return P
    raise ConfigError(f"calibration pose {pose!r} is unknown; expected one of {list(POSES)}")
