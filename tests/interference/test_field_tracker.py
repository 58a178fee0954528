"""EM field (EM-POSE Eq. 1-2), metal as induced dipoles, and the least-squares pose solver."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from wearpose.geometry import axis_angle_to_matrix, geodesic_angle, matrix_to_axis_angle
from wearpose.interference import (
    EMTracker, MetalObject, Scene, TrackerConfig, closed_form_pose, coupling, dipole_field, ideal_voltages,
    measured_voltages, soft_coupling,
)
from wearpose.interference._so3 import angle_between, exp_so3


def _rot(rng, n=None):
    aa = rng.normal(size=(3,) if n is None else (n, 3))
    return axis_angle_to_matrix(torch.from_numpy(aa)).numpy()


def test_dipole_field_matches_eq1_on_axis_and_equator():
    m = np.array([0.0, 0.0, 2.0])  # A m^2
    r = 0.7
    on_axis = dipole_field(np.array([0.0, 0.0, r]), m)
    equator = dipole_field(np.array([r, 0.0, 0.0]), m)
    # textbook values of Eq. 1: 2 m mu0/(4 pi r^3) on the axis, -m mu0/(4 pi r^3) on the equator
    assert on_axis == pytest.approx([0.0, 0.0, 1e-7 * 2 * 2.0 / r ** 3], rel=1e-12, abs=1e-20)
    assert equator == pytest.approx([0.0, 0.0, -1e-7 * 2.0 / r ** 3], rel=1e-12, abs=1e-20)
    rng = np.random.default_rng(0)
    p, M = rng.normal(size=(20, 3)), rng.normal(size=(20, 3))
    # coupling(p) M is Eq. 1 in normalised units (mu0/4pi = 1)
    np.testing.assert_allclose(dipole_field(p, M), 1e-7 * np.einsum("tij,tj->ti", coupling(p), M), rtol=1e-12)


def test_voltages_eq2_and_world_covariance():
    rng = np.random.default_rng(1)
    R_src, R_s = _rot(rng, 5), _rot(rng, 5)
    p_src, p_s = rng.normal(size=(5, 3)), rng.normal(size=(5, 3))
    V_world = measured_voltages(Scene(), R_s, p_s, R_src, p_src)
    R_rel = np.swapaxes(R_src, -1, -2) @ R_s
    p_rel = np.einsum("tji,tj->ti", R_src, p_s - p_src)
    np.testing.assert_allclose(V_world, ideal_voltages(R_rel, p_rel), atol=1e-12)
    # Eq. 2 element by element: V[l, k] = B_k(p) . (R N_l)
    V = ideal_voltages(R_rel[0], p_rel[0])
    for k in range(3):
        B = coupling(p_rel[0]) @ np.eye(3)[k]
        for l in range(3):
            assert V[l, k] == pytest.approx(B @ (R_rel[0] @ np.eye(3)[l]), abs=1e-12)


@pytest.mark.parametrize("solver", ["scipy", "numpy"])
def test_solver_recovers_pose_from_clean_voltages(solver):
    rng = np.random.default_rng(2)
    for _ in range(5):
        R = _rot(rng)
        p = rng.normal(size=3)
        p = p / np.linalg.norm(p) * rng.uniform(0.2, 1.2)
        trk = EMTracker(TrackerConfig(hemisphere=tuple(p), solver=solver))
        Rs, ps, res = trk.solve(ideal_voltages(R, p))
        assert np.abs(ps - p).max() < 1e-6
        assert angle_between(Rs, R) < 1e-6
        assert res < 1e-8


def test_hemisphere_ambiguity_and_tracking():
    rng = np.random.default_rng(3)
    R, p = _rot(rng), np.array([0.3, -0.4, 0.2])
    V = ideal_voltages(R, p)
    np.testing.assert_allclose(V, ideal_voltages(R, -p), atol=1e-12)  # the ambiguity is exact
    Rc, pc = closed_form_pose(V, hemisphere=np.array([0.0, 0.0, -1.0]))
    np.testing.assert_allclose(pc, -p, atol=1e-9)   # the configured hemisphere decides
    np.testing.assert_allclose(Rc, R, atol=1e-9)
    # a path crossing the hemisphere plane (z = 0) is followed by continuity
    T = 60
    path = np.stack([np.full(T, 0.4), np.full(T, -0.3), np.linspace(0.2, -0.2, T)], 1)
    trk = EMTracker(TrackerConfig(hemisphere=(0.0, 0.0, 1.0), solver="numpy"))
    _, ps, _ = trk.track(ideal_voltages(np.broadcast_to(R, (T, 3, 3)), path))
    np.testing.assert_allclose(ps, path, atol=1e-6)


def _pose_error_near_sphere(dist: float) -> tuple[float, float]:
    R, p = np.eye(3), np.array([0.0, -0.45, 0.25])
    scene = Scene([MetalObject.sphere("can", p + np.array([dist, 0.0, 0.0]), 0.04)])
    V = measured_voltages(scene, R[None], p[None], np.eye(3)[None], np.zeros((1, 3)))[0]
    trk = EMTracker(TrackerConfig(hemisphere=tuple(p), solver="numpy"))
    trk.solve(ideal_voltages(R, p))  # warm start on the clean pose, as if approaching
    Rm, pm, _ = trk.solve(V)
    dV = np.linalg.norm(V - ideal_voltages(R, p))
    return float(np.linalg.norm(pm - p)), dV


def test_metal_near_sensor_errors_fall_like_inverse_cube():
    e1, v1 = _pose_error_near_sphere(0.10)
    e2, v2 = _pose_error_near_sphere(0.20)
    e4, v4 = _pose_error_near_sphere(0.40)
    assert e1 > e2 > e4 > 0
    assert e1 > 1e-3  # a can 10 cm from the sensor costs millimetres to centimetres
    # voltage perturbation ~ 1/r^3 in the sensor-object distance (source distance nearly fixed)
    assert 5.0 < v1 / v2 < 10.0
    assert 5.0 < v2 / v4 < 12.0


def test_soft_coupling_matches_far_and_stays_finite_near():
    r = np.array([[0.5, 0.2, -0.1]])
    np.testing.assert_allclose(soft_coupling(r, 1e-4), coupling(r), rtol=1e-6)
    near = soft_coupling(np.array([[1e-6, 0.0, 0.0]]), 0.05)
    assert np.isfinite(near).all() and np.abs(near).max() < 3 / 0.05 ** 3


def test_floor_is_an_image_source():
    # a perfect floor cancels the normal field on the floor plane
    src = np.array([[0.0, 0.5, 0.0]])
    pts = np.array([[0.3, 0.0, 0.1], [-0.2, 0.0, 0.4]])
    scene = Scene([], floor_height=0.0, floor_reflection=1.0)
    H = scene.field_matrix(pts, np.repeat(np.eye(3)[None], 2, 0), np.repeat(src, 2, 0))
    assert np.abs(H[:, 1, :]).max() < 1e-12  # y component of every coil's field


def test_so3_helpers_match_geometry():
    rng = np.random.default_rng(4)
    for _ in range(5):
        v = rng.normal(size=3)
        np.testing.assert_allclose(exp_so3(v), axis_angle_to_matrix(torch.from_numpy(v)).numpy(), atol=1e-12)
        A, B = _rot(rng), _rot(rng)
        assert angle_between(A, B) == pytest.approx(float(geodesic_angle(torch.from_numpy(A), torch.from_numpy(B))), abs=1e-9)
    small = exp_so3(np.array([1e-9, 0.0, 0.0]))
    assert float(matrix_to_axis_angle(torch.from_numpy(small))[0]) == pytest.approx(1e-9, rel=1e-6)
