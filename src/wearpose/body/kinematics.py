"""Forward kinematics on a joint tree (no skinning). Differentiable, any batch shape."""

from __future__ import annotations

import math
from collections.abc import Sequence
from functools import lru_cache
from typing import Any

import torch

from wearpose.body.skeleton import PARENTS


#: Batches up to this size (flattened) use the level-by-level path of :func:`forward_kinematics`:
#: there the cost is per torch call (8 products instead of 23 joints). The two give bit-equal
#: values but gradients summed in another order, so larger batches keep the per-joint loop
#: (about as fast there: 4.5 vs 4.3 ms CPU at 1024), and with it the autograd rounding that
#: EM-POSE's closed-form gradient is pinned to (tests/estimators/test_empose_fastgrad).
LEVEL_FK_MAX_BATCH = 64


@lru_cache(maxsize=16)
def _level_plan(parents: tuple[int, ...]) -> tuple[tuple[int, int, int, tuple[int, ...]], ...] | None:
    """Joints grouped by tree depth, when each depth is one contiguous run of joint ids in
    increasing depth (true for SMPL's order). Per level: (first, end, parent level, parent ids
    local to that level). ``None`` when the order does not allow it."""
    depth: list[int] = []
    for j, p in enumerate(parents):
        if p >= j:
            return None
        depth.append(0 if p < 0 else depth[p] + 1)
    if depth != sorted(depth) or depth.count(0) != 1:
        return None
    starts = [depth.index(d) for d in range(max(depth) + 1)] + [len(parents)]
    return tuple((starts[d], starts[d + 1], d - 1, tuple(parents[j] - starts[d - 1] for j in range(starts[d], starts[d + 1])))
                 for d in range(1, max(depth) + 1))


def _fk_levels(local_rot: torch.Tensor, rest_joints: torch.Tensor, parents: tuple[int, ...],
               plan: tuple[tuple[int, int, int, tuple[int, ...]], ...]) -> tuple[torch.Tensor, torch.Tensor]:
    """:func:`forward_kinematics` one tree level per step: a joint's ``[R | t]`` block ``(..., 3, 4)``
    is its parent's block times its own homogeneous ``[[R_local, offset], [0, 0, 0, 1]]``, one
    matrix product per level (the root's offset is its rest position).

    Bit-equal to the per-joint loop: every product is a dot of 3 terms (the fourth, ``t * 0`` for
    a rotation entry and ``t * 1`` for a translation, adds exactly the loop's ``+ 0`` / ``+ t``)
    computed by the same small-matrix kernel (tested)."""
    par = list(parents[1:])
    offset = torch.cat([rest_joints[..., :1, :], rest_joints[..., 1:, :] - rest_joints[..., par, :]], -2)
    top = torch.cat([local_rot, offset.unsqueeze(-1)], dim=-1)  # (..., J, 3, 4)
    last = top.new_tensor([0.0, 0.0, 0.0, 1.0]).expand(*top.shape[:-2], 1, 4)
    child = torch.cat([top, last], dim=-2)  # (..., J, 4, 4) homogeneous
    levels = [top[..., :plan[0][0], :, :]]
    for a, b, pl, local in plan:
        P = levels[pl]
        if local == tuple(range(local[0], local[0] + len(local))):
            Pp = P[..., local[0]:local[0] + len(local), :, :]
        elif len(set(local)) == 1:
            Pp = P[..., local[0]:local[0] + 1, :, :]  # broadcast: every joint of the level has this parent
        else:
            Pp = P[..., list(local), :, :]
        levels.append(Pp @ child[..., a:b, :, :])
    T = torch.cat(levels, dim=-3)
    return T[..., :3], T[..., 3]


@lru_cache(maxsize=64)
def _level_steps(parents: tuple[int, ...], n: int, device: torch.device
                 ) -> tuple[tuple[int, ...], tuple[tuple[int, str, Any], ...], torch.Tensor] | None:
    """The plan of :func:`_fk_levels_nograd` for a flat batch of ``n``: split sizes of the
    joint-major ``(J * n, 4, 4)`` blocks by level; per level the parent level and how its parents'
    blocks are taken ("all": the whole parent level, "narrow": a run of it, "expand": one parent
    for every joint, "index": ids); the parent ids of joints 1.. as a tensor."""
    plan = _level_plan(parents)
    if plan is None:
        return None
    starts = [0] + [a for a, _, _, _ in plan] + [len(parents)]
    sizes = tuple(n * (starts[i + 1] - starts[i]) for i in range(len(starts) - 1))
    steps: list[tuple[int, str, Any]] = []
    for a, b, pl, local in plan:
        k, level_size = b - a, starts[pl + 1] - starts[pl]
        if local == tuple(range(level_size)):
            steps.append((pl, "all", None))
        elif local == tuple(range(local[0], local[0] + k)):
            steps.append((pl, "narrow", (local[0] * n, k * n)))
        elif len(set(local)) == 1:
            steps.append((pl, "expand", (local[0] * n, k)))
        else:
            steps.append((pl, "index", torch.tensor([q * n + i for q in local for i in range(n)], device=device)))
    return sizes, tuple(steps), torch.tensor(parents[1:], device=device)


def _fk_levels_nograd(local_rot: torch.Tensor, rest_joints: torch.Tensor, parents: tuple[int, ...]
                      ) -> tuple[torch.Tensor, torch.Tensor] | None:
    """:func:`_fk_levels` without autograd, for small batches where the cost is per torch call:
    the same ``(4, 4)`` blocks and products (bit-equal, tested), laid out joint-major ``(J, n, 4,
    4)`` so that each level is one ``bmm`` written in place and most parent blocks are a level
    as it is (no per-level slicing, reshaping and final concatenation). ``None`` when the joint
    order has no level plan."""
    J = local_rot.shape[-3]
    batch = local_rot.shape[:-3]
    n = math.prod(batch)
    got = _level_steps(parents, n, local_rot.device)
    if got is None:
        return None
    sizes, steps, par = got
    if n == 1:  # joint-major is the given layout: one view, not a reshape and a transpose
        R, rest = local_rot.reshape(J, 1, 3, 3), rest_joints.reshape(J, 1, 3)
    else:
        R = local_rot.reshape(n, J, 3, 3).transpose(0, 1)  # (J, n, 3, 3)
        rest = rest_joints.reshape(n, J, 3).transpose(0, 1)  # (J, n, 3)
    offset = torch.cat([rest[:1], rest[1:] - rest.index_select(0, par)])  # (J, n, 3): root's is its rest position
    last = _last_row(local_rot.dtype, local_rot.device).expand(J, n, 1, 4)
    child = torch.cat([torch.cat([R, offset.unsqueeze(-1)], -1), last], -2).view(J * n, 4, 4)
    C = child.split_with_sizes(sizes)  # (Tensor.split's Python wrapper cost as much as the split)
    T = torch.empty_like(child)
    Ts = T.split_with_sizes(sizes)
    Ts[0].copy_(C[0])
    for d, (pl, how, arg) in enumerate(steps, 1):
        P = Ts[pl]
        if how == "narrow":
            P = P.narrow(0, arg[0], arg[1])
        elif how == "expand":  # (at n = 1 a stride-0 batch, no copy)
            P = P.narrow(0, arg[0], n).expand(arg[1], n, 4, 4).reshape(-1, 4, 4) if n > 1 else P[arg[0]].expand(arg[1], 4, 4)
        elif how == "index":
            P = P.index_select(0, arg)
        torch.bmm(P, C[d], out=Ts[d])
    T = T.view(*batch, J, 4, 4) if n == 1 else T.view(J, n, 4, 4).transpose(0, 1).reshape(*batch, J, 4, 4)
    return T[..., :3, :3], T[..., :3, 3]


@lru_cache(maxsize=16)
def _last_row(dtype: torch.dtype, device: torch.device) -> torch.Tensor:
    """``[0, 0, 0, 1]``: the bottom row of a homogeneous transform (made once per dtype and device)."""
    return torch.tensor([0.0, 0.0, 0.0, 1.0], dtype=dtype, device=device)


def forward_kinematics(
    local_rot: torch.Tensor,
    rest_joints: torch.Tensor,
    parents: Sequence[int] = PARENTS,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Global joint rotations and positions from local rotations and a rest skeleton.

    Joint frames are aligned with the body frame at rest (SMPL convention), so the offset of a
    joint from its parent is ``rest_joints[j] - rest_joints[parent]`` expressed in the parent's
    frame.

    Small batches (up to :data:`LEVEL_FK_MAX_BATCH`) go one tree level at a time (9 levels for
    SMPL instead of 23 joints; without autograd, each level one in-place ``bmm`` on a joint-major
    layout, :func:`_fk_levels_nograd`); larger ones joint by joint. All compute the same products.

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
    par = parents if type(parents) is tuple else tuple(int(p) for p in parents)  # SMPL's PARENTS is one already
    plan = _level_plan(par) if J > 1 else None
    if plan is not None and math.prod(batch) <= LEVEL_FK_MAX_BATCH:
        if not (torch.is_grad_enabled() and (local_rot.requires_grad or rest_joints.requires_grad)):
            fast = _fk_levels_nograd(local_rot, rest_joints, par)
            if fast is not None:
                return fast
        return _fk_levels(local_rot, rest_joints, par, plan)
    return _fk_loop(local_rot, rest_joints, parents)


def _fk_loop(local_rot: torch.Tensor, rest_joints: torch.Tensor, parents: Sequence[int]
             ) -> tuple[torch.Tensor, torch.Tensor]:
    """:func:`forward_kinematics` joint by joint (any parent order with parents first)."""
    J = local_rot.shape[-3]
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
