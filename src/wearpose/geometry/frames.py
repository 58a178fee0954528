"""World-frame changes between wearpose's Y-up world and other conventions.

wearpose world: right-handed, Y up, a body at zero pose faces +Z with its left towards +X.
AMASS (and many mocap systems) use a Z-up world: AMASS root orientations already contain the
rotation that stands SMPL up in that world, so converting an AMASS world to ours is one fixed
rotation applied on the left of root orientations and to translations.
"""

from __future__ import annotations

import torch

#: Maps Z-up world coordinates (x, y, z) to Y-up (x, z, -y): a -90 deg rotation about X.
Z_UP_TO_Y_UP = torch.tensor([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]], dtype=torch.float64)
#: Inverse of :data:`Z_UP_TO_Y_UP`.
Y_UP_TO_Z_UP = Z_UP_TO_Y_UP.T.contiguous()


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
