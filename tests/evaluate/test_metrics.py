"""Tests for wearpose.evaluate.metrics: hand-built cases with known answers, a numpy reference
for PA-MPJPE, and property tests (symmetry, non-negativity, invariances)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from wearpose.body.kinematics import forward_kinematics
from wearpose.body.skeleton import MAJOR_JOINTS, NUM_JOINTS, SIP_JOINTS
from wearpose.errors import ShapeError
from wearpose.evaluate import metrics as M
from wearpose.geometry import axis_angle_to_matrix, rotation_x, rotation_y, rotation_z

DEG = math.pi / 180.0
HYP = settings(max_examples=25, deadline=None)


def rand_rot(*shape: int, gen: torch.Generator, dtype=torch.float64, max_angle: float = math.pi) -> torch.Tensor:
    v = torch.randn(*shape, 3, generator=gen, dtype=dtype)
    v = v / v.norm(dim=-1, keepdim=True) * torch.rand(*shape, 1, generator=gen, dtype=dtype) * max_angle
    return axis_angle_to_matrix(v)


def rest_joints(seed: int = 0, dtype=torch.float64) -> torch.Tensor:
    g = torch.Generator().manual_seed(seed)
    return torch.randn(NUM_JOINTS, 3, generator=g, dtype=dtype) * 0.3


def identity_pose(*batch: int, dtype=torch.float64) -> torch.Tensor:
    return torch.eye(3, dtype=dtype).expand(*batch, NUM_JOINTS, 3, 3).clone()


def rot_about(axis: str, deg: float, dtype=torch.float64) -> torch.Tensor:
    fn = {"x": rotation_x, "y": rotation_y, "z": rotation_z}[axis]
    return fn(torch.tensor(deg * DEG, dtype=dtype))


# ---------------------------------------------------------------------------------------------
# MPJPE / PA-MPJPE
# ---------------------------------------------------------------------------------------------

def test_mpjpe_translation_root_aligned_zero_else_offset():
    gen = torch.Generator().manual_seed(1)
    gt = torch.randn(5, 24, 3, generator=gen, dtype=torch.float64)
    offset = torch.tensor([0.3, -0.4, 1.2], dtype=torch.float64)
    pred = gt + offset
    assert torch.allclose(M.mpjpe(pred, gt), torch.zeros(5, dtype=torch.float64), atol=1e-12)
    assert torch.allclose(M.mpjpe(pred, gt, root_align=False), offset.norm().expand(5))
    assert M.mpjpe(pred, gt).shape == (5,)


def test_mpjpe_single_joint_known_value():
    gt = torch.zeros(24, 3, dtype=torch.float64)
    pred = gt.clone()
    pred[15, 1] = 0.12  # head 12 cm off
    assert M.mpjpe(pred, gt).item() == pytest.approx(0.12 / 24)
    assert M.mpjpe(pred, gt, MAJOR_JOINTS).item() == pytest.approx(0.12 / 15)
    assert M.mpjpe(pred, gt, SIP_JOINTS).item() == 0.0
    # Moving the root with root alignment moves every other joint relative to it.
    pred = gt.clone()
    pred[0, 0] = 0.1
    assert M.mpjpe(pred, gt).item() == pytest.approx(0.1 * 23 / 24)


def test_pa_mpjpe_similarity_copy_is_zero():
    gen = torch.Generator().manual_seed(2)
    gt = torch.randn(4, 7, 24, 3, generator=gen, dtype=torch.float64)
    R = rand_rot(4, 7, gen=gen)
    pred = 2.7 * gt @ R.transpose(-1, -2) + torch.randn(4, 7, 1, 3, generator=gen, dtype=torch.float64)
    err = M.pa_mpjpe(pred, gt)
    assert err.shape == (4, 7)
    assert err.abs().max().item() < 1e-10
    assert M.mpjpe(pred, gt).min().item() > 0.1  # while plain MPJPE is large
    assert M.pa_mpjpe(pred, gt, MAJOR_JOINTS).abs().max().item() < 1e-10


def _pa_mpjpe_numpy(pred: np.ndarray, gt: np.ndarray) -> float:
    """Textbook similarity Procrustes (HMR's compute_similarity_transform), one frame."""
    mu1, mu2 = pred.mean(0), gt.mean(0)
    X1, X2 = pred - mu1, gt - mu2
    var1 = (X1 ** 2).sum()
    K = X1.T @ X2
    U, s, Vh = np.linalg.svd(K)
    V = Vh.T
    Z = np.eye(3)
    Z[-1, -1] *= np.sign(np.linalg.det(U @ V.T))
    R = V @ Z @ U.T
    scale = np.trace(R @ K) / var1
    t = mu2 - scale * R @ mu1
    aligned = scale * pred @ R.T + t
    return float(np.linalg.norm(aligned - gt, axis=1).mean())


@HYP
@given(seed=st.integers(0, 2**31 - 1), n=st.integers(3, 30))
def test_pa_mpjpe_matches_numpy_reference(seed, n):
    rng = np.random.default_rng(seed)
    gt = rng.normal(size=(n, 3))
    pred = gt + rng.normal(scale=0.3, size=(n, 3))
    ref = _pa_mpjpe_numpy(pred, gt)
    ours = M.pa_mpjpe(torch.from_numpy(pred), torch.from_numpy(gt)).item()
    assert ours == pytest.approx(ref, rel=1e-7, abs=1e-9)
    # The alignment is least squares: its residual never exceeds that of centring alone.
    aligned = M.procrustes_align(torch.from_numpy(pred), torch.from_numpy(gt)).numpy()
    centred = ((pred - pred.mean(0)) - (gt - gt.mean(0))) ** 2
    assert ((aligned - gt) ** 2).sum() <= centred.sum() + 1e-9


def test_pa_mpjpe_batched_matches_numpy_and_scipy_disparity():
    from scipy.spatial import procrustes

    rng = np.random.default_rng(3)
    gt = rng.normal(size=(6, 24, 3))
    pred = gt + rng.normal(scale=0.1, size=(6, 24, 3))
    ours = M.pa_mpjpe(torch.from_numpy(pred), torch.from_numpy(gt)).numpy()
    ref = np.array([_pa_mpjpe_numpy(p, g) for p, g in zip(pred, gt)])
    np.testing.assert_allclose(ours, ref, rtol=1e-8)
    # scipy's disparity = sum of squared residuals after aligning the (unit-normalised)
    # prediction to the unit-normalised ground truth; compare through procrustes_align.
    for p, g in zip(pred, gt):
        gn = (g - g.mean(0)) / np.linalg.norm(g - g.mean(0))
        pn = (p - p.mean(0)) / np.linalg.norm(p - p.mean(0))
        _, _, disparity = procrustes(gn, pn)
        aligned = M.procrustes_align(torch.from_numpy(pn), torch.from_numpy(gn)).numpy()
        assert ((aligned - gn) ** 2).sum() == pytest.approx(disparity, rel=1e-8)


def test_pa_mpjpe_float32_and_rigid_option():
    gen = torch.Generator().manual_seed(4)
    gt = torch.randn(10, 24, 3, generator=gen)
    R = rand_rot(10, gen=gen, dtype=torch.float32)
    pred = gt @ R.transpose(-1, -2) + 1.0
    assert M.pa_mpjpe(pred, gt).dtype == torch.float32
    assert M.pa_mpjpe(pred, gt, scale=False).abs().max().item() < 1e-5
    # A scaled copy is not a rigid copy.
    assert M.pa_mpjpe(1.5 * pred, gt, scale=False).min().item() > 1e-2
    assert M.pa_mpjpe(1.5 * pred, gt).abs().max().item() < 1e-5


# ---------------------------------------------------------------------------------------------
# MPJAE / SIP / angular error
# ---------------------------------------------------------------------------------------------

@pytest.mark.parametrize("axis", ["x", "y", "z"])
def test_mpjae_single_leaf_joint_30_degrees(axis):
    gt = identity_pose()
    pred = gt.clone()
    pred[15] = rot_about(axis, 30.0)  # head: no descendants
    assert M.mpjae(pred, gt).item() == pytest.approx(30 * DEG / 15, rel=1e-9)
    assert M.mpjae(pred, gt, joints=None).item() == pytest.approx(30 * DEG / 24, rel=1e-9)


def test_mpjae_propagates_along_chain_and_ignores_root():
    gt = identity_pose()
    # Left shoulder (16) rotates its global frame and the elbow's (18; 20, 22 are not major).
    pred = gt.clone()
    pred[16] = rot_about("z", 30.0)
    assert M.mpjae(pred, gt).item() == pytest.approx(2 * 30 * DEG / 15, rel=1e-9)
    assert M.mpjae(pred, gt, joints=None).item() == pytest.approx(4 * 30 * DEG / 24, rel=1e-9)
    # Local comparison sees only the shoulder.
    local = M.joint_angle_errors(pred, gt, frame="local")
    assert local[16].item() == pytest.approx(30 * DEG) and local.sum().item() == pytest.approx(30 * DEG)
    # Wrist (20) is not a major joint and has no major descendants.
    pred = gt.clone()
    pred[20] = rot_about("x", 30.0)
    assert M.mpjae(pred, gt).item() == 0.0
    # Root orientation is removed.
    pred = gt.clone()
    pred[0] = rot_about("y", 70.0)
    assert M.mpjae(pred, gt).item() == pytest.approx(0.0, abs=1e-7)
    assert M.global_angular_error(pred, gt).item() == pytest.approx(0.0, abs=1e-7)
    assert M.global_angular_error(pred, gt, root_aligned=False).item() == pytest.approx(70 * DEG, rel=1e-9)


def test_sip_error_only_sees_hips_and_shoulders():
    gt = identity_pose()
    for j in (15, 18, 19, 4, 5, 13):  # head, elbows, knees, collar: not SIP joints nor ancestors
        pred = gt.clone()
        pred[j] = rot_about("x", 40.0)
        if j == 13:  # left collar is the shoulder's parent
            assert M.sip_error(pred, gt).item() == pytest.approx(40 * DEG / 4, rel=1e-9)
        else:
            assert M.sip_error(pred, gt).item() == 0.0
    pred = gt.clone()
    pred[1] = rot_about("x", 30.0)  # left hip
    assert M.sip_error(pred, gt).item() == pytest.approx(30 * DEG / 4, rel=1e-9)
    pred = gt.clone()
    pred[9] = rot_about("z", 30.0)  # spine3: both shoulders inherit it (global space)
    assert M.sip_error(pred, gt).item() == pytest.approx(2 * 30 * DEG / 4, rel=1e-9)


def test_birae_groups_partition_and_values():
    groups = M.BIRAE_JOINT_GROUPS
    assert groups["distal"] == SIP_JOINTS
    assert sorted(sum(groups.values(), ())) == sorted(MAJOR_JOINTS)
    gt = identity_pose()
    pred = gt.clone()
    pred[15] = rot_about("x", 30.0)  # head: tracking group
    res = M.mpjae_groups(pred, gt)
    assert res["tracking"].item() == pytest.approx(30 * DEG / 5, rel=1e-9)
    assert res["distal"].item() == 0.0 and res["other"].item() == 0.0


@HYP
@given(seed=st.integers(0, 2**31 - 1))
def test_angular_metrics_properties(seed):
    gen = torch.Generator().manual_seed(seed)
    a = rand_rot(3, 24, gen=gen)
    b = rand_rot(3, 24, gen=gen)
    for fn in (M.mpjae, M.sip_error, M.global_angular_error):
        ab, ba = fn(a, b), fn(b, a)
        assert ab.shape == (3,)
        assert torch.allclose(ab, ba, atol=1e-9)  # symmetric
        assert (ab >= 0).all() and (ab <= math.pi + 1e-9).all()
        assert fn(a, a).abs().max().item() < 1e-6  # zero on identical poses
    # Invariant to a different world rotation of each root (root-relative orientations).
    a2, b2 = a.clone(), b.clone()
    a2[:, 0] = rand_rot(3, gen=gen) @ a[:, 0]
    b2[:, 0] = rand_rot(3, gen=gen) @ b[:, 0]
    assert torch.allclose(M.mpjae(a2, b2), M.mpjae(a, b), atol=1e-9)
    assert torch.allclose(M.sip_error(a2, b2), M.sip_error(a, b), atol=1e-9)
    # Global (root-included) errors are invariant to a common world rotation.
    W = rand_rot(3, gen=gen)
    a3, b3 = a.clone(), b.clone()
    a3[:, 0] = W @ a[:, 0]
    b3[:, 0] = W @ b[:, 0]
    assert torch.allclose(M.global_angular_error(a3, b3, root_aligned=False),
                          M.global_angular_error(a, b, root_aligned=False), atol=1e-9)


def test_mask_joint_rotations():
    gen = torch.Generator().manual_seed(5)
    a = rand_rot(2, 24, gen=gen)
    m = M.mask_joint_rotations(a)
    eye = torch.eye(3, dtype=a.dtype)
    for j in (7, 8, 10, 11, 20, 21, 22, 23):
        assert torch.equal(m[:, j], eye.expand(2, 3, 3))
    for j in (0,) + MAJOR_JOINTS:
        assert torch.equal(m[:, j], a[:, j])
    assert not torch.equal(a[:, 7], eye.expand(2, 3, 3))  # input untouched


# ---------------------------------------------------------------------------------------------
# positional / mesh error
# ---------------------------------------------------------------------------------------------

def _fk(local: torch.Tensor, trans: torch.Tensor, rest: torch.Tensor):
    g_rot, joints = forward_kinematics(local, rest)
    return g_rot, joints + trans.unsqueeze(-2)


def test_positional_error_invariant_to_root_pose_and_zero_when_equal():
    gen = torch.Generator().manual_seed(6)
    rest = rest_joints()
    local = rand_rot(4, 24, gen=gen, max_angle=1.0)
    trans = torch.randn(4, 3, generator=gen, dtype=torch.float64)
    _, gt_j = _fk(local, trans, rest)
    other = local.clone()
    other[:, 0] = rand_rot(4, gen=gen) @ local[:, 0]
    _, pred_j = _fk(other, trans + 5.0, rest)
    err = M.positional_error(pred_j, gt_j, other[:, 0], local[:, 0])
    assert err.shape == (4,)
    assert err.abs().max().item() < 1e-10
    # Without orientation alignment the root rotation shows up.
    assert M.positional_error(pred_j, gt_j, None, None).min().item() > 1e-3
    # A single-joint local error gives a positive error.
    bad = local.clone()
    bad[:, 18] = rot_about("y", 45.0) @ bad[:, 18]
    _, bad_j = _fk(bad, trans, rest)
    assert M.positional_error(bad_j, gt_j, bad[:, 0], local[:, 0]).min().item() > 1e-4


def test_mesh_error_invariant_to_global_rigid_transform():
    gen = torch.Generator().manual_seed(7)
    rest = rest_joints()
    local = rand_rot(3, 24, gen=gen, max_angle=1.0)
    trans = torch.randn(3, 3, generator=gen, dtype=torch.float64)
    g_rot, joints = _fk(local, trans, rest)
    # "Vertices": points rigidly attached to each joint (two per joint).
    offs = torch.randn(24, 2, 3, generator=gen, dtype=torch.float64) * 0.05
    verts = (joints.unsqueeze(-2) + (g_rot.unsqueeze(-3) @ offs.unsqueeze(-1)).squeeze(-1)).reshape(3, 48, 3)
    # Perturbed ground truth: move the elbows' offsets a bit.
    gt_verts = verts.clone()
    gt_verts[:, 36:40] += 0.02
    base = M.mesh_error(verts, gt_verts, joints[:, 0], joints[:, 0], g_rot[:, 0], g_rot[:, 0])
    assert base.min().item() > 0
    W = rand_rot(3, gen=gen)
    t = torch.randn(3, 3, generator=gen, dtype=torch.float64)
    v2 = verts @ W.transpose(-1, -2) + t.unsqueeze(-2)
    root2 = (W @ joints[:, 0].unsqueeze(-1)).squeeze(-1) + t
    rot2 = W @ g_rot[:, 0]
    moved = M.mesh_error(v2, gt_verts, root2, joints[:, 0], rot2, g_rot[:, 0])
    assert torch.allclose(moved, base, atol=1e-12)
    assert M.mesh_error(verts, verts, joints[:, 0], joints[:, 0], g_rot[:, 0], g_rot[:, 0]).abs().max() < 1e-12
    # Known value: every vertex displaced by the same 3 cm, root untouched.
    shifted = verts + torch.tensor([0.0, 0.03, 0.0], dtype=torch.float64)
    e = M.mesh_error(shifted, verts, joints[:, 0], joints[:, 0])
    assert torch.allclose(e, torch.full_like(e, 0.03))


@HYP
@given(seed=st.integers(0, 2**31 - 1))
def test_position_metrics_properties(seed):
    gen = torch.Generator().manual_seed(seed)
    a = torch.randn(2, 5, 24, 3, generator=gen, dtype=torch.float64)
    b = torch.randn(2, 5, 24, 3, generator=gen, dtype=torch.float64)
    for kw in ({}, {"root_align": False}, {"joints": MAJOR_JOINTS}):
        ab = M.mpjpe(a, b, **kw)
        assert ab.shape == (2, 5) and (ab >= 0).all()
        assert torch.allclose(ab, M.mpjpe(b, a, **kw))
    # Common rigid transform of both leaves MPJPE and PA-MPJPE unchanged.
    W = rand_rot(gen=gen)
    t = torch.randn(3, generator=gen, dtype=torch.float64)
    a2, b2 = a @ W.T + t, b @ W.T + t
    assert torch.allclose(M.mpjpe(a2, b2), M.mpjpe(a, b), atol=1e-10)
    assert torch.allclose(M.pa_mpjpe(a2, b2), M.pa_mpjpe(a, b), atol=1e-10)
    assert (M.pa_mpjpe(a, b) >= 0).all()
    # PA-MPJPE is invariant to any similarity transform of the prediction alone.
    s = 0.5 + torch.rand((), generator=gen, dtype=torch.float64)
    assert torch.allclose(M.pa_mpjpe(s * a @ W.T + t, b), M.pa_mpjpe(a, b), atol=1e-9)


# ---------------------------------------------------------------------------------------------
# jitter
# ---------------------------------------------------------------------------------------------

def _trajectory(coeffs: list[list[float]], T: int, fps: float, J: int = 3) -> torch.Tensor:
    """p(t) = sum_k c_k t^k per axis, for J joints, shape (T, J, 3)."""
    t = torch.arange(T, dtype=torch.float64) / fps
    c = torch.tensor(coeffs, dtype=torch.float64)  # (K, 3)
    powers = torch.stack([t ** k for k in range(c.shape[0])], -1)  # (T, K)
    p = powers @ c  # (T, 3)
    offsets = torch.arange(J, dtype=torch.float64)[:, None] * torch.tensor([0.1, 0.2, 0.3], dtype=torch.float64)
    return p[:, None, :] + offsets


def test_jitter_zero_for_constant_velocity_and_acceleration():
    fps = 60.0
    for coeffs in ([[0, 0, 0], [1, -2, 0.5]], [[1, 2, 3], [1, 0, 0], [0.5, -4.9, 2]]):
        p = _trajectory(coeffs, 30, fps)
        j = M.jitter(p, fps)
        assert j.shape == (27,)
        assert j.abs().max().item() < 1e-6


def test_jitter_cubic_exact_jerk():
    fps = 60.0
    c3 = torch.tensor([2.0, -1.0, 0.5], dtype=torch.float64)
    p = _trajectory([[0, 0, 0], [0.3, 0, 0], [1, 1, 1], c3.tolist()], 40, fps)
    expected = 6 * c3.norm().item()
    assert torch.allclose(M.jitter(p, fps), torch.full((37,), expected, dtype=torch.float64), rtol=1e-6)
    assert torch.allclose(M.jerk(p, fps), torch.full((37, 3), expected, dtype=torch.float64), rtol=1e-6)
    # Root-relative jitter removes a common cubic translation.
    assert M.jitter(p, fps, root_relative=True).abs().max().item() < 1e-6


def test_relative_jitter_in_root_frame():
    fps = 30.0
    T = 20
    # Body rotating about Y with constant angular velocity; joints fixed in the root frame.
    ang = torch.arange(T, dtype=torch.float64) * 0.2
    R = rotation_y(ang)  # (T, 3, 3)
    local = torch.tensor([[0.0, 0.0, 0.0], [0.5, 0.0, 0.0], [0.0, 0.3, 0.4]], dtype=torch.float64)
    joints = (R.unsqueeze(1) @ local.unsqueeze(-1)).squeeze(-1)  # (T, 3, 3)
    assert M.jitter(joints, fps).mean().item() > 1.0  # circular motion has jerk
    assert M.jitter(joints, fps, root_relative=True).mean().item() > 1.0  # root-translation-free only
    assert M.jitter(joints, fps, root_relative=True, root_rot=R).abs().max().item() < 1e-9


def test_jitter_batched_float32():
    p = torch.randn(2, 3, 10, 24, 3)
    j = M.jitter(p, 60)
    assert j.shape == (2, 3, 7) and j.dtype == torch.float32 and (j >= 0).all()


# ---------------------------------------------------------------------------------------------
# translation
# ---------------------------------------------------------------------------------------------

def test_cumulative_translation_error_straight_line():
    T = 101
    t = torch.arange(T, dtype=torch.float64)
    gt = torch.stack([0.1 * t, torch.zeros_like(t), torch.zeros_like(t)], -1) + 3.0  # 0.1 m / frame
    pred = torch.stack([0.09 * t, torch.zeros_like(t), torch.zeros_like(t)], -1) - 1.0  # anchors differ
    curve = M.cumulative_translation_error(pred, gt, thresholds=[0.0, 1.0, 5.0, 10.0, 20.0])
    assert torch.allclose(curve.travelled, 0.1 * t)
    assert torch.allclose(curve.error, 0.01 * t)
    assert torch.allclose(curve.error_at[:4], torch.tensor([0.0, 0.1, 0.5, 1.0], dtype=torch.float64))
    assert math.isnan(curve.error_at[4].item())  # never travelled 20 m
    assert curve.final_error.item() == pytest.approx(1.0)
    assert curve.drift.item() == pytest.approx(0.1)
    assert curve.mean_error.item() == pytest.approx(0.5)
    # Batched, and no motion -> NaN drift.
    batch = torch.stack([gt, torch.zeros_like(gt)])
    c2 = M.cumulative_translation_error(batch + 0.0, batch)
    assert c2.error.abs().max().item() == 0.0
    assert c2.error_at.shape == (2, 11)
    assert math.isnan(c2.drift[1].item())


# ---------------------------------------------------------------------------------------------
# shape errors
# ---------------------------------------------------------------------------------------------

def test_shape_errors():
    j24 = torch.zeros(5, 24, 3)
    with pytest.raises(ShapeError):
        M.mpjpe(j24, torch.zeros(5, 23, 3))
    with pytest.raises(ShapeError):
        M.mpjpe(torch.zeros(5, 24, 2), torch.zeros(5, 24, 2))
    with pytest.raises(ShapeError):
        M.mpjpe(j24, j24, joints=[30])
    with pytest.raises(ShapeError):
        M.pa_mpjpe(j24.numpy(), j24.numpy())
    with pytest.raises(ShapeError):
        M.mpjae(identity_pose(5), identity_pose(4))
    with pytest.raises(ShapeError):
        M.mpjae(torch.eye(3).expand(5, 15, 3, 3), torch.eye(3).expand(5, 15, 3, 3))  # not 24 joints
    with pytest.raises(ShapeError):
        M.sip_error(torch.zeros(5, 24, 3), torch.zeros(5, 24, 3))
    with pytest.raises(ShapeError):
        M.jitter(torch.zeros(3, 24, 3), 60)  # fewer than 4 frames
    with pytest.raises(ShapeError):
        M.jitter(torch.zeros(10, 24, 3), 0)
    with pytest.raises(ShapeError):
        M.mesh_error(torch.zeros(5, 10, 3), torch.zeros(5, 10, 3), torch.zeros(4, 3), torch.zeros(5, 3))
    with pytest.raises(ShapeError):
        M.positional_error(j24, j24, torch.eye(3).expand(5, 3, 3), None)
    with pytest.raises(ShapeError):
        M.cumulative_translation_error(torch.zeros(10, 3), torch.zeros(11, 3))
    with pytest.raises(ShapeError):
        M.mpjpe(torch.zeros(5, 24, 3, dtype=torch.int64), torch.zeros(5, 24, 3, dtype=torch.int64))
    with pytest.raises(ShapeError):
        M.to_report_units({"unknown": 1.0})
    with pytest.raises(ShapeError):
        M.joint_angle_errors(identity_pose(), identity_pose(), frame="bogus")


# ---------------------------------------------------------------------------------------------
# reporting
# ---------------------------------------------------------------------------------------------

def test_to_report_units():
    out = M.to_report_units({"mpjpe": 0.05, "mpjae": math.pi / 6, "mesh_error": 0.07,
                             "jitter_abs": 1500.0, "translation_drift": 0.1})
    assert out["mpjpe_mm"] == pytest.approx(50.0)
    assert out["mpjae_deg"] == pytest.approx(30.0)
    assert out["mesh_error_cm"] == pytest.approx(7.0)
    assert out["jitter_abs_km_s3"] == pytest.approx(1.5)
    assert out["translation_drift_pct"] == pytest.approx(10.0)


def test_compute_all_and_format_table():
    gen = torch.Generator().manual_seed(8)
    rest = rest_joints()
    T = 12
    gt_local = rand_rot(T, 24, gen=gen, max_angle=0.5)
    pred_local = gt_local.clone()
    pred_local[:, 15] = rot_about("x", 30.0) @ pred_local[:, 15]  # head off by 30 deg
    gt_trans = torch.stack([torch.arange(T, dtype=torch.float64) * 0.05, torch.zeros(T, dtype=torch.float64),
                            torch.zeros(T, dtype=torch.float64)], -1)
    _, gt_j = _fk(gt_local, gt_trans, rest)
    _, pred_j = _fk(pred_local, gt_trans, rest)
    gt = {"local_rot": gt_local, "joints": gt_j, "vertices": gt_j.clone(), "trans": gt_trans}
    pred = {"local_rot": pred_local, "joints": pred_j, "vertices": pred_j.clone(), "trans": gt_trans * 0.9}
    res = M.compute_all(pred, gt, fps=60.0)
    assert res["mpjae_deg"] == pytest.approx(2.0, rel=1e-9)
    assert res["mpjae_all_deg"] == pytest.approx(30 / 24, rel=1e-9)
    assert res["angular_error_deg"] == pytest.approx(30 / 24, rel=1e-9)
    assert res["sip_error_deg"] == pytest.approx(0.0, abs=1e-6)
    assert res["mpjae_tracking_deg"] == pytest.approx(6.0, rel=1e-9)
    assert res["mpjpe_mm"] == pytest.approx(res["positional_error_cm"] * 10, rel=1e-9)
    assert res["mesh_error_cm"] == pytest.approx(res["positional_error_cm"], rel=1e-9)
    assert res["translation_drift_pct"] == pytest.approx(10.0, rel=1e-9)
    for key in ("mpjpe_major_mm", "pa_mpjpe_mm", "pa_mpjpe_major_mm", "jitter_abs_km_s3", "jitter_rel_km_s3",
                "translation_error_cm", "mpjae_distal_deg", "mpjae_other_deg"):
        assert key in res and math.isfinite(res[key])
    # Validity mask: frames where only the head is wrong vs. a corrupted frame.
    pred_bad = dict(pred)
    pred_bad["local_rot"] = pred_local.clone()
    pred_bad["local_rot"][3, 16] = rot_about("z", 90.0)
    valid = torch.ones(T, dtype=torch.bool)
    valid[3] = False
    masked = M.compute_all(pred_bad, gt, valid=valid)
    assert masked["mpjae_deg"] == pytest.approx(2.0, rel=1e-9)
    # Only rotations given -> only rotation metrics.
    rot_only = M.compute_all({"local_rot": pred_local}, {"local_rot": gt_local})
    assert "mpjpe_mm" not in rot_only and "mpjae_deg" in rot_only

    table = M.format_table({"ours": res, "rot-only": rot_only})
    lines = table.strip().splitlines()
    assert lines[0].startswith("| | MPJAE (15) [deg]")
    assert "MPJPE [mm]" in lines[0] and "Mesh err [cm]" in lines[0] and "Abs jitter [km/s^3]" in lines[0]
    assert len(lines) == 4 and lines[2].startswith("| ours | 2.00")
    assert " - " in lines[3]
    single = M.format_table(res, digits=1)
    assert single.count("\n") == 3


def test_metrics_are_differentiable():
    gen = torch.Generator().manual_seed(9)
    rest = rest_joints()
    gt_local = rand_rot(2, 24, gen=gen, max_angle=0.5)
    pred_local = rand_rot(2, 24, gen=gen, max_angle=0.5).requires_grad_(True)
    _, gt_j = _fk(gt_local, torch.zeros(2, 3, dtype=torch.float64), rest)
    _, pred_j = _fk(pred_local, torch.zeros(2, 3, dtype=torch.float64), rest)
    loss = (M.mpjpe(pred_j, gt_j).sum() + M.mpjae(pred_local, gt_local).sum()
            + M.positional_error(pred_j, gt_j, pred_local[:, 0], gt_local[:, 0]).sum())
    loss.backward()
    assert pred_local.grad is not None and torch.isfinite(pred_local.grad).all()


# --------------------------------------------------------------------------- joint_error_split
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_joint_error_split_constant_offset_is_all_bias(dtype):
    g = torch.Generator().manual_seed(0)
    gt = torch.randn(50, 24, 3, generator=g, dtype=dtype)
    offset = torch.zeros(24, 3, dtype=dtype)
    offset[16] = torch.tensor([0.03, -0.04, 0.0], dtype=dtype)  # 5 cm at the left shoulder, every frame
    s = M.joint_error_split(gt + offset, gt)
    assert s.frames == 50 and s.rms.dtype == dtype and s.rms.shape == (24,)
    assert float(s.bias[16]) == pytest.approx(0.05, rel=1e-5)
    assert float(s.varying[16]) == pytest.approx(0.0, abs=1e-6)
    assert float(s.rms[16]) == pytest.approx(0.05, rel=1e-5)
    assert float(s.mean[16]) == pytest.approx(0.05, rel=1e-5)
    others = [j for j in range(24) if j != 16]
    assert float(s.rms[others].abs().max()) == pytest.approx(0.0, abs=1e-6)


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_joint_error_split_zero_mean_error_is_all_varying_and_parts_add_up(dtype):
    g = torch.Generator().manual_seed(1)
    gt = torch.randn(40, 24, 3, generator=g, dtype=dtype)
    wobble = torch.randn(20, 24, 3, generator=g, dtype=dtype)
    wobble[:, 0] = 0.0
    noise = torch.cat([wobble, -wobble])  # every joint's error averages to exactly zero over the clip
    s = M.joint_error_split(gt + noise, gt)
    assert float(s.bias.abs().max()) == pytest.approx(0.0, abs=1e-6)
    torch.testing.assert_close(s.varying, noise.square().sum(-1).mean(0).sqrt())
    pred = gt + noise + torch.tensor([0.0, 0.1, 0.0], dtype=dtype)
    mixed = M.joint_error_split(pred, gt)
    torch.testing.assert_close(mixed.rms.square(), mixed.bias.square() + mixed.varying.square())
    torch.testing.assert_close(mixed.mean, M.joint_position_errors(pred, gt).mean(0))  # MPJPE's per joint
    assert float(mixed.bias[0]) == 0.0  # the root is aligned away


def test_joint_error_split_root_frame_keeps_a_body_offset_constant():
    # A skeleton offset fixed in the body: constant in the true root's frame, not in the joints' frame
    # once the root turns.
    T = 36
    angles = torch.linspace(0, 2 * math.pi, T + 1, dtype=torch.float64)[:-1]
    R = rotation_y(angles)
    gt = torch.zeros(T, 24, 3, dtype=torch.float64)
    gt[:, 1] = torch.tensor([0.1, 0.0, 0.0], dtype=torch.float64) @ R.transpose(-1, -2)
    body_offset = torch.tensor([0.0, 0.0, 0.02], dtype=torch.float64)
    pred = gt.clone()
    pred[:, 1] = gt[:, 1] + body_offset @ R.transpose(-1, -2)
    in_body = M.joint_error_split(pred, gt, R)
    assert float(in_body.bias[1]) == pytest.approx(0.02, rel=1e-9)
    assert float(in_body.varying[1]) == pytest.approx(0.0, abs=1e-9)
    in_world = M.joint_error_split(pred, gt)  # the offset turns a full circle: its mean is zero
    assert float(in_world.bias[1]) == pytest.approx(0.0, abs=1e-9)
    assert float(in_world.varying[1]) == pytest.approx(0.02, rel=1e-9)


def test_pool_joint_error_splits_weights_clips_by_frames():
    g = torch.Generator().manual_seed(2)
    a_gt, b_gt = torch.randn(10, 24, 3, generator=g), torch.randn(30, 24, 3, generator=g)
    a = M.joint_error_split(a_gt + torch.tensor([0.03, 0.0, 0.0]), a_gt)
    b = M.joint_error_split(b_gt + 0.01 * torch.randn(30, 24, 3, generator=g), b_gt)
    p = M.pool_joint_error_splits([a, b])
    assert p.frames == 40
    torch.testing.assert_close(p.rms.square(), (10 * a.rms.square() + 30 * b.rms.square()) / 40)
    torch.testing.assert_close(p.mean, (10 * a.mean + 30 * b.mean) / 40)
    torch.testing.assert_close(p.rms.square(), p.bias.square() + p.varying.square())
    assert float(p.bias[5]) == pytest.approx(float((10 * a.bias[5] ** 2 + 30 * b.bias[5] ** 2) / 40) ** 0.5, rel=1e-5)


def test_joint_error_split_refuses_bad_input_naming_the_shape():
    x = torch.zeros(5, 24, 3)
    with pytest.raises(ShapeError, match=r"one clip's joints \(T, J, 3\)"):
        M.joint_error_split(x[None], x[None])
    with pytest.raises(ShapeError, match="gt_root_rot"):
        M.joint_error_split(x, x, torch.eye(3).expand(4, 3, 3))
    with pytest.raises(ShapeError, match="no clips"):
        M.pool_joint_error_splits([])
    with pytest.raises(ShapeError, match="different joints"):
        M.pool_joint_error_splits([M.joint_error_split(x, x), M.joint_error_split(x[:, :15], x[:, :15])])
