"""smooth_geodesic_angle and twist_angle (the MI-Poser loss's rotation measures) against scipy."""

import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation as S

from wearpose import geometry as g

ROTS = S.random(64, random_state=3)


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_smooth_geodesic_angle_matches_scipy_and_has_finite_gradients(dtype: torch.dtype) -> None:
    A, B = ROTS[:32], ROTS[32:]
    want = (A.inv() * B).magnitude()
    R1 = torch.as_tensor(A.as_matrix(), dtype=dtype)
    R2 = torch.as_tensor(B.as_matrix(), dtype=dtype)
    got = g.smooth_geodesic_angle(R1, R2)
    np.testing.assert_allclose(got.numpy(), want, atol=1e-5 if dtype == torch.float32 else 1e-9)
    # 0 and pi: finite gradients (geodesic_angle's asin has an infinite slope at pi).
    for ang in (0.0, torch.pi):
        x = g.rotation_y(torch.tensor(ang, dtype=dtype)).requires_grad_()
        a = g.smooth_geodesic_angle(x, torch.eye(3, dtype=dtype))
        a.backward()
        assert abs(float(a.detach()) - ang) < 1e-5 and torch.isfinite(x.grad).all()


@pytest.mark.budget(30)  # matrix_to_quat imports roma (torch._dynamo): ~10 s at load 7
def test_twist_angle_is_the_turn_about_the_axis() -> None:
    """A twist about Y of t composed with a swing about X or Z: the twist's magnitude is recovered."""
    t = torch.tensor([0.0, 0.3, -1.2, 2.9, -3.1], dtype=torch.float64)
    swing = g.rotation_x(torch.tensor(0.4, dtype=torch.float64)) @ g.rotation_z(torch.tensor(-0.2, dtype=torch.float64))
    sx = g.rotation_x(torch.tensor(0.4, dtype=torch.float64))
    got = g.twist_angle(sx @ g.rotation_y(t), torch.tensor([0.0, 1.0, 0.0]))
    np.testing.assert_allclose(got.numpy(), t.abs().numpy(), atol=1e-9)
    # A general swing: the measure is scipy's quaternion's twist about Y, 2 atan2(|q_y|, q_w).
    q = S.from_matrix((swing @ g.rotation_y(t)).numpy()).as_quat()  # x, y, z, w
    q = q * np.sign(q[:, 3:])
    want = 2 * np.arctan2(np.abs(q[:, 1]), q[:, 3])
    np.testing.assert_allclose(g.twist_angle(swing @ g.rotation_y(t), torch.tensor([0.0, 1.0, 0.0])).numpy(), want, atol=1e-9)
