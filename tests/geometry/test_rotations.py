"""Rotation conversions against scipy's reference implementation."""

import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation as S

from wearpose import geometry as g
from wearpose.errors import ShapeError

RNG = np.random.default_rng(0)
ROTS = S.random(64, random_state=1)


def _t(x: np.ndarray) -> torch.Tensor:
    return torch.as_tensor(x, dtype=torch.float64)


def test_axis_angle_matches_scipy() -> None:
    aa = ROTS.as_rotvec()
    np.testing.assert_allclose(g.axis_angle_to_matrix(_t(aa)).numpy(), ROTS.as_matrix(), atol=1e-12)
    np.testing.assert_allclose(g.matrix_to_axis_angle(_t(ROTS.as_matrix())).numpy(), aa, atol=1e-9)


def test_quaternion_wxyz_matches_scipy() -> None:
    xyzw = ROTS.as_quat()
    wxyz = np.concatenate([xyzw[:, 3:], xyzw[:, :3]], axis=1)
    np.testing.assert_allclose(g.quat_to_matrix(_t(wxyz)).numpy(), ROTS.as_matrix(), atol=1e-12)
    q = g.matrix_to_quat(_t(ROTS.as_matrix())).numpy()
    assert np.all(q[:, 0] >= 0)
    wxyz = wxyz * np.sign(wxyz[:, :1])
    np.testing.assert_allclose(q, wxyz, atol=1e-9)


@pytest.mark.parametrize("order", ["ZXY", "ZYX", "XYZ", "YXZ"])
def test_euler_intrinsic_matches_scipy(order: str) -> None:
    ang = RNG.uniform(-np.pi, np.pi, size=(32, 3))
    ref = S.from_euler(order, ang).as_matrix()  # upper case = intrinsic
    np.testing.assert_allclose(g.euler_to_matrix(_t(ang), order).numpy(), ref, atol=1e-12)
    back = g.euler_to_matrix(g.matrix_to_euler(_t(ref), order), order).numpy()
    np.testing.assert_allclose(back, ref, atol=1e-9)


def test_rot6d_roundtrip_and_gram_schmidt() -> None:
    R = _t(ROTS.as_matrix())
    np.testing.assert_allclose(g.rot6d_to_matrix(g.matrix_to_rot6d(R)).numpy(), R.numpy(), atol=1e-12)
    d6 = torch.randn(10, 6, dtype=torch.float64)
    M = g.rot6d_to_matrix(d6)
    np.testing.assert_allclose((M.transpose(-1, -2) @ M).numpy(), np.broadcast_to(np.eye(3), (10, 3, 3)), atol=1e-12)
    np.testing.assert_allclose(torch.det(M).numpy(), 1.0, atol=1e-12)


def test_geodesic_and_slerp() -> None:
    R0 = _t(ROTS.as_matrix()[:8])
    R1 = _t((ROTS[:8] * S.from_rotvec(np.tile([0, 0, 0.8], (8, 1)))).as_matrix())
    np.testing.assert_allclose(g.geodesic_angle(R0, R1).numpy(), 0.8, atol=1e-9)
    mid = g.slerp_matrix(R0, R1, torch.full((8,), 0.25, dtype=torch.float64))
    np.testing.assert_allclose(g.geodesic_angle(R0, mid).numpy(), 0.2, atol=1e-9)


def test_rotation_between_including_antiparallel() -> None:
    a = _t(RNG.normal(size=(20, 3)))
    b = _t(RNG.normal(size=(20, 3)))
    b[0] = -a[0]
    b[1] = a[1] * 2
    R = g.rotation_between(a, b)
    out = (R @ (a / a.norm(dim=-1, keepdim=True)).unsqueeze(-1)).squeeze(-1)
    np.testing.assert_allclose(out.numpy(), (b / b.norm(dim=-1, keepdim=True)).numpy(), atol=1e-9)


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_skew_is_the_cross_product_matrix(dtype: torch.dtype) -> None:
    gen = torch.Generator().manual_seed(0)
    v, w = torch.randn(2, 5, 3, generator=gen, dtype=dtype)
    K = g.skew(v)
    assert K.shape == (5, 3, 3) and K.dtype == dtype
    assert torch.allclose((K @ w.unsqueeze(-1)).squeeze(-1), torch.linalg.cross(v, w, dim=-1), atol=1e-6)
    assert torch.equal(K.transpose(-1, -2), -K)
    with pytest.raises(ShapeError, match=r"skew: expected shape \(\.\.\., 3\)"):
        g.skew(torch.zeros(4, 2))


def test_bad_shapes_raise() -> None:
    with pytest.raises(ShapeError, match=r"\(\.\.\., 3\)"):
        g.axis_angle_to_matrix(torch.zeros(4, 4))
    with pytest.raises(ShapeError, match="order"):
        g.euler_to_matrix(torch.zeros(3), "ZQY")


def test_z_up_to_y_up() -> None:
    up_z = torch.tensor([0.0, 0.0, 1.0], dtype=torch.float64)
    np.testing.assert_allclose(g.change_world_points(g.Z_UP_TO_Y_UP, up_z).numpy(), [0, 1, 0])
    np.testing.assert_allclose((g.Z_UP_TO_Y_UP @ g.Y_UP_TO_Z_UP).numpy(), np.eye(3))


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_own_conversions_equal_roma(dtype: torch.dtype) -> None:
    """axis-angle, 6D and quaternion -> matrix are ours (roma is imported lazily): the same
    values as roma's, bit for bit, incl. the small-angle branch and the gradient at 0."""
    import roma

    gen = torch.Generator().manual_seed(0)
    aa = torch.randn(300, 3, generator=gen, dtype=dtype) * 2
    aa[:20] *= 1e-7
    aa[20] = 0
    assert torch.equal(g.axis_angle_to_matrix(aa.view(10, 30, 3)), roma.rotvec_to_rotmat(aa).view(10, 30, 3, 3))
    d6 = torch.randn(7, 5, 6, generator=gen, dtype=dtype)
    assert torch.equal(g.rot6d_to_matrix(d6), roma.special_gramschmidt(torch.stack([d6[..., :3], d6[..., 3:]], -1)))
    q = torch.randn(300, 4, generator=gen, dtype=dtype)
    qn = q / q.norm(dim=-1, keepdim=True)
    assert torch.equal(g.quat_to_matrix(q), roma.unitquat_to_rotmat(roma.quat_wxyz_to_xyzw(qn)))
    zero = torch.zeros(2, 3, dtype=dtype, requires_grad=True)
    g.axis_angle_to_matrix(zero).sum().backward()
    assert torch.isfinite(zero.grad).all()


@pytest.mark.budget(60)  # a fresh interpreter importing torch: 3-9 s on a loaded 2-core machine
def test_body_import_does_not_pull_in_dynamo() -> None:
    """``import wearpose.body`` stays clear of roma (whose import pulls in torch._dynamo)."""
    import subprocess
    import sys

    code = "import sys, wearpose.body; print(sorted(m for m in ('roma', 'torch._dynamo', 'sympy') if m in sys.modules))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=True)
    assert out.stdout.strip() == "[]", out.stdout + out.stderr
