"""Root-relative normalisation of sensor inputs, as the papers do it.

- BiRAE Eq. 1: ``R^{R0 Bi}_t = (R^{T R0}_t)^-1 R^{T Bi}_t`` -- each non-root orientation
  expressed in the root sensor's frame (:func:`root_relative_orientations`).
- EM-POSE supp. Sec. 2.1: the root translation is removed and every quantity is rotated by the
  inverse of the *first frame's* root orientation:
  ``R^n_root(t) = R_root(0)^-1 R_root(t)``, ``p^n_s(t) = R_root(0)^-1 (p_s(t) - t_root(t))``,
  ``R^n_s(t) = R_root(0)^-1 R_s(t)`` (:func:`empose_normalize`).

Shapes are time first, then sensors; rotations map the sensor frame to the world (or to the
source frame for EM data -- the maths is the same).
"""

from __future__ import annotations

from typing import Sequence

import torch

from wearpose.errors import ShapeError


def root_relative_orientations(R: torch.Tensor, root: int = -1, keep_root: bool = False) -> torch.Tensor:
    """BiRAE Eq. 1: orientations relative to the root sensor.

    Args:
        R: ``(..., S, 3, 3)`` sensor orientations ``R_WS`` (world frame).
        root: index of the root sensor along the sensor axis (BiRAE: the lower-spine sensor;
            the last sensor of the ``mimu6`` and ``imu6`` kits).
        keep_root: keep the root's own (identity) entry.

    Returns:
        ``(..., S-1, 3, 3)`` (or ``(..., S, 3, 3)`` with ``keep_root``): ``R_root^T R_i`` for the
        non-root sensors, in kit order.
    """
    if R.dim() < 3 or R.shape[-2:] != (3, 3):
        raise ShapeError(f"root_relative_orientations: expected (..., S, 3, 3), got {tuple(R.shape)}")
    S = R.shape[-3]
    r = root % S
    rel = R[..., r:r + 1, :, :].transpose(-1, -2) @ R
    if keep_root:
        return rel
    idx = [i for i in range(S) if i != r]
    return rel[..., idx, :, :]


def empose_normalize(position: torch.Tensor, orientation: torch.Tensor, root_orientation: torch.Tensor,
                     root_translation: torch.Tensor) -> dict[str, torch.Tensor]:
    """EM-POSE supp. Sec. 2.1 normalisation of one sequence.

    Args:
        position: ``(T, S, 3)`` sensor positions, m.
        orientation: ``(T, S, 3, 3)`` sensor orientations.
        root_orientation: ``(T, 3, 3)`` root orientation ``R_root(t)`` (same frame as the sensors).
        root_translation: ``(T, 3)`` root translation ``t_root(t)``, m.

    Returns:
        dict with ``position`` ``(T, S, 3)``, ``orientation`` ``(T, S, 3, 3)`` and
        ``root_orientation`` ``(T, 3, 3)`` normalised; ``R0`` ``(3, 3)`` the first root
        orientation used.
    """
    if position.dim() != 3 or orientation.shape != (*position.shape, 3):
        raise ShapeError(f"empose_normalize: expected position (T, S, 3) and orientation (T, S, 3, 3), got "
                         f"{tuple(position.shape)} and {tuple(orientation.shape)}")
    R0T = root_orientation[0].transpose(-1, -2)
    p = (R0T @ (position - root_translation[:, None, :]).unsqueeze(-1)).squeeze(-1)
    return {"position": p, "orientation": R0T @ orientation, "root_orientation": R0T @ root_orientation,
            "R0": root_orientation[0]}


def select(names: Sequence[str], wanted: Sequence[str]) -> list[int]:
    """Indices of ``wanted`` sensor names in ``names`` (ShapeError naming the missing ones)."""
    missing = [w for w in wanted if w not in names]
    if missing:
        raise ShapeError(f"sensors {missing} not among {list(names)}")
    return [list(names).index(w) for w in wanted]
