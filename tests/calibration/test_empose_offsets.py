"""EM-POSE subject offsets (supp. Eq. 1-3, Sec. 2.2): simulate with known offsets, calibrate, compare."""

from __future__ import annotations

import json
import math
import warnings

import pytest
import torch

from calib_testutils import posed_motion, sim_to_recording
from wearpose.calibration import CalibrationError, calibrate, fit_offsets
from wearpose.geometry import axis_angle_to_matrix, geodesic_angle
from wearpose.sensors import random_subject_offsets, simulate

FPS = 120.0


@pytest.fixture(scope="module")
def calib_motion():
    # EM-POSE's calibration sequence: T-pose, head and wrist rotations, ... (supp. Sec. 8); 4 s
    # of T-pose + smooth whole-body motion exercises every sensor.
    return posed_motion(int(4 * FPS), FPS, seed=3, amp=0.4, hold=0.5)


@pytest.fixture(scope="module")
def subject():
    return random_subject_offsets(12, torch.Generator().manual_seed(11))


def _errors(res, truth):
    et = (res.translation - truth.t).norm(dim=-1) * 1e3
    er = torch.rad2deg(geodesic_angle(res.rotation, truth.R))
    return et, er


def _run(calib_motion, subject, body, noise):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # site substitutions on assets without shoulder sites
        sim = simulate(calib_motion, "em12", body, seed=5, noise=noise, offsets=subject)
    rec = sim_to_recording(sim, ground_truth=calib_motion)
    return sim, calibrate(rec, "empose-offsets", body=body)


def test_noise_free_recovery(calib_motion, subject, body):
    sim, res = _run(calib_motion, subject, body, "none")
    et, er = _errors(res, sim.em_offsets)  # the offsets actually applied (one draw of phi(t))
    assert et.max() < 5.0 and er.max() < 1.0  # acceptance
    assert et.max() < 1e-6 and er.max() < 1e-6  # in fact exact: Eq. 4 inverted frame by frame
    eo = res.to_em_offsets()
    assert eo.num_sensors == 12 and eo.t_cov.shape == (12, 3, 3)
    assert res.sensors == sim.kit.sensor_names


def test_default_noise_figures(calib_motion, subject, body, record_property):
    sim, res = _run(calib_motion, subject, body, "default")
    et, er = _errors(res, sim.em_offsets)
    figures = {"translation_mm_max": float(et.max()), "translation_mm_mean": float(et.mean()),
               "rotation_deg_max": float(er.max()), "rotation_deg_mean": float(er.mean()),
               "per_sensor_translation_mm": [round(float(x), 3) for x in et],
               "per_sensor_rotation_deg": [round(float(x), 3) for x in er]}
    record_property("empose_offsets_default_noise", json.dumps(figures))
    print("EM-POSE offsets, default EM noise, 4 s at 120 Hz:", json.dumps(figures))
    # Zero-mean noise averages out over the sequence; these bounds are 3-5x the measured figures.
    assert et.max() < 5.0 and er.max() < 1.0
    # Dropped frames are excluded, not averaged in as NaN.
    counts = [int(sim[n].valid.sum()) for n in sim.kit.sensor_names]
    assert min(counts) < 4 * FPS  # the default noise drops frames (seed 5)...
    assert res.quality["frames"] == counts  # ...and exactly the valid ones are used


def test_offsets_feed_back_into_simulate(calib_motion, subject, body):
    sim, res = _run(calib_motion, subject, body, "none")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sim2 = simulate(calib_motion.slice(0, 60), "em12", body, seed=1, noise="none", offsets=res.to_em_offsets())
    assert sim2.em_offsets.num_sensors == 12


def test_translation_distribution_is_fitted():
    # supp. Sec. 2.2: a multivariate normal fitted to t(t).
    g = torch.Generator().manual_seed(0)
    T, S = 4000, 2
    cov = torch.tensor([[[4.0, 1.0, 0.0], [1.0, 2.0, 0.5], [0.0, 0.5, 1.0]]] * S, dtype=torch.float64) * 1e-6
    L = torch.linalg.cholesky(cov)
    mu = torch.tensor([[0.01, -0.02, 0.015], [0.0, 0.005, 0.02]], dtype=torch.float64)
    t_t = mu + (L @ torch.randn(T, S, 3, 1, generator=g, dtype=torch.float64)).squeeze(-1)
    R0 = axis_angle_to_matrix(torch.tensor([[0.1, 0.2, -0.3], [0.5, 0.0, 0.1]], dtype=torch.float64))
    R_t = R0 @ axis_angle_to_matrix(0.02 * torch.randn(T, S, 3, generator=g, dtype=torch.float64))
    res = fit_offsets(R_t, t_t)
    assert torch.allclose(res.translation, mu, atol=1e-4)
    assert torch.allclose(res.translation_cov, cov, atol=3e-7)
    assert geodesic_angle(res.rotation, R0).max() < math.radians(0.1)


def test_needs_ground_truth(calib_motion, body):
    sim = simulate(calib_motion.slice(0, 30), "em6", body, seed=0, noise="none")
    with pytest.raises(CalibrationError, match="ground_truth"):
        calibrate(sim_to_recording(sim), "empose-offsets", body=body)


def test_from_simulation_recording_and_subject_offsets(calib_motion, subject, body, tmp_path):
    # The recording type the rest of wearpose writes for simulations (float32 channels).
    from wearpose.calibration import CalibrationResult, store_calibration
    from wearpose.recording import Recording, load_recording

    sim = simulate(calib_motion, "em12", body, seed=5, noise="none", offsets=subject)
    rec = Recording.from_simulation(sim, calib_motion)
    res = calibrate(rec, "empose-offsets", body=body)
    truth = torch.tensor(rec.subject["offsets"]["translation_mean_m"], dtype=torch.float64)
    assert (res.translation - truth).norm(dim=-1).max() < 5e-4  # float32 channels: sub-millimetre
    assert torch.rad2deg(geodesic_angle(res.rotation, torch.tensor(rec.subject["offsets"]["rotation"]))).max() < 0.05
    stored = load_recording(store_calibration(rec, res).save(tmp_path / "calib.npz"))
    assert stored.subject["offsets"]["origin"].startswith("calibrated")
    assert "offsets_previous" in stored.subject
    back = CalibrationResult.from_dict(stored.meta["calibration"])
    assert torch.allclose(back.translation_cov, res.translation_cov)
