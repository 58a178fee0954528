"""EM-POSE's per-recording shape fit (wearpose.estimators.empose.shapefit): recovery of a
non-mean body from ideal sensors, the L_r guard, the off switch and the estimator option, on
synthetic motion with the tiny preset."""

from __future__ import annotations

import pytest
import torch

from wearpose.body import BodyModel
from wearpose.body.shapes import standing_height
from wearpose.errors import ConfigError
from wearpose.estimators import iter_frames
from wearpose.estimators.empose import EmposeEstimator
from wearpose.estimators.empose.data import recording_from_clip, simulate_clip
from wearpose.estimators.empose.model import encode_pose, sensor_features
from wearpose.estimators.empose.shapefit import fit_frames, fit_shape
from wearpose.evaluate.latency import apply_settings
from wearpose.geometry import axis_angle_to_matrix
from wearpose.motion import MotionSequence

from test_empose import synthetic_motion, tiny_cfg  # tests/estimators is on sys.path (pytest rootdir mode)

#: A wearer far from the mean body (about 1.87 m on the embedded asset, the mean is 1.69 m).
TALL = torch.tensor([1.6, -0.8, 0.5, 0.0, 0.3, -0.4, 0.0, 0.2, 0.0, -0.1])


def _clip(body: BodyModel, betas: torch.Tensor, T: int = 12, noise: str = "none") -> dict:
    m = synthetic_motion(3, T=T)
    m = MotionSequence(m.pose, betas.to(m.pose.dtype), m.trans, m.fps, m.meta)
    return simulate_clip(m, tiny_cfg(), body, seed=5, noise=noise)


def _learned_stand_in(clip: dict) -> tuple[torch.Tensor, torch.Tensor]:
    """A learned estimate's stand-in on the mean body: the true poses with the elbows and knees
    off by 0.15 rad (what a network trained on one body gets nearly right) and beta = 0."""
    pose = clip["pose"].clone()
    off = axis_angle_to_matrix(torch.tensor([0.15, 0.0, -0.1]))
    for j in (4, 5, 18, 19):
        pose[:, j] = off @ pose[:, j]
    return pose, torch.zeros(pose.shape[0], 10)


def _rec(kernel, pose: torch.Tensor, betas: torch.Tensor, clip: dict) -> torch.Tensor:  # noqa: ANN001
    ctx = kernel.forward(torch.cat([encode_pose(pose, "rot6d"), betas], -1), clip["position"], clip["orientation"],
                         clip["off_R"], clip["off_t"])
    return ctx["rec"]


def test_fit_recovers_the_standing_height_of_a_non_mean_body_from_ideal_sensors(body: BodyModel) -> None:
    """Ideal sensors (no noise) on a 1.87 m wearer, the fit started at the mean body (18 cm too
    short) and perturbed poses: the fitted body's standing height is within 1 cm of the wearer's.
    Why 1 cm: with ideal sensors the only errors left are the prior's pull towards the mean
    (w = 1e-3 against an L_r that is 0 at the truth) and the finite iterations; half of the
    acceptance target (2 cm median, issue 24) leaves room for the noise of real recordings, and
    the measured error here is a few millimetres."""
    est = EmposeEstimator(tiny_cfg(), body=body)
    kernel = est.sensors.lean()
    clip = _clip(body, TALL)
    pose, betas = _learned_stand_in(clip)
    rec = _rec(kernel, pose, betas, clip)
    fit = fit_shape(kernel, pose, betas, rec, clip["position"], clip["orientation"], clip["off_R"], clip["off_t"],
                    steps=80, prior=1e-3)
    h_true = float(standing_height(body, TALL))
    assert abs(float(standing_height(body, torch.zeros(10))) - h_true) > 0.1  # the start is far off
    assert fit.accepted
    assert abs(float(standing_height(body, fit.betas)) - h_true) < 0.01
    assert float(fit.rec_after.sum()) < 0.05 * float(fit.rec_before.sum())
    # The fitted poses are rotations and keep the learned root (L_r does not see it).
    eye = torch.eye(3).expand(pose.shape[0], 24, 3, 3)
    assert torch.allclose(fit.local_rot.transpose(-1, -2) @ fit.local_rot, eye, atol=1e-5)
    assert torch.equal(fit.local_rot[:, 0], pose[:, 0])


@pytest.mark.budget(30)  # about 3 s on an idle core; 27 s measured on the shared machine under two trainings
def test_fit_never_increases_the_summed_rec(body: BodyModel) -> None:
    """From the stand-in (the fit lowers L_r) and from the truth with a prior so strong that its
    optimum is a worse body: then the guard keeps the learned shape and L_r as they were."""
    est = EmposeEstimator(tiny_cfg(), body=body)
    kernel = est.sensors.lean()
    clip = _clip(body, TALL, noise="default")
    pose, betas = _learned_stand_in(clip)
    for steps in (1, 4):
        rec = _rec(kernel, pose, betas, clip)
        fit = fit_shape(kernel, pose, betas, rec, clip["position"], clip["orientation"], clip["off_R"],
                        clip["off_t"], steps=steps, prior=1e-3)
        assert float(fit.rec_after.sum()) <= float(rec.sum())
        assert torch.equal(fit.rec_before, rec)
    T = pose.shape[0]
    truth = TALL.expand(T, 10)
    rec = _rec(kernel, clip["pose"], truth, clip)
    fit = fit_shape(kernel, clip["pose"], truth, rec, clip["position"], clip["orientation"], clip["off_R"],
                    clip["off_t"], steps=3, prior=100.0)
    assert not fit.accepted
    assert torch.equal(fit.betas, TALL) and torch.equal(fit.rec_after, rec) and torch.equal(fit.local_rot, clip["pose"])


def test_fit_frames_spread_or_first() -> None:
    valid = torch.tensor([False, True, True, False, True, True, True, True, False, True])
    assert fit_frames(valid, 3).tolist() == [1, 5, 9]
    assert fit_frames(valid, 3, spread=False).tolist() == [1, 2, 4]
    assert fit_frames(valid, 20).tolist() == [1, 2, 4, 5, 6, 7, 9]
    assert fit_frames(torch.zeros(4, dtype=torch.bool), 3).numel() == 0


@pytest.mark.budget(30)  # 0.2 s on an idle core; 10 s measured on the shared machine under two trainings
def test_estimate_with_shape_fit_off_is_the_network_and_on_changes_only_the_shape(body: BodyModel) -> None:
    """shape_fit_frames = 0: the output is the network's own (poses of its last LGD iteration,
    the mean of its per-frame shapes), bit for bit. On: the same poses, the fitted shape (10,)
    float32, every frame's L_r with that shape, the fit's summed L_r not above the learned one;
    the online step fits once at the N-th valid frame and returns that
    shape from then on."""
    torch.manual_seed(0)
    est = EmposeEstimator(tiny_cfg(), body=body)
    clip = _clip(body, TALL, T=16, noise="default")
    rec = recording_from_clip(clip, est.config)
    base = est.estimate(rec)
    assert "shape_fit" not in base.extras and "rec_loss_learned" not in base.extras
    p, R, valid = est._measurements(rec)
    T, S = p.shape[:2]
    offR, offt = est._offsets_from(rec)  # the recording's calibration (float32 of the simulated offsets)
    x = sensor_features(p, R)
    with torch.no_grad():  # as estimate runs (the LSTM takes another kernel in grad mode)
        last = est.model.refine(est.model.initial(x[None])[0][0], x, p, R, offR.expand(T, S, 3, 3),
                                offt.expand(T, S, 3), est.sensors, train=False)[-1]
    ok = valid.all(1)
    assert torch.equal(base.local_rot, last["local_rot"]) and torch.equal(base.extras["rec_loss"], last["rec"])
    assert torch.equal(base.betas, last["betas"][ok].mean(0))

    est.set_shape_fit_frames(8)
    fit = est.estimate(rec)
    assert torch.equal(fit.local_rot, base.local_rot)
    assert fit.betas.shape == (10,) and fit.betas.dtype == torch.float32
    assert fit.extras["rec_loss"].shape == (T,) and fit.extras["rec_loss"].dtype == torch.float32
    assert torch.equal(fit.extras["rec_loss_learned"], base.extras["rec_loss"])
    summary = fit.extras["shape_fit"]
    assert summary["frames"] == 8 and summary["accepted"] is True
    assert summary["rec_after"] <= summary["rec_before"]
    assert not torch.equal(fit.betas, base.betas)
    again = est._rec(fit.local_rot, fit.betas.expand(T, 10), p, R, offR, offt)
    assert torch.allclose(again, fit.extras["rec_loss"])

    est.reset()
    est.set_offsets(clip["off_R"], clip["off_t"])
    frames = [est.step(f) for f in iter_frames(rec, est.sensor_names)]
    n_valid = ok.cumsum(0)
    assert [f.extras["shape_fitted"] for f in frames] == (n_valid >= 8).tolist()
    after = [f.betas for f, done in zip(frames, (n_valid >= 8).tolist()) if done]
    assert all(torch.equal(b, after[0]) for b in after) and after[0].dtype == torch.float32
    assert all(f.extras["rec_loss_learned"] >= 0.0 for f in frames)


def test_shape_fit_settings_are_checked_and_reachable_through_set(body: BodyModel) -> None:
    est = EmposeEstimator(tiny_cfg(), body=body)
    apply_settings(est, {"shape_fit_frames": "12", "shape_fit_steps": "5", "shape_fit_prior": "0.01"})
    assert (est.config.shape_fit_frames, est.config.shape_fit_steps, est.config.shape_fit_prior) == (12, 5, 0.01)
    assert est.model.cfg is est.config
    for bad in (dict(shape_fit_frames=-1), dict(shape_fit_frames=True), dict(shape_fit_steps=2.5),
                dict(shape_fit_prior=-1.0)):
        with pytest.raises(ConfigError, match="shape_fit"):
            tiny_cfg(**bad)
