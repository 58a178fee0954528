"""Rotations, frame changes and unit conversion: the only place these live.

Conventions (see DESIGN.md):
- rotation matrices ``(..., 3, 3)`` inside the library; a global rotation maps a local frame
  to the world;
- quaternions are ``(w, x, y, z)`` and unit-norm;
- 6D is the first two columns of the matrix, flattened column-major as ``(a1, a2)``
  (Zhou et al. 2019), shape ``(..., 6)``;
- axis-angle / exponential map ``(..., 3)``: direction = axis, norm = angle in radians;
- Euler angles follow BVH semantics: intrinsic, matrices multiplied in the channel order
  (``"ZXY"`` means ``R = Rz @ Rx @ Ry``).

Rotation maths delegates to ``roma`` (BSD-3, well tested, differentiable, numerically careful
near 0 and pi), imported on first use; axis-angle, 6D and quaternion to matrix are written in
``rotations`` with roma's arithmetic (equal results, tested), so importing the library does not
import roma (and torch._dynamo with it). This module fixes our conventions on top of it.
All functions accept any leading batch shape and work on torch tensors; numpy arrays are
accepted by the ``*_np`` helpers only where file readers need them.
"""

from wearpose.geometry.rotations import (
    axis_angle_to_matrix,
    euler_to_matrix,
    geodesic_angle,
    smooth_geodesic_angle,
    twist_angle,
    matrix_to_axis_angle,
    matrix_to_euler,
    matrix_to_quat,
    matrix_to_rot6d,
    project_to_so3,
    quat_to_matrix,
    rot6d_to_matrix,
    rotation_between,
    rotation_x,
    rotation_y,
    heading,
    vector_heading,
    best_yaw,
    rotation_z,
    skew,
    slerp_matrix,
)
from wearpose.geometry.frames import (
    SMPL_TO_X_FORWARD_BODY,
    Z_UP_TO_Y_UP,
    Y_UP_TO_Z_UP,
    change_world_rotation,
    change_world_points,
    MIRROR_X,
    mirror_rotation,
    mirror_points,
    TO_UNITY,
    to_unity_points,
    to_unity_rotation,
    to_unity_quat,
    MVN_TO_WEARPOSE,
    mvn_segment_to_wearpose,
    wearpose_to_mvn_segment,
    WORLD_AXES,
    world_frame_description,
)
from wearpose.geometry.units import (
    CM_TO_M,
    DEG_TO_RAD,
    INCH_TO_M,
    MM_TO_M,
    M_TO_MM,
    M_TO_CM,
    RAD_TO_DEG,
    GRAVITY,
)

__all__ = [
    "axis_angle_to_matrix", "matrix_to_axis_angle", "quat_to_matrix", "matrix_to_quat",
    "rot6d_to_matrix", "matrix_to_rot6d", "euler_to_matrix", "matrix_to_euler",
    "geodesic_angle", "smooth_geodesic_angle", "twist_angle", "slerp_matrix", "project_to_so3", "rotation_between",
    "rotation_x", "rotation_y", "rotation_z", "skew", "heading", "vector_heading", "best_yaw",
    "Z_UP_TO_Y_UP", "Y_UP_TO_Z_UP", "SMPL_TO_X_FORWARD_BODY", "change_world_rotation", "change_world_points",
    "MIRROR_X", "mirror_rotation", "mirror_points",
    "TO_UNITY", "to_unity_points", "to_unity_rotation", "to_unity_quat",
    "MVN_TO_WEARPOSE", "mvn_segment_to_wearpose", "wearpose_to_mvn_segment", "WORLD_AXES",
    "world_frame_description",
    "CM_TO_M", "MM_TO_M", "M_TO_MM", "M_TO_CM", "INCH_TO_M", "DEG_TO_RAD", "RAD_TO_DEG", "GRAVITY",
]
