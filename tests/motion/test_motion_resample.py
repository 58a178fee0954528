"""Resampling against analytic constant-angular-velocity motion."""

from __future__ import annotations

import math

import pytest
import torch

from wearpose.errors import ShapeError
from wearpose.geometry import axis_angle_to_matrix, geodesic_angle
from wearpose.motion import MotionSequence, resample


def analytic(fps: float, T: int) -> tuple[MotionSequence, torch.Tensor, torch.Tensor, torch.Tensor]:
    """Every joint spins at its own constant angular velocity (< pi per source frame) about a fixed
    axis, starting from its own rotation; the root translates with constant velocity."""
    g = torch.Generator().manual_seed(3)
    axes = torch.nn.functional.normalize(torch.randn(24, 3, generator=g, dtype=torch.float64), dim=-1)
    omega = torch.rand(24, generator=g, dtype=torch.float64) * 6.0 + 0.5  # rad/s
    start = axis_angle_to_matrix(torch.randn(24, 3, generator=g, dtype=torch.float64))
    vel = torch.tensor([0.3, -0.1, 1.2], dtype=torch.float64)
    t = torch.arange(T, dtype=torch.float64) / fps
    seq = MotionSequence(truth_pose(t, axes, omega, start), torch.zeros(10), vel * t[:, None], fps, {"clip": "spin"})
    return seq, axes, omega, start


def truth_pose(t: torch.Tensor, axes: torch.Tensor, omega: torch.Tensor, start: torch.Tensor) -> torch.Tensor:
    return axis_angle_to_matrix(axes * (omega[None, :, None] * t[:, None, None])) @ start


@pytest.mark.parametrize("target", [25.0, 30.0, 100.0, 59.94, 120.0])
def test_constant_angular_velocity_is_reproduced(target: float) -> None:
    seq, axes, omega, start = analytic(60.0, 91)  # last sample at 1.5 s
    out = resample(seq, target)
    n = int(math.floor(1.5 * target + 1e-6)) + 1
    assert out.num_frames == n and out.fps == target
    t = torch.arange(n, dtype=torch.float64) / target
    err = geodesic_angle(out.pose, truth_pose(t, axes, omega, start))
    assert float(err.max()) < 1e-6
    vel = torch.tensor([0.3, -0.1, 1.2], dtype=torch.float64)
    assert torch.allclose(out.trans, vel * t[:, None], atol=1e-9)
    assert out.meta["resampled_from_fps"] == 60.0 and out.meta["clip"] == "spin"


def test_same_rate_and_single_frame() -> None:
    seq, *_ = analytic(30.0, 10)
    assert torch.equal(resample(seq, 30.0).pose, seq.pose)
    one = resample(seq.slice(0, 1), 90.0)
    assert one.num_frames == 1 and one.fps == 90.0
    with pytest.raises(ShapeError):
        resample(seq, 0.0)


def test_float32_input_keeps_dtype() -> None:
    seq, *_ = analytic(60.0, 30)
    out = resample(seq.to(torch.float32), 24.0)
    assert out.pose.dtype == torch.float32 and out.num_frames == int(29 / 60 * 24) + 1
