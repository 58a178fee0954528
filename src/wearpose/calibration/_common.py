"""Small helpers shared by the calibration procedures (rotation averages, windows; yaw lives in geometry)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import torch

from wearpose.errors import WearposeError
from wearpose.geometry import GRAVITY, project_to_so3


class CalibrationError(WearposeError, ValueError):
    """A calibration cannot be computed from the data given (missing sensors, no valid frames...)."""


class DegenerateCalibrationError(CalibrationError):
    """The data does not constrain the unknowns (e.g. AX=YB poses that all rotate about one axis)."""


F64 = torch.float64
E_Y = torch.tensor([0.0, 1.0, 0.0], dtype=F64)
#: Gravity of the wearpose world, m/s^2, ``(3,)`` float64.
G_VEC = torch.tensor(GRAVITY, dtype=F64)


def t64(x: Any) -> torch.Tensor:
    """Any array-like -> float64 tensor (copies numpy, keeps torch graphs out)."""
    if isinstance(x, torch.Tensor):
        return x.detach().to(F64)
    return torch.as_tensor(np.asarray(x, dtype=np.float64))


def chordal_mean(R: torch.Tensor, weights: torch.Tensor | None = None) -> torch.Tensor:
    """Chordal L2 mean of rotations: SVD projection of the (weighted) sum (EM-POSE supp. Eq. 2-3).

    Args:
        R: ``(N, ..., 3, 3)`` rotations; the mean is over the first axis.
        weights: optional ``(N, ...)`` non-negative weights (0 = ignore, e.g. invalid frames).

    Returns:
        ``(..., 3, 3)``: ``U diag(1, 1, sign det(U V^T)) V^T`` with ``U S V^T = SVD(sum_t w_t R_t)``.
    """
    if weights is not None:
        R = R * weights[..., None, None].to(R)
    return project_to_so3(R.sum(0))


def rotation_y(angle: torch.Tensor | float) -> torch.Tensor:
    """Rotation about the world up axis (+Y) by ``angle`` ``(...)`` radians -> ``(..., 3, 3)`` float64."""
    a = torch.as_tensor(angle, dtype=F64)
    c, s = torch.cos(a), torch.sin(a)
    o, z = torch.ones_like(a), torch.zeros_like(a)
    return torch.stack([c, z, s, z, o, z, -s, z, c], -1).reshape(*a.shape, 3, 3)


def window_mask(timestamps: np.ndarray | torch.Tensor, window: tuple[float, float], name: str) -> np.ndarray:
    """Bool mask of ``timestamps`` (s) inside ``[window[0], window[1])``; error if empty."""
    ts = np.asarray(timestamps, dtype=np.float64)
    t0, t1 = float(window[0]), float(window[1])
    if not (t1 > t0):
        raise CalibrationError(f"{name}: calibration window {window!r} is empty; expected (start_s, stop_s) with stop > start")
    m = (ts >= t0 - 1e-9) & (ts < t1 - 1e-9)
    if not m.any():
        raise CalibrationError(f"{name}: no frames in the calibration window [{t0:g}, {t1:g}) s "
                               f"(the stream covers [{ts[0]:g}, {ts[-1]:g}] s)")
    return m


def deg(x: torch.Tensor | float) -> float:
    return float(torch.as_tensor(x)) * 180.0 / math.pi
