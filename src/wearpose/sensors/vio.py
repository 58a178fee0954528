"""Headset VIO simulator: 6-DoF head pose in the world with optional random-walk drift.

Visual-inertial odometry is gravity-aligned (the accelerometer observes pitch and roll), so its
unobservable, drifting directions are the 3-D position and the heading (rotation about the
vertical). The model (our assumption; MI-Poser uses the Spectacles VIO at 60 Hz and reports it
"precise" without figures)::

    R_meas(t) = R_y(psi(t)) R(t) exp([n_r(t)]x)
    p_meas(t) = p(0) + R_y(psi(t)) (p(t) - p(0)) + b(t) + n_p(t)

with ``psi`` and ``b`` random walks starting at 0 (the VIO map is anchored at the first frame)
and white noise ``n_r``, ``n_p``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch

from wearpose.errors import ShapeError
from wearpose.geometry import axis_angle_to_matrix, rotation_y


@dataclass(frozen=True)
class VioNoise:
    """VIO error model (assumed magnitudes).

    Attributes:
        position_white: per-axis white position noise, m (1 mm).
        orientation_white: per-axis white orientation noise, rad (0.2 deg).
        position_walk: position drift random walk per axis, m/sqrt(s) (std 1 cm after 1 s, 7.7 cm after 60 s).
        yaw_walk: heading drift random walk, rad/sqrt(s) (0.1 deg/sqrt(s)).
    """

    position_white: float = 0.001
    orientation_white: float = math.radians(0.2)
    position_walk: float = 0.01
    yaw_walk: float = math.radians(0.1)

    @staticmethod
    def none() -> VioNoise:
        return VioNoise(0.0, 0.0, 0.0, 0.0)

    @staticmethod
    def no_drift() -> VioNoise:
        return VioNoise(position_walk=0.0, yaw_walk=0.0)


def _walk(T: int, shape: tuple[int, ...], fps: float, density: float, g: torch.Generator | None) -> torch.Tensor:
    out = torch.zeros((T, *shape), dtype=torch.float64)
    if density > 0 and T > 1:
        out[1:] = torch.cumsum(density * math.sqrt(1.0 / fps) * torch.randn((T - 1, *shape), generator=g, dtype=torch.float64), 0)
    return out


def simulate_vio(R: torch.Tensor, p: torch.Tensor, fps: float, *, noise: VioNoise | None = None,
                 generator: torch.Generator | None = None) -> dict[str, torch.Tensor]:
    """Simulate headset VIO.

    Args:
        R: ``(T, S, 3, 3)`` true orientation ``R_WS`` (usually ``S = 1``, the head site).
        p: ``(T, S, 3)`` true position, m, world.
        fps: Hz. noise: :class:`VioNoise` (``None`` = ideal). generator: random source.

    Returns:
        dict: ``orientation`` ``(T, S, 3, 3)``, ``position`` ``(T, S, 3)`` (world, m),
        ``valid`` ``(T,)``, ``yaw_drift`` ``(T, S)`` rad and ``position_drift`` ``(T, S, 3)`` m.
    """
    if R.dim() != 4 or p.shape != R.shape[:-1]:
        raise ShapeError(f"simulate_vio: expected R (T, S, 3, 3) and p (T, S, 3), got {tuple(R.shape)}, {tuple(p.shape)}")
    dtype = R.dtype
    T, S = R.shape[:2]
    R64, p64 = R.to(torch.float64), p.to(torch.float64)
    if noise is None:
        noise = VioNoise.none()
    psi = _walk(T, (S,), fps, noise.yaw_walk, generator)
    b = _walk(T, (S, 3), fps, noise.position_walk, generator)
    Ry = rotation_y(psi)
    Rm = Ry @ R64
    if noise.orientation_white > 0:
        Rm = Rm @ axis_angle_to_matrix(noise.orientation_white * torch.randn(T, S, 3, generator=generator, dtype=torch.float64))
    pm = p64[:1] + (Ry @ (p64 - p64[:1]).unsqueeze(-1)).squeeze(-1) + b
    if noise.position_white > 0:
        pm = pm + noise.position_white * torch.randn(T, S, 3, generator=generator, dtype=torch.float64)
    return {"orientation": Rm.to(dtype), "position": pm.to(dtype), "valid": torch.ones(T, dtype=torch.bool),
            "yaw_drift": psi.to(dtype), "position_drift": b.to(dtype)}
