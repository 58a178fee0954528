"""SMPL rest joints for the motion readers: the default body model's, and a typed-in SMPL-like
template that tests use as an independent synthetic skeleton.
"""

from __future__ import annotations

import functools
from typing import Any

import torch

from wearpose.body.model import BodyModel

#: SMPL-neutral-like rest joints (metres), zero pose: T-pose facing +Z, left at +X, Y up.
#: Typed in to resemble SMPL's neutral J at betas = 0 (pelvis at about (0, -0.22, 0.03)).
SMPL_LIKE_REST_JOINTS: tuple[tuple[float, float, float], ...] = (
    (-0.002, -0.223, 0.028),  # pelvis
    (0.069, -0.314, 0.024), (-0.068, -0.314, 0.020),  # left/right hip
    (-0.004, -0.114, 0.002),  # spine1
    (0.103, -0.690, 0.015), (-0.106, -0.690, 0.010),  # knees
    (0.004, 0.024, 0.028),  # spine2
    (0.089, -1.090, -0.020), (-0.090, -1.090, -0.025),  # ankles
    (0.000, 0.080, 0.030),  # spine3
    (0.118, -1.150, 0.100), (-0.117, -1.150, 0.100),  # feet (toe joints)
    (-0.001, 0.290, 0.012),  # neck
    (0.080, 0.195, 0.020), (-0.082, 0.195, 0.018),  # collars
    (0.004, 0.360, 0.062),  # head
    (0.175, 0.230, 0.008), (-0.175, 0.230, 0.006),  # shoulders
    (0.430, 0.215, -0.020), (-0.430, 0.215, -0.020),  # elbows
    (0.680, 0.225, -0.025), (-0.680, 0.225, -0.025),  # wrists
    (0.765, 0.215, -0.035), (-0.765, 0.215, -0.035),  # hands
)


def template_rest_joints(dtype: torch.dtype = torch.float64) -> torch.Tensor:
    """The typed-in SMPL-like rest joints ``(24, 3)``, metres."""
    return torch.tensor(SMPL_LIKE_REST_JOINTS, dtype=dtype)


@functools.lru_cache(maxsize=1)
def _body_model() -> Any:
    """The default body model, loaded once per process (loading the asset is not free)."""
    return BodyModel(dtype=torch.float64)


def default_rest_joints(betas: torch.Tensor | None = None, dtype: torch.dtype = torch.float64
                        ) -> tuple[torch.Tensor, str]:
    """Rest joints ``(24, 3)`` (metres) of the default body model for ``betas`` (default zeros).

    No silent fallback: if the body asset cannot load, its error propagates, because motion
    converted on another skeleton would be subtly wrong everywhere downstream.

    Returns:
        ``(rest_joints, asset_id)``.
    """
    model = _body_model()
    b = torch.zeros(model.num_betas, dtype=torch.float64) if betas is None else betas.to(torch.float64)
    joints = model.rest_joints(b)
    joints = joints.reshape(-1, 24, 3)[0] if joints.dim() > 2 else joints
    return joints.to(dtype), str(model.asset_id)
