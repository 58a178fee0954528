"""Forward kinematics on a joint tree (no skinning). Differentiable, any batch shape."""

from __future__ import annotations

from collections.abc import Sequence

import torch

from wearpose.body.skeleton import PARENTS


def forward_kinematics(
    local_rot: torch.Tensor,
    rest_joints: torch.Tensor,
    parents: Sequence[int] = PARENTS,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Global joint rotations and positions from local rotations and a rest skeleton.

    Joint frames are aligned with the body frame at rest (SMPL convention), so the offset of a
    joint from its parent is ``rest_joints[j] - rest_joints[parent]`` expressed in the parent's
    frame.

    Args:
        local_rot: ``(..., J, 3, 3)`` rotation of each joint relative to its parent (joint 0:
            relative to the world).
        rest_joints: ``(..., J, 3)`` or ``(J, 3)`` joint positions at zero pose, metres.
        parents: parent index per joint, ``-1`` for the root; parents precede children.

    Returns:
        ``global_rot`` ``(..., J, 3, 3)`` (joint frame -> world) and ``joints`` ``(..., J, 3)``
        (metres, root placed at ``rest_joints[0]``; add translation outside).
    """
    J = local_rot.shape[-3]
    rest_joints = rest_joints.to(local_rot)
    batch = local_rot.shape[:-3]
    rest_joints = rest_joints.expand(*batch, J, 3)
    g_rot: list[torch.Tensor] = []
    g_pos: list[torch.Tensor] = []
    for j in range(J):
        p = parents[j]
        if p < 0:
            g_rot.append(local_rot[..., j, :, :])
            g_pos.append(rest_joints[..., j, :])
        else:
            offset = rest_joints[..., j, :] - rest_joints[..., p, :]
            g_rot.append(g_rot[p] @ local_rot[..., j, :, :])
            g_pos.append(g_pos[p] + (g_rot[p] @ offset.unsqueeze(-1)).squeeze(-1))
    return torch.stack(g_rot, dim=-3), torch.stack(g_pos, dim=-2)


def global_to_local(global_rot: torch.Tensor, parents: Sequence[int] = PARENTS) -> torch.Tensor:
    """Inverse of the rotation part of :func:`forward_kinematics`.

    Args:
        global_rot: ``(..., J, 3, 3)`` joint frame -> world.

    Returns:
        ``(..., J, 3, 3)`` rotations relative to the parent (root: relative to the world).
    """
    out = []
    for j, p in enumerate(parents):
        if p < 0:
            out.append(global_rot[..., j, :, :])
        else:
            out.append(global_rot[..., p, :, :].transpose(-1, -2) @ global_rot[..., j, :, :])
    return torch.stack(out, dim=-3)
