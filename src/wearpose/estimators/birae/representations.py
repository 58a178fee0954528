"""BiRAE network inputs: root-relative sensor orientations (Eq. 1) in one of four parameterisations.

Sensors (kit ``mimu6``): left wrist, right wrist, left lower leg, right lower leg, head, root
(lower spine). With world orientations ``R_WS`` ``(T, 6, 3, 3)`` the five non-root sensors are
expressed in the root frame, ``R_rel = R_root^T R_i`` (Eq. 1,
:func:`wearpose.sensors.root_relative_orientations`), and flattened per frame:

- ``6param``: Appendix A, ``(r11, r21, r31, r32, r33, r22)`` per sensor, 30 values;
- ``3param``: the yaw-free subset ``(r31, r32, r33)`` (Eq. 3: pitch and roll only), 15 values;
- ``3param_rate``: 3-param plus the root-relative angular rate of each sensor (Sec. V-C: "the
  difference of two consecutive 3D orientations"), ``w_t = log(R_rel,t-1^T R_rel,t) * fps``
  (rad/s, sensor frame, first frame 0) times ``rate_scale``, 30 values; the rate is also the
  target of the auxiliary reconstruction head (Sec. IV-D);
- ``zhou6d``: Zhou et al.'s first two columns, 30 values.

The representations live in :mod:`wearpose.sensors.mimu` (they permute our Y-up frames to the
paper's Z-up before picking entries); this module only assembles the feature vector. No
accelerations are used (Sec. III-C).

Outputs: the 15 major SMPL joints (:data:`wearpose.body.MAJOR_JOINTS`) as exponential maps
(axis-angle, radians) of their local rotations; every other joint is the identity (Sec. IV-C).
"""

from __future__ import annotations

import torch

from wearpose.body.skeleton import MAJOR_JOINTS, NUM_JOINTS
from wearpose.errors import ShapeError
from wearpose.geometry import axis_angle_to_matrix, matrix_to_axis_angle
from wearpose.sensors import birae_3param, birae_6param, root_relative_orientations, zhou_6d

#: Kit ``mimu6`` sensor order; the root (lower spine) is last.
SENSORS: tuple[str, ...] = ("left_wrist", "right_wrist", "left_lower_leg", "right_lower_leg", "head", "root")
ROOT_INDEX = 5
NUM_OUT_JOINTS = len(MAJOR_JOINTS)  # 15
OUT_DIM = 3 * NUM_OUT_JOINTS  # 45


def input_dim(rep: str) -> int:
    """Feature width of representation ``rep`` for the 5 non-root sensors."""
    return {"6param": 30, "3param": 15, "3param_rate": 30, "zhou6d": 30}[rep]


def relative_orientations(R_world: torch.Tensor) -> torch.Tensor:
    """Eq. 1: ``(..., 6, 3, 3)`` world orientations (kit order, root last) -> ``(..., 5, 3, 3)``."""
    if R_world.shape[-3:] != (6, 3, 3):
        raise ShapeError(f"BiRAE: expected (..., 6, 3, 3) sensor orientations (kit mimu6), got {tuple(R_world.shape)}")
    return root_relative_orientations(R_world, root=ROOT_INDEX)


def angular_rate(R_rel: torch.Tensor, fps: float) -> torch.Tensor:
    """Root-relative angular rate ``(T, 5, 3)`` rad/s (sensor frame) from ``(T, 5, 3, 3)``; frame 0 is 0.

    ``w_t = log(R_{t-1}^T R_t) * fps``: at any frame rate it estimates the same physical rate,
    which keeps the frame-rate flexibility of Sec. V-E.
    """
    w = torch.zeros(*R_rel.shape[:-2], 3, dtype=R_rel.dtype, device=R_rel.device)
    if R_rel.shape[0] > 1:
        w[1:] = matrix_to_axis_angle(R_rel[:-1].transpose(-1, -2) @ R_rel[1:]) * float(fps)
    return w


def features(R_rel: torch.Tensor, rep: str, rate: torch.Tensor | None = None, rate_scale: float = 0.1) -> torch.Tensor:
    """Network input ``(..., D)`` from root-relative orientations ``(..., 5, 3, 3)``.

    Args:
        R_rel: root-relative orientations (Eq. 1).
        rep: ``6param`` / ``3param`` / ``3param_rate`` / ``zhou6d``.
        rate: ``(..., 5, 3)`` angular rate, rad/s (``3param_rate`` only).
        rate_scale: factor on the rate.
    """
    if rep == "6param":
        f = birae_6param(R_rel)
    elif rep in ("3param", "3param_rate"):
        f = birae_3param(R_rel)
        if rep == "3param_rate":
            if rate is None:
                raise ShapeError("BiRAE rep '3param_rate' needs the angular rate (..., 5, 3)")
            f = torch.cat([f, rate * rate_scale], dim=-1)
    elif rep == "zhou6d":
        f = zhou_6d(R_rel)
    else:
        raise ShapeError(f"unknown BiRAE input representation {rep!r}")
    return f.flatten(-2)


def pose_to_target(local_rot: torch.Tensor) -> torch.Tensor:
    """SMPL local rotations ``(..., 24, 3, 3)`` -> exp-map target ``(..., 15, 3)`` of the major joints."""
    return matrix_to_axis_angle(local_rot[..., list(MAJOR_JOINTS), :, :])


def target_to_pose(expmap: torch.Tensor, root: torch.Tensor | None = None) -> torch.Tensor:
    """Exp-map ``(..., 15, 3)`` -> SMPL local rotations ``(..., 24, 3, 3)``; others identity.

    Args:
        root: optional ``(..., 3, 3)`` root orientation (default identity: BiRAE predicts the
            pose "less rotation and translation of root").
    """
    shape = expmap.shape[:-2]
    out = torch.eye(3, dtype=expmap.dtype, device=expmap.device).expand(*shape, NUM_JOINTS, 3, 3).clone()
    out[..., list(MAJOR_JOINTS), :, :] = axis_angle_to_matrix(expmap)
    if root is not None:
        out[..., 0, :, :] = root
    return out
