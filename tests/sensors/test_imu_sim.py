"""IMU simulator acceptance: analytic acceleration, analytic gyro, gyro integration, noise."""

import math

import pytest
import torch

from sensor_testutils import smooth_motion
from wearpose.geometry import axis_angle_to_matrix, geodesic_angle, rotation_x, rotation_z
from wearpose.sensors import (
    ImuNoise, angular_velocity, free_acceleration, integrate_gyro, simulate_imu, specific_force, synthetic_acceleration,
)

FPS = 60.0
D = torch.float64


def circle(T=600, fps=FPS, r=0.5, f=1.0):
    t = torch.arange(T, dtype=D) / fps
    w = 2 * math.pi * f
    p = torch.stack([r * torch.cos(w * t), 1.2 + 0 * t, r * torch.sin(w * t)], -1)
    a = torch.stack([-r * w * w * torch.cos(w * t), 0 * t, -r * w * w * torch.sin(w * t)], -1)
    return p, a, w


def rel_err(a, b):
    return ((a - b).norm(dim=-1) / b.norm(dim=-1)).max().item()


def test_acceleration_circle_unsmoothed_within_1pct():
    p, a, w = circle()
    est, valid = synthetic_acceleration(p, FPS, smooth_n=1, ends="one_sided")
    assert valid.all()
    err = rel_err(est[1:-1], a[1:-1])
    # central difference scales a sinusoid by 2(1-cos(w dt))/(w dt)^2 = 1 - 0.09 % at 1 Hz, 60 Hz
    assert err < 0.01
    assert err == pytest.approx(1 - 2 * (1 - math.cos(w / FPS)) / (w / FPS) ** 2, rel=1e-3)
    # one-sided second-order ends: within a few percent at the two extreme frames
    assert rel_err(est[[0, -1]], a[[0, -1]]) < 0.03


@pytest.mark.parametrize("f", [0.5, 1.0, 2.0])
def test_acceleration_circle_smoothed_matches_predicted_attenuation(f):
    n = 4
    p, a, w = circle(f=f)
    est, _ = synthetic_acceleration(p, FPS, smooth_n=n)
    x = w * n / FPS
    gain = 2 * (1 - math.cos(x)) / x ** 2  # the widened stencil is a low-pass (TransPose smooth_n=4)
    inner = slice(n, -n)
    assert rel_err(est[inner], gain * a[inner]) < 1e-6
    # quantified: 0.4 % at 0.5 Hz, 1.5 % at 1 Hz, 5.7 % at 2 Hz
    assert 1 - gain == pytest.approx({0.5: 0.0037, 1.0: 0.0146, 2.0: 0.0572}[f], abs=2e-4)


def test_acceleration_sinusoid_1d_and_ends_modes():
    t = torch.arange(300, dtype=D) / FPS
    p = torch.stack([0.1 * torch.sin(2 * math.pi * 0.8 * t), 0 * t, 0 * t], -1)
    a = torch.stack([-0.1 * (2 * math.pi * 0.8) ** 2 * torch.sin(2 * math.pi * 0.8 * t), 0 * t, 0 * t], -1)
    est, _ = synthetic_acceleration(p, FPS, smooth_n=1)
    big = a[:, 0].abs() > 0.3 * a[:, 0].abs().max()  # relative error only where the signal is not ~0
    assert ((est - a)[big, 0].abs() / a[big, 0].abs())[1:-1].max() < 0.01
    zero, v0 = synthetic_acceleration(p, FPS, smooth_n=4, ends="zero")
    assert v0.all() and zero[0].abs().sum() == 0 and zero[-1].abs().sum() == 0
    m, vm = synthetic_acceleration(p, FPS, smooth_n=4, ends="mask")
    assert not vm[0] and not vm[-1] and vm[1:-1].all()
    # TransPose: frames 1..n-1 are the unsmoothed central difference
    assert torch.allclose(zero[1], (p[0] + p[2] - 2 * p[1]) * FPS ** 2)


def test_gyro_constant_body_rate():
    w = torch.tensor([0.3, -1.2, 2.0], dtype=D)
    R0 = axis_angle_to_matrix(torch.tensor([0.2, 0.5, -0.1], dtype=D))
    t = torch.arange(600, dtype=D) / FPS
    R = R0 @ axis_angle_to_matrix(t[:, None] * w)
    for conv in ("central", "forward"):
        est = angular_velocity(R, FPS, conv)
        assert (est - w).abs().max() < 1e-9


def test_gyro_time_varying_analytic():
    # R(t) = Rz(a(t)) Rx(b(t)): body rate = Rx(b)^T z a' + x b'
    t = torch.arange(600, dtype=D) / FPS
    a, da = 1.5 * torch.sin(2 * math.pi * 0.7 * t), 1.5 * 2 * math.pi * 0.7 * torch.cos(2 * math.pi * 0.7 * t)
    b, db = 0.8 * torch.sin(2 * math.pi * 1.1 * t + 0.3), 0.8 * 2 * math.pi * 1.1 * torch.cos(2 * math.pi * 1.1 * t + 0.3)
    Rb = rotation_x(b)
    R = rotation_z(a) @ Rb
    z = torch.tensor([0.0, 0.0, 1.0], dtype=D)
    w = (Rb.transpose(-1, -2) @ z) * da[:, None] + torch.stack([db, 0 * db, 0 * db], -1)
    est = angular_velocity(R, FPS, "central")
    err = (est - w).norm(dim=-1)[1:-1]
    peak = w.norm(dim=-1).max()
    assert (err / peak).max() < 0.01  # second order: ~1e-3 of the peak rate at 60 Hz
    assert (angular_velocity(R, FPS, "forward") - w).norm(dim=-1)[1:-1].max() / peak < 0.1  # first order


def test_integrated_gyro_reproduces_orientation_10s():
    # a body site over 10 s of varied motion (smooth random joint angles)
    T = 600
    t = torch.arange(T, dtype=D) / FPS
    g = torch.Generator().manual_seed(3)
    amp, fr, ph = 1.2 * torch.rand(4, 3, generator=g, dtype=D), 0.2 + 1.5 * torch.rand(4, 3, generator=g, dtype=D), 6 * torch.rand(4, 3, generator=g, dtype=D)
    R = torch.eye(3, dtype=D)
    for k in range(4):  # a 4-link chain composed of time-varying rotations
        R = R @ axis_angle_to_matrix(amp[k] * torch.sin(2 * math.pi * fr[k] * t[:, None] + ph[k]))
    for conv in ("central", "forward"):
        w = angular_velocity(R, FPS, conv)
        Ri = integrate_gyro(w, R[0], FPS, conv)
        err = geodesic_angle(Ri, R).max().item()
        assert math.degrees(err) < 1.0, (conv, math.degrees(err))


def test_specific_force_and_free_acceleration():
    R = axis_angle_to_matrix(torch.tensor([[0.3, 1.0, -0.4]], dtype=D))
    f = specific_force(R, torch.zeros(1, 3, dtype=D))
    assert torch.allclose(R[0] @ f[0], torch.tensor([0, 9.81, 0], dtype=D))  # at rest: +g up
    a = torch.tensor([[1.0, 2.0, 3.0]], dtype=D)
    assert torch.allclose(free_acceleration(R, specific_force(R, a)), a)


def test_simulate_imu_noise_free_and_seeded_noise():
    p, a, w = circle(T=600)
    R = axis_angle_to_matrix(torch.arange(600, dtype=D)[:, None] / FPS * torch.tensor([0.0, w, 0.0], dtype=D))
    ideal = simulate_imu(R[:, None], p[:, None], FPS, noise=None, smooth_n=1)
    assert torch.allclose(ideal["orientation"], R[:, None])
    assert rel_err(ideal["acceleration"][1:-1, 0], a[1:-1]) < 0.01
    n1 = simulate_imu(R[:, None], p[:, None], FPS, noise=ImuNoise(), generator=torch.Generator().manual_seed(5))
    n2 = simulate_imu(R[:, None], p[:, None], FPS, noise=ImuNoise(), generator=torch.Generator().manual_seed(5))
    assert torch.equal(n1["angular_velocity"], n2["angular_velocity"])
    # white-noise-only gyro: per-sample std = density * sqrt(fps)
    T = 20000
    Rs = torch.eye(3, dtype=D).expand(T, 1, 3, 3)
    ps = torch.zeros(T, 1, 3, dtype=D)
    only_white = ImuNoise(gyro_white=0.01, gyro_bias=0, gyro_bias_walk=0, acc_white=0.02, acc_bias=0, acc_bias_walk=0,
                          orientation_white=0)
    r = simulate_imu(Rs, ps, FPS, noise=only_white, generator=torch.Generator().manual_seed(1))
    assert r["angular_velocity"].std().item() == pytest.approx(0.01 * math.sqrt(FPS), rel=0.03)
    assert (r["specific_force"] - torch.tensor([0, 9.81, 0], dtype=D)).std().item() == pytest.approx(0.02 * math.sqrt(FPS), rel=0.03)
    # constant bias: same offset every frame
    bias = ImuNoise.none().__class__(gyro_white=0, gyro_bias=0.01, gyro_bias_walk=0, acc_white=0, acc_bias=0,
                                     acc_bias_walk=0, orientation_white=0)
    rb = simulate_imu(Rs[:100], ps[:100], FPS, noise=bias, generator=torch.Generator().manual_seed(2))
    assert torch.allclose(rb["angular_velocity"], rb["angular_velocity"][:1].expand(100, 1, 3))


def test_motion_site_like_trajectory_gyro_integration():
    # the same acceptance on a trajectory built from the synthetic motion's root
    m = smooth_motion(T=600, fps=FPS)
    R = m.pose[:, 0]
    w = angular_velocity(R, FPS)
    assert math.degrees(geodesic_angle(integrate_gyro(w, R[0], FPS), R).max().item()) < 1.0
