"""Hand-eye calibration A_i X = Y B_i (MI-Poser App. B.1; Shah 2013 closed form + refinement)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from wearpose.calibration import DegenerateCalibrationError, axyb_closed_form, calibrate, handeye_transforms, solve_axyb
from wearpose.recording import Recording, SensorInfo, SensorStream

SIGMA_R = math.radians(0.5)
SIGMA_T = 0.001


def _problem(rng, N=100, axis=None):
    RX, RY = Rotation.random(2, random_state=rng).as_matrix()
    tX, tY = rng.normal(size=3) * 0.2, rng.normal(size=3) * 1.0
    if axis is None:
        RA = Rotation.random(N, random_state=rng).as_matrix()
    else:
        RA = Rotation.from_rotvec(np.outer(rng.uniform(-3, 3, N), axis)).as_matrix()
    tA = rng.normal(size=(N, 3))
    RB = np.einsum("ji,njk,kl->nil", RY, RA, RX)  # B = Y^-1 A X
    tB = np.einsum("ji,nj->ni", RY, np.einsum("nij,j->ni", RA, tX) + tA - tY)
    return (RX, tX, RY, tY), (RA, tA), (RB, tB)


def _noisy(rng, R, t):
    N = R.shape[0]
    return R @ Rotation.from_rotvec(rng.normal(size=(N, 3)) * SIGMA_R).as_matrix(), t + rng.normal(size=(N, 3)) * SIGMA_T


def _err(res, truth):
    RX, tX, RY, tY = truth
    X, Y = (m.numpy() for m in handeye_transforms(res))
    ang = lambda A, B: math.degrees(np.linalg.norm(Rotation.from_matrix(A.T @ B).as_rotvec()))  # noqa: E731
    return ang(X[:3, :3], RX), 1e3 * np.linalg.norm(X[:3, 3] - tX), ang(Y[:3, :3], RY), 1e3 * np.linalg.norm(Y[:3, 3] - tY)


def test_noise_free_exact():
    rng = np.random.default_rng(1)
    truth, A, B = _problem(rng, N=10)
    RX, tX, RY, tY, _ = axyb_closed_form(*A, *B)
    assert np.allclose(RX, truth[0], atol=1e-9) and np.allclose(tX, truth[1], atol=1e-9)
    assert np.allclose(RY, truth[2], atol=1e-9) and np.allclose(tY, truth[3], atol=1e-9)


def test_recovers_x_and_y_from_100_noisy_poses(record_property):
    """Acceptance. Noise 0.5 deg / 1 mm on every A_i and B_i, 100 poses, 10 random problems.

    Tolerances: the rotation of X is fixed only through R_A R_X = R_Y R_B, so its error is about
    sqrt(2) sigma_r / sqrt(N) per axis = 0.07 deg, ~0.12 deg as a 3-D angle; Y is also pinned by
    the translations (1 m lever arms), so it is better. Translations: sqrt(2) mm / sqrt(N) per axis
    plus rotation error times the lever arms, ~0.5 mm. We assert < 0.5 deg and < 2 mm on every
    problem (4x the typical figure) and report the mean.
    """
    rng = np.random.default_rng(7)
    closed, refined = [], []
    for _ in range(10):
        truth, A, B = _problem(rng)
        A, B = _noisy(rng, *A), _noisy(rng, *B)
        closed.append(_err(solve_axyb(A, B, refine=False), truth))
        refined.append(_err(solve_axyb(A, B), truth))
    c, r = np.array(closed), np.array(refined)
    fig = {"columns": ["X rot deg", "X trans mm", "Y rot deg", "Y trans mm"],
           "closed_form_mean": c.mean(0).round(3).tolist(), "closed_form_max": c.max(0).round(3).tolist(),
           "refined_mean": r.mean(0).round(3).tolist(), "refined_max": r.max(0).round(3).tolist()}
    record_property("axyb", json.dumps(fig))
    print("AX=YB, 100 poses, 0.5 deg / 1 mm:", json.dumps(fig))
    assert r[:, [0, 2]].max() < 0.5 and r[:, [1, 3]].max() < 2.0
    # The refinement is what brings the translations in: the closed form weighs them poorly.
    assert r[:, 3].mean() < c[:, 3].mean()


@pytest.mark.parametrize("case", ["one_axis", "no_rotation", "too_few"])
def test_degenerate_input_raises(case):
    rng = np.random.default_rng(3)
    if case == "one_axis":
        _, A, B = _problem(rng, N=50, axis=np.array([0.0, 0.0, 1.0]))
    elif case == "no_rotation":
        _, A, B = _problem(rng, N=50, axis=np.array([0.0, 0.0, 0.0]))
    else:
        _, A, B = _problem(rng, N=2)
    with pytest.raises(DegenerateCalibrationError, match="axis|at least 3"):
        solve_axyb(A, B)


def test_robust_loss_with_outliers():
    rng = np.random.default_rng(5)
    truth, A, B = _problem(rng)
    A, B = _noisy(rng, *A), _noisy(rng, *B)
    tB = B[1].copy()
    tB[:5] += 0.2  # five pairs hit by metal distortion: 20 cm off
    res = solve_axyb(A, (B[0], tB), loss="soft_l1")
    ex = _err(res, truth)
    assert ex[0] < 0.5 and ex[2] < 0.5 and ex[1] < 5.0 and ex[3] < 5.0


def test_calibrate_recording_pairs_streams():
    """MI-Poser App. B.1: an iPhone (VIO world, 60 Hz) and an EM sensor (source frame, 120 Hz) on a rigid rig."""
    rng = np.random.default_rng(11)
    truth, A, B = _problem(rng, N=240)
    RX, tX, RY, tY = truth
    ta = np.arange(120) / 60.0
    tb = np.arange(240) / 120.0
    # A: 60 Hz, B: 120 Hz; B's even frames are the pairs, odd ones are other poses.
    phone = SensorStream(SensorInfo("phone", "vio", None, 60.0), ta, np.ones(120, bool),
                         position=A[1][::2], orientation=A[0][::2])
    em = SensorStream(SensorInfo("em", "em6dof", None, 120.0), tb, np.ones(240, bool), position=B[1], orientation=B[0])
    rec = Recording([phone, em])
    res = calibrate(rec, "hand-eye", sensors=("phone", "em"))
    assert res.params["pairs"] == 120 and res.params["a"] == "phone"
    e = _err(res, truth)
    assert max(e) < 1e-3
