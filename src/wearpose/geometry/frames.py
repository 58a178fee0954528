"""World-frame changes between wearpose's Y-up world and other conventions.

wearpose world: right-handed, Y up, a body at zero pose faces +Z with its left towards +X.
AMASS (and many mocap systems) use a Z-up world: AMASS root orientations already contain the
rotation that stands SMPL up in that world, so converting an AMASS world to ours is one fixed
rotation applied on the left of root orientations and to translations.
"""

from __future__ import annotations

import torch

from wearpose.geometry.rotations import matrix_to_quat

#: Maps Z-up world coordinates (x, y, z) to Y-up (x, z, -y): a -90 deg rotation about X.
Z_UP_TO_Y_UP = torch.tensor([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]], dtype=torch.float64)
#: Inverse of :data:`Z_UP_TO_Y_UP`.
Y_UP_TO_Z_UP = Z_UP_TO_Y_UP.T.contiguous()
#: SMPL joint-frame axes (x left, y up, z forward at zero pose) -> the axes of a segment frame
#: that is x forward, y left, z up (Xsens MVN's segment frames, aligned with its Z-up world in the
#: T-pose facing +X): ``v_B = SMPL_TO_X_FORWARD_BODY @ v_J``. An MVN segment orientation ``R_GB``
#: is the SMPL global joint rotation ``Z_UP_TO_Y_UP @ R_GB @ SMPL_TO_X_FORWARD_BODY`` (a T-pose
#: facing MVN's +X stands facing +X in wearpose's world).
SMPL_TO_X_FORWARD_BODY = torch.tensor([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]], dtype=torch.float64)


def change_world_rotation(C: torch.Tensor, R: torch.Tensor) -> torch.Tensor:
    """Re-express global rotations in a new world frame.

    Args:
        C: ``(3, 3)`` rotation mapping old-world coordinates to new-world coordinates.
        R: ``(..., 3, 3)`` global rotations (local frame -> old world).

    Returns:
        ``(..., 3, 3)`` rotations local frame -> new world, ``C @ R``.
    """
    return C.to(R) @ R


def change_world_points(C: torch.Tensor, p: torch.Tensor) -> torch.Tensor:
    """Re-express points/vectors ``(..., 3)`` in a new world frame: ``C @ p``."""
    return p @ C.to(p).T


#: Reflection through the body's sagittal plane at zero pose (x -> -x: left <-> right).
MIRROR_X = torch.diag(torch.tensor([-1.0, 1.0, 1.0], dtype=torch.float64))


def mirror_rotation(R: torch.Tensor) -> torch.Tensor:
    """The left/right mirror image of rotations ``(..., 3, 3)``: ``M R M`` with ``M`` =
    :data:`MIRROR_X` (still a proper rotation; local or global, since ``M`` is its own inverse)."""
    M = MIRROR_X.to(R)
    return M @ R @ M


def mirror_points(p: torch.Tensor) -> torch.Tensor:
    """The left/right mirror image of points/vectors ``(..., 3)`` (x negated)."""
    return p * MIRROR_X.diagonal().to(p)


#: wearpose world (right-handed, Y up, the body faces +Z with its left at +X) -> Unity's world
#: (left-handed, Y up, a humanoid faces +Z with its left at -X): x is negated.
TO_UNITY = torch.diag(torch.tensor([-1.0, 1.0, 1.0], dtype=torch.float64))


def to_unity_points(p: torch.Tensor) -> torch.Tensor:
    """Points/vectors ``(..., 3)`` in wearpose's world (m) as Unity coordinates (m): ``(-x, y, z)``.

    The two worlds share Y up and the facing direction +Z; Unity is left-handed, so the axis
    across the body flips: a point at the subject's left (+X here) is at -X in Unity.
    """
    return p * TO_UNITY.diagonal().to(p)


def to_unity_rotation(R: torch.Tensor) -> torch.Tensor:
    """Rotations ``(..., 3, 3)`` (global, or local in SMPL's rest-aligned joint frames) as the
    same rotations in Unity's left-handed frame: ``M R M`` with ``M = diag(-1, 1, 1)``.

    The result maps Unity coordinates to Unity coordinates (``R_u p_u = M (R p)`` for
    ``p_u = M p``); it is a proper rotation. As a quaternion ``(w, x, y, z)`` it is
    ``(w, x, -y, -z)`` of the input (see :func:`to_unity_quat`).
    """
    M = TO_UNITY.to(R)
    return M @ R @ M


def to_unity_quat(R: torch.Tensor) -> torch.Tensor:
    """Rotations ``(..., 3, 3)`` in wearpose's world as Unity quaternions in Unity's component
    order ``(x, y, z, w)`` (the order of ``UnityEngine.Quaternion`` and of the VMC protocol)."""
    q = matrix_to_quat(to_unity_rotation(R))  # (w, x, y, z)
    return torch.cat([q[..., 1:], q[..., :1]], dim=-1)


#: Xsens MVN's Z-up world and segment axes (a segment at the T-pose has identity orientation:
#: x forward, y to the subject's left, z up) -> wearpose's (x left, y up, z forward): a cyclic
#: permutation of the axes, ``(x, y, z)_mvn -> (y, z, x)``. Rows: new axes in MVN coordinates.
MVN_TO_WEARPOSE = torch.tensor([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]], dtype=torch.float64)


def mvn_segment_to_wearpose(R: torch.Tensor) -> torch.Tensor:
    """MVN segment orientations ``(..., 3, 3)`` (segment axes -> MVN world, identity at MVN's
    T-pose) as wearpose global joint rotations (SMPL-style: identity at the T-pose, Y-up world
    facing +Z): ``C R C^T`` with ``C`` = :data:`MVN_TO_WEARPOSE` (both frames change)."""
    C = MVN_TO_WEARPOSE.to(R)
    return C @ R @ C.T


def wearpose_to_mvn_segment(R: torch.Tensor) -> torch.Tensor:
    """Inverse of :func:`mvn_segment_to_wearpose`."""
    C = MVN_TO_WEARPOSE.to(R)
    return C.T @ R @ C


#: wearpose's world axes: up, the direction a body at zero pose faces, and its left (module doc).
WORLD_AXES: dict[str, tuple[float, float, float]] = {"up": (0.0, 1.0, 0.0), "facing": (0.0, 0.0, 1.0),
                                                     "left": (1.0, 0.0, 0.0)}


def _axis_label(v: torch.Tensor) -> str:
    """A unit axis vector ``(3,)`` as ``"+X"``, ``"-Z"``, ...; any other vector as its components."""
    i = int(v.abs().argmax())
    if abs(abs(float(v[i])) - 1.0) > 1e-9:
        return "(" + ", ".join(f"{float(x):.6g}" for x in v) + ")"
    return ("+" if float(v[i]) > 0 else "-") + "XYZ"[i]


def world_frame_description(C: torch.Tensor | None = None, unit: str = "m") -> dict[str, str]:
    """How a file's world is laid out, for the metadata a file states its frame in.

    Args:
        C: ``(3, 3)`` rotation from wearpose's world to the file's (e.g. :data:`Y_UP_TO_Z_UP`
            for AMASS); default the identity (the file is in wearpose's world).
        unit: the file's length unit (``"m"`` or ``"cm"``).

    Returns:
        ``{"up": "+Y", "facing": "+Z", "left": "+X", "handedness": "right", "units": unit}``: the
        file's axes pointing up, the way a body at zero pose faces, and its left side.
    """
    M = torch.eye(3, dtype=torch.float64) if C is None else C.to(torch.float64)
    out = {k: _axis_label(M @ torch.tensor(v, dtype=torch.float64)) for k, v in WORLD_AXES.items()}
    hand = "right" if float(torch.linalg.det(M)) > 0 else "left"
    return {**out, "handedness": hand, "units": unit}
