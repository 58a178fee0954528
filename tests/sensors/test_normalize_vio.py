"""Root-relative normalisation (BiRAE Eq. 1, EM-POSE supp. 2.1) and the VIO simulator."""

import math

import torch

from wearpose.geometry import geodesic_angle
from wearpose.sensors import VioNoise, empose_normalize, root_relative_orientations, simulate_vio

from sensor_testutils import rand_R

D = torch.float64


def test_birae_root_relative():
    R = rand_R(10, 6)
    rel = root_relative_orientations(R)  # root = last (mimu6 "root" sensor)
    assert rel.shape == (10, 5, 3, 3)
    assert torch.allclose(rel, R[:, 5:6].transpose(-1, -2) @ R[:, :5])
    G = rand_R(seed=3)
    assert torch.allclose(root_relative_orientations(G @ R), rel)  # invariant to a global rotation
    assert torch.allclose(root_relative_orientations(R, root=0, keep_root=True)[:, 0], torch.eye(3, dtype=D).expand(10, 3, 3))


def test_empose_normalize():
    T, S = 8, 4
    p, R = torch.randn(T, S, 3, dtype=D), rand_R(T, S)
    Rr, tr = rand_R(T, seed=1), torch.randn(T, 3, dtype=D)
    n = empose_normalize(p, R, Rr, tr)
    assert torch.allclose(n["root_orientation"][0], torch.eye(3, dtype=D))
    assert torch.allclose(n["position"], torch.einsum("ji,tsj->tsi", Rr[0], p - tr[:, None]))
    assert torch.allclose(n["orientation"], Rr[0].T @ R)
    # a global yaw+translation of the whole sequence leaves the normalised data unchanged
    G = rand_R(seed=5)
    n2 = empose_normalize(p @ G.T + 2, G @ R, G @ Rr, tr @ G.T + 2)
    assert torch.allclose(n2["position"], n["position"]) and torch.allclose(n2["orientation"], n["orientation"])


def test_vio():
    T = 600
    R = rand_R(T, 1)
    p = torch.randn(T, 1, 3, dtype=D)
    ideal = simulate_vio(R, p, 60.0, noise=None)
    assert torch.allclose(ideal["position"], p, atol=1e-12) and torch.allclose(ideal["orientation"], R)
    g = lambda: torch.Generator().manual_seed(2)  # noqa: E731
    a, b = simulate_vio(R, p, 60.0, noise=VioNoise(), generator=g()), simulate_vio(R, p, 60.0, noise=VioNoise(), generator=g())
    assert torch.equal(a["position"], b["position"])
    # drift starts at zero; heading drift is a rotation about the vertical only
    assert a["yaw_drift"][0].abs().max() == 0 and a["position_drift"][0].abs().max() == 0
    nd = simulate_vio(R, p, 60.0, noise=VioNoise(0, 0, 0, math.radians(1.0)), generator=g())
    up = torch.tensor([0.0, 1.0, 0.0], dtype=D)
    assert torch.allclose(nd["orientation"].transpose(-1, -2) @ up, R.transpose(-1, -2) @ up)
    assert geodesic_angle(nd["orientation"], R).max() > 0
    # random-walk drift std ~ density * sqrt(t) over many runs
    walks = torch.stack([simulate_vio(R[:, :], p, 60.0, noise=VioNoise(0, 0, 0.01, 0), generator=torch.Generator().manual_seed(s))["position_drift"][-1, 0]
                         for s in range(200)])
    assert 0.7 < walks.std().item() / (0.01 * math.sqrt((T - 1) / 60)) < 1.3
