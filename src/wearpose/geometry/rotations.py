"""Rotation representations and operations. Shapes: any leading batch ``...``.

Every function is pure, differentiable where the maths allows, and dtype/device preserving.

The three conversions every path needs (axis-angle, 6D and quaternion to matrix) are written
here, the same arithmetic as roma's (equal results, tested against roma); the rest delegate to
``roma``, imported on first use: roma 1.8 calls ``torch._dynamo.disable`` at import, which pulls
in dynamo, sympy and fx (~2 s, ~75 MiB) into every process that imports the body model.
"""

from __future__ import annotations

from types import ModuleType

import torch

from wearpose.errors import ShapeError

#: Angles (rad) below which axis-angle -> matrix uses the first-order form ``I + [aa]_x``
#: (roma's default threshold: Rodrigues' ``aa / |aa|`` is ill-conditioned there).
SMALL_ANGLE = 1e-6


def _roma() -> ModuleType:
    """roma, imported when a function that needs it is first called (module doc)."""
    import roma  # start-up: roma adds ~1.5 s to import wearpose.geometry

    return roma


def _check_last(x: torch.Tensor, shape: tuple[int, ...], name: str) -> None:
    if not isinstance(x, torch.Tensor):
        raise ShapeError(f"{name}: expected a torch.Tensor, got {type(x).__name__}")
    if tuple(x.shape[-len(shape):]) != shape:
        raise ShapeError(f"{name}: expected shape (..., {', '.join(map(str, shape))}), got {tuple(x.shape)}")


def skew(v: torch.Tensor) -> torch.Tensor:
    """Cross-product matrix ``[v]x`` ``(..., 3, 3)`` of vectors ``(..., 3)``: ``[v]x w = v x w``
    (antisymmetric; the derivative of ``R`` under an angular change ``v`` is ``[v]x R``)."""
    _check_last(v, (3,), "skew")
    z = torch.zeros_like(v[..., 0])
    x, y, w = v.unbind(-1)
    return torch.stack([torch.stack([z, -w, y], -1), torch.stack([w, z, -x], -1), torch.stack([-y, x, z], -1)], -2)


def axis_angle_to_matrix(aa: torch.Tensor) -> torch.Tensor:
    """Axis-angle / exponential map ``(..., 3)`` (radians) -> rotation matrix ``(..., 3, 3)``."""
    _check_last(aa, (3,), "axis_angle")
    theta = torch.linalg.vector_norm(aa, dim=-1)
    # Clamped, not masked: torch.where alone would give NaN gradients at theta = 0.
    k = aa / torch.clamp_min(theta[..., None], SMALL_ANGLE)
    kx, ky, kz = k.unbind(-1)
    s, c1 = torch.sin(theta), 1 - torch.cos(theta)
    xs, ys, zs = kx * s, ky * s, kz * s
    xy, xz, yz = kx * ky * c1, kx * kz * c1, ky * kz * c1
    xx, yy, zz = kx ** 2 * c1, ky ** 2 * c1, kz ** 2 * c1
    rodrigues = torch.stack([1 - yy - zz, xy - zs, xz + ys,
                             xy + zs, 1 - xx - zz, -xs + yz,
                             xz - ys, xs + yz, 1 - xx - yy], dim=-1)
    x, y, z = aa.unbind(-1)
    one = torch.ones_like(x)
    first_order = torch.stack([one, -z, y, z, one, -x, -y, x, one], dim=-1)
    R = torch.where((theta < SMALL_ANGLE)[..., None], first_order, rodrigues)
    return R.reshape(*aa.shape[:-1], 3, 3)


def matrix_to_axis_angle(R: torch.Tensor) -> torch.Tensor:
    """Rotation matrix ``(..., 3, 3)`` -> axis-angle ``(..., 3)`` with angle in ``[0, pi]``."""
    _check_last(R, (3, 3), "R")
    return _roma().rotmat_to_rotvec(R)


def quat_to_matrix(q: torch.Tensor) -> torch.Tensor:
    """Quaternion ``(..., 4)`` as ``(w, x, y, z)`` -> rotation matrix ``(..., 3, 3)``.

    The quaternion is normalised first, so slightly non-unit input (e.g. from files) is fine.
    """
    _check_last(q, (4,), "quaternion")
    q = q / q.norm(dim=-1, keepdim=True).clamp_min(1e-12)
    w, x, y, z = q.unbind(-1)
    x2, y2, z2, w2 = x * x, y * y, z * z, w * w
    xy, zw, xz, yw, yz, xw = x * y, z * w, x * z, y * w, y * z, x * w
    return torch.stack((x2 - y2 - z2 + w2, 2 * (xy - zw), 2 * (xz + yw),
                        2 * (xy + zw), -x2 + y2 - z2 + w2, 2 * (yz - xw),
                        2 * (xz - yw), 2 * (yz + xw), -x2 - y2 + z2 + w2), dim=-1).reshape(*q.shape[:-1], 3, 3)


def matrix_to_quat(R: torch.Tensor) -> torch.Tensor:
    """Rotation matrix ``(..., 3, 3)`` -> unit quaternion ``(..., 4)`` as ``(w, x, y, z)``, w >= 0."""
    _check_last(R, (3, 3), "R")
    roma = _roma()
    q = roma.quat_xyzw_to_wxyz(roma.rotmat_to_unitquat(R))
    return torch.where(q[..., :1] < 0, -q, q)


def rot6d_to_matrix(d6: torch.Tensor) -> torch.Tensor:
    """6D representation ``(..., 6)`` = first two columns ``(a1, a2)`` -> rotation ``(..., 3, 3)``.

    Gram-Schmidt as in Zhou et al. (CVPR 2019); any 6-vector with non-parallel halves maps to a
    valid rotation, which is why networks output it.
    """
    _check_last(d6, (6,), "rot6d")
    # Columns of a (..., 3, 2) matrix, as roma reads them (the strided layout fixes the rounding
    # of the sums: equal results to roma's special_gramschmidt).
    M = torch.stack([d6[..., :3], d6[..., 3:]], dim=-1)
    x, y = M[..., 0], M[..., 1]
    x = x / torch.linalg.vector_norm(x, dim=-1, keepdim=True)
    y = y - torch.sum(x * y, dim=-1, keepdim=True) * x
    y = y / torch.linalg.vector_norm(y, dim=-1, keepdim=True)
    return torch.stack((x, y, torch.linalg.cross(x, y, dim=-1)), dim=-1)


def matrix_to_rot6d(R: torch.Tensor) -> torch.Tensor:
    """Rotation ``(..., 3, 3)`` -> 6D ``(..., 6)``: first column then second column."""
    _check_last(R, (3, 3), "R")
    return torch.cat([R[..., :, 0], R[..., :, 1]], dim=-1)


def rotation_x(angle: torch.Tensor) -> torch.Tensor:
    """Rotation about X by ``angle`` ``(...)`` radians -> ``(..., 3, 3)``."""
    c, s = torch.cos(angle), torch.sin(angle)
    o, z = torch.ones_like(angle), torch.zeros_like(angle)
    return torch.stack([o, z, z, z, c, -s, z, s, c], dim=-1).reshape(*angle.shape, 3, 3)


def rotation_y(angle: torch.Tensor) -> torch.Tensor:
    """Rotation about Y by ``angle`` ``(...)`` radians -> ``(..., 3, 3)``."""
    c, s = torch.cos(angle), torch.sin(angle)
    o, z = torch.ones_like(angle), torch.zeros_like(angle)
    return torch.stack([c, z, s, z, o, z, -s, z, c], dim=-1).reshape(*angle.shape, 3, 3)


def heading(R: torch.Tensor) -> torch.Tensor:
    """Yaw (rad, about +Y) of the forward axis (+Z column) of ``R`` ``(..., 3, 3)``: 0 facing +Z."""
    return vector_heading(R[..., :, 2])


def vector_heading(v: torch.Tensor) -> torch.Tensor:
    """Yaw (rad, about +Y, in (-pi, pi]) of direction ``v`` ``(..., 3)`` seen from above:
    ``atan2(x, z)``, 0 along +Z, +pi/2 along +X (``rotation_y(a) @ e_z`` has heading ``a``).
    The vertical component is ignored; a vertical ``v`` gives ``atan2(0, 0) = 0``."""
    return torch.atan2(v[..., 0], v[..., 2])


def best_yaw(M: torch.Tensor) -> torch.Tensor:
    """Angle ``psi`` ``(...)`` rad of the rotation about +Y closest (Frobenius) to ``M`` ``(..., 3, 3)``.

    ``rotation_y(psi)`` maximises ``trace(rotation_y(psi)^T M)`` (1-D Wahba), so
    ``psi = atan2(M[0, 2] - M[2, 0], M[0, 0] + M[2, 2])``. Not :func:`heading`: for a pure
    rotation about +Y both give its angle, but for a tilted ``M`` this is the yaw of the whole
    rotation (used for yaw *errors* ``R_est R_true^T``), while :func:`heading` is where one axis
    points. ``M`` need not be a rotation (e.g. a sum of rotations).
    """
    return torch.atan2(M[..., 0, 2] - M[..., 2, 0], M[..., 0, 0] + M[..., 2, 2])


def rotation_z(angle: torch.Tensor) -> torch.Tensor:
    """Rotation about Z by ``angle`` ``(...)`` radians -> ``(..., 3, 3)``."""
    c, s = torch.cos(angle), torch.sin(angle)
    o, z = torch.ones_like(angle), torch.zeros_like(angle)
    return torch.stack([c, -s, z, s, c, z, z, z, o], dim=-1).reshape(*angle.shape, 3, 3)


_AXIS_FN = {"X": rotation_x, "Y": rotation_y, "Z": rotation_z}


def euler_to_matrix(angles: torch.Tensor, order: str) -> torch.Tensor:
    """Intrinsic Euler angles (radians) -> rotation matrix, BVH semantics.

    Args:
        angles: ``(..., k)`` angles in radians, one per letter of ``order``.
        order: axis letters, e.g. ``"ZXY"``; ``R = R_Z(a0) @ R_X(a1) @ R_Y(a2)``. This is how
            BVH channels listed as ``Zrotation Xrotation Yrotation`` are composed.

    Returns:
        ``(..., 3, 3)`` rotation matrices.
    """
    order = order.upper()
    if not order or any(c not in "XYZ" for c in order):
        raise ShapeError(f"euler order must be letters from XYZ, got {order!r}")
    if angles.shape[-1] != len(order):
        raise ShapeError(f"euler angles: expected last dim {len(order)} for order {order!r}, got {tuple(angles.shape)}")
    R = _AXIS_FN[order[0]](angles[..., 0])
    for i, c in enumerate(order[1:], start=1):
        R = R @ _AXIS_FN[c](angles[..., i])
    return R


def matrix_to_euler(R: torch.Tensor, order: str) -> torch.Tensor:
    """Rotation ``(..., 3, 3)`` -> intrinsic Euler angles ``(..., 3)`` (radians), inverse of
    :func:`euler_to_matrix` for three distinct axes (used by the BVH writer)."""
    _check_last(R, (3, 3), "R")
    order = order.upper()
    if len(order) != 3 or len(set(order)) != 3 or any(c not in "XYZ" for c in order):
        raise ShapeError(f"matrix_to_euler needs three distinct axes, got {order!r}")
    # roma's intrinsic convention uses upper-case axis letters.
    return _roma().rotmat_to_euler(order, R, degrees=False)


def geodesic_angle(R1: torch.Tensor, R2: torch.Tensor) -> torch.Tensor:
    """Angle (radians, in ``[0, pi]``) of ``R1^T R2``; ``(..., 3, 3)`` x2 -> ``(...)``.

    Uses a numerically careful formulation (roma) that stays accurate near 0 and pi.
    """
    _check_last(R1, (3, 3), "R1")
    _check_last(R2, (3, 3), "R2")
    return _roma().rotmat_geodesic_distance(R1, R2)


def smooth_geodesic_angle(R1: torch.Tensor, R2: torch.Tensor, eps: float = 1e-12) -> torch.Tensor:
    """Angle (radians, ``[0, pi]``) of ``R1^T R2`` with finite gradients everywhere, for losses;
    ``(..., 3, 3)`` x2 -> ``(...)``.

    ``atan2(sin, cos)`` of the relative rotation ``M``: ``sin`` = the norm of ``vee((M - M^T) / 2)``
    (smoothed by ``eps`` under the square root), ``cos`` = ``(tr M - 1) / 2``. Unlike
    :func:`geodesic_angle` (``asin``, infinite slope at pi) the slope is 1 per radian up to pi, so
    a loss on it pulls a 180 deg error back as hard as a small one; the angle is off by at most
    ``sqrt(eps)`` near 0 and pi.
    """
    _check_last(R1, (3, 3), "R1")
    _check_last(R2, (3, 3), "R2")
    M = R1.transpose(-1, -2) @ R2
    v = torch.stack([M[..., 2, 1] - M[..., 1, 2], M[..., 0, 2] - M[..., 2, 0], M[..., 1, 0] - M[..., 0, 1]], -1) / 2
    s = torch.sqrt((v * v).sum(-1) + eps)
    c = (M[..., 0, 0] + M[..., 1, 1] + M[..., 2, 2] - 1) / 2
    return torch.atan2(s, c)


def twist_angle(R: torch.Tensor, axis: torch.Tensor) -> torch.Tensor:
    """Magnitude (radians, ``[0, pi]``) of the twist of ``R`` ``(..., 3, 3)`` about the unit
    ``axis`` ``(3,)`` (the swing-twist decomposition ``R = swing @ twist``, ``twist`` about
    ``axis``): ``2 atan2(|q_v . axis|, q_w)`` of ``R``'s quaternion (``q_w >= 0``). For a joint's
    local rotation and its bone axis this is the turn about the bone -> ``(...)``."""
    q = matrix_to_quat(R)
    a = axis.to(q)
    return 2 * torch.atan2((q[..., 1:] * a).sum(-1).abs(), q[..., 0])


def slerp_matrix(R0: torch.Tensor, R1: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
    """Spherical linear interpolation between rotations.

    Args:
        R0, R1: ``(..., 3, 3)`` endpoints.
        t: ``(...)`` interpolation weights in ``[0, 1]`` (broadcast against the batch).

    Returns:
        ``(..., 3, 3)``: ``R0 @ exp(t * log(R0^T R1))`` (shortest path).
    """
    rel = matrix_to_axis_angle(R0.transpose(-1, -2) @ R1)
    return R0 @ axis_angle_to_matrix(rel * t.to(rel).unsqueeze(-1))


def project_to_so3(M: torch.Tensor) -> torch.Tensor:
    """Nearest rotation (Frobenius) to each ``(..., 3, 3)`` matrix, via SVD with det fix."""
    _check_last(M, (3, 3), "M")
    return _roma().special_procrustes(M)


def rotation_between(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """Minimal rotation taking direction ``a`` to direction ``b``; ``(..., 3)`` x2 -> ``(..., 3, 3)``.

    For antiparallel vectors a rotation of pi about an axis orthogonal to ``a`` is returned.
    """
    _check_last(a, (3,), "a")
    _check_last(b, (3,), "b")
    a = a / a.norm(dim=-1, keepdim=True).clamp_min(1e-12)
    b = b / b.norm(dim=-1, keepdim=True).clamp_min(1e-12)
    a, b = torch.broadcast_tensors(a, b)
    axis = torch.cross(a, b, dim=-1)
    s = axis.norm(dim=-1, keepdim=True)
    c = (a * b).sum(-1, keepdim=True)
    angle = torch.atan2(s, c)
    # Fallback axis for (anti)parallel input: anything orthogonal to a.
    helper = torch.where(a[..., :1].abs() < 0.9, torch.tensor([1.0, 0.0, 0.0]).to(a), torch.tensor([0.0, 1.0, 0.0]).to(a))
    ortho = torch.cross(a, helper, dim=-1)
    ortho = ortho / ortho.norm(dim=-1, keepdim=True)
    unit_axis = torch.where(s > 1e-9, axis / s.clamp_min(1e-12), ortho)
    return axis_angle_to_matrix(unit_axis * angle)
