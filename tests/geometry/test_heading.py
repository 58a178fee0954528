"""heading / vector_heading / best_yaw: the yaw conventions (0 facing +Z, positive towards +X)."""

import math

import torch

from wearpose import geometry as g

GEN = torch.Generator().manual_seed(0)


def _wrap(a: torch.Tensor) -> torch.Tensor:
    return torch.remainder(a + math.pi, 2 * math.pi) - math.pi


def _random_rot(n: int) -> torch.Tensor:
    return g.axis_angle_to_matrix(torch.randn(n, 3, generator=GEN, dtype=torch.float64) * 2)


def test_heading_of_a_turn_about_y_is_its_angle_and_ignores_spin_and_tilt_of_up() -> None:
    a = (torch.rand(200, generator=GEN, dtype=torch.float64) * 2 - 1) * (math.pi - 1e-6)
    spin = torch.rand(200, generator=GEN, dtype=torch.float64) * 6
    pitch = (torch.rand(200, generator=GEN, dtype=torch.float64) - 0.5) * 3  # |pitch| < 1.5 rad: forward not vertical
    R = g.rotation_y(a) @ g.rotation_x(pitch) @ g.rotation_z(spin)  # spin about the forward axis, then pitch
    torch.testing.assert_close(g.heading(R), a, atol=1e-12, rtol=0)
    torch.testing.assert_close(g.heading(g.rotation_y(a)), a, atol=1e-12, rtol=0)
    # +X is +pi/2 (rotation_y(pi/2) takes +Z to +X)
    assert abs(float(g.vector_heading(torch.tensor([1.0, 0.3, 0.0]))) - math.pi / 2) < 1e-6


def test_heading_is_vector_heading_of_the_forward_column_even_near_vertical() -> None:
    eps = torch.logspace(-12, -1, 50, dtype=torch.float64)
    R = torch.cat([_random_rot(200), g.rotation_y(eps * 50) @ g.rotation_x(math.pi / 2 - eps)])
    assert torch.equal(g.heading(R), g.vector_heading(R[..., :, 2]))
    v = torch.randn(100, 3, generator=GEN, dtype=torch.float64)
    torch.testing.assert_close(g.vector_heading(v), torch.atan2(v[:, 0], v[:, 2]), atol=0, rtol=0)
    assert float(g.vector_heading(torch.tensor([0.0, 1.0, 0.0]))) == 0.0  # vertical: defined, 0


def test_best_yaw_is_the_closest_rotation_about_y() -> None:
    M = torch.randn(20, 3, 3, generator=GEN, dtype=torch.float64)
    psi = g.best_yaw(M)
    grid = torch.linspace(-math.pi, math.pi, 20001, dtype=torch.float64)
    Ry = g.rotation_y(grid)  # (G, 3, 3)
    score = torch.einsum("gij,nij->ng", Ry, M)  # trace(Ry^T M)
    torch.testing.assert_close(_wrap(psi - grid[score.argmax(1)]), torch.zeros(20, dtype=torch.float64), atol=5e-4, rtol=0)
    # equivariant under turns about Y; exact on pure turns
    a = torch.rand(20, generator=GEN, dtype=torch.float64) * 6 - 3
    torch.testing.assert_close(_wrap(g.best_yaw(g.rotation_y(a) @ M) - psi - a), torch.zeros(20, dtype=torch.float64),
                               atol=1e-12, rtol=0)
    torch.testing.assert_close(g.best_yaw(g.rotation_y(a)), a, atol=1e-12, rtol=0)


def test_best_yaw_and_heading_differ_on_tilted_rotations() -> None:
    # Why both exist: where the forward axis points vs the yaw of the whole rotation.
    R = g.rotation_z(torch.tensor(0.8, dtype=torch.float64)) @ g.rotation_x(torch.tensor(0.7, dtype=torch.float64))
    assert abs(float(g.heading(R) - g.best_yaw(R))) > 0.1
