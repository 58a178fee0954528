"""wearpose world -> Unity's left-handed frame (VMC output)."""

from __future__ import annotations

import math

import torch

from wearpose.geometry import (
    axis_angle_to_matrix,
    quat_to_matrix,
    rotation_y,
    to_unity_points,
    to_unity_quat,
    to_unity_rotation,
)


def test_points_flip_the_axis_across_the_body() -> None:
    # the subject's left hand (+X here) is at -X in Unity; up and forward are shared
    p = torch.tensor([[0.7, 1.4, 0.1]], dtype=torch.float64)
    assert torch.equal(to_unity_points(p), torch.tensor([[-0.7, 1.4, 0.1]], dtype=torch.float64))


def test_rotation_acts_on_unity_coordinates() -> None:
    g = torch.Generator().manual_seed(0)
    R = axis_angle_to_matrix(torch.randn(50, 3, generator=g, dtype=torch.float64))
    p = torch.randn(50, 3, generator=g, dtype=torch.float64)
    Ru = to_unity_rotation(R)
    # R_u (M p) == M (R p): the same physical rotation in the mirrored coordinates
    lhs = (Ru @ to_unity_points(p)[..., None])[..., 0]
    rhs = to_unity_points((R @ p[..., None])[..., 0])
    assert torch.allclose(lhs, rhs, atol=1e-12)
    assert torch.allclose(torch.linalg.det(Ru), torch.ones(50, dtype=torch.float64), atol=1e-12)


def test_left_elbow_bent_forward_by_hand() -> None:
    # Forearm along +X (T-pose, left arm) turned to point forward (+Z): R_y(-90 deg) here.
    R = rotation_y(torch.tensor(-math.pi / 2, dtype=torch.float64))
    assert torch.allclose(R @ torch.tensor([1.0, 0, 0], dtype=torch.float64),
                          torch.tensor([0, 0, 1.0], dtype=torch.float64), atol=1e-12)
    # In Unity the left arm points along -X; Quaternion.Euler(0, 90, 0) = (x, y, z, w) =
    # (0, sin 45, 0, cos 45) turns -X to +Z (left-handed: +90 deg about Y takes +Z to +X).
    h = math.sqrt(0.5)
    q = to_unity_quat(R)
    assert torch.allclose(q, torch.tensor([0.0, h, 0.0, h], dtype=torch.float64), atol=1e-12)


def test_quaternion_is_w_x_minus_y_minus_z() -> None:
    g = torch.Generator().manual_seed(1)
    qw = torch.nn.functional.normalize(torch.randn(20, 4, generator=g, dtype=torch.float64), dim=-1)
    qw = torch.where(qw[:, :1] < 0, -qw, qw)
    out = to_unity_quat(quat_to_matrix(qw))  # (x, y, z, w)
    expected = torch.stack([qw[:, 1], -qw[:, 2], -qw[:, 3], qw[:, 0]], dim=-1)
    assert torch.allclose(out, expected, atol=1e-9)
