"""EM-POSE's measurement-consistency refinement (wearpose.estimators.empose.refine): the batched
L-BFGS, the gate, and the estimator option, on synthetic motion with the tiny preset."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch

from wearpose.body import BodyModel
from wearpose.errors import ConfigError
from wearpose.estimators import iter_frames
from wearpose.estimators.empose import EmposeConfig, EmposeEstimator
from wearpose.estimators.empose.data import recording_from_clip, simulate_clip
from wearpose.estimators.empose.refine import calibrate_threshold, lbfgs, refine_frames
from wearpose.evaluate.latency import apply_settings
from wearpose.geometry import axis_angle_to_matrix

from test_empose import FakeStore, synthetic_motion, tiny_cfg  # tests/estimators is on sys.path (pytest rootdir mode)


def _clip(body: BodyModel, T: int = 12, noise: str = "none") -> dict:
    return simulate_clip(synthetic_motion(3, T=T), tiny_cfg(), body, seed=5, noise=noise)


def test_lbfgs_never_increases_f_and_converges_on_quadratics() -> None:
    """Independent ill-conditioned quadratics (condition 100) per row: f is monotone per row and
    30 iterations bring every row to 1e-6 of its start (torch.optim.LBFGS, history 5, needs
    about as many on the first row)."""
    g = torch.Generator().manual_seed(0)
    scale = torch.logspace(0, 2, 8, dtype=torch.float64)
    target = torch.randn(5, 8, generator=g, dtype=torch.float64)

    def fg(x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        d = x - target
        return (scale * d * d).sum(-1), 2 * scale * d

    x0 = torch.zeros(5, 8, dtype=torch.float64)
    f0 = fg(x0)[0]
    prev = f0
    for k in (1, 2, 4, 8):
        _, f = lbfgs(fg, x0, k)
        assert bool((f <= prev + 1e-12).all())
        prev = f
    _, f = lbfgs(fg, x0, 30)
    assert bool((f < 1e-6 * f0).all())


def test_refinement_lowers_rec_on_a_perturbed_frame_and_leaves_the_others_untouched(body: BodyModel) -> None:
    """Noise-free measurements of the true pose; frame 4's elbows and knees rotated 0.5 rad. Only
    frame 4 is over the gate: its L_r drops by far and its joints move towards the truth; every
    other frame comes back bit for bit."""
    est = EmposeEstimator(tiny_cfg(), body=body)
    kernel = est.sensors.lean()
    clip = _clip(body)
    T = clip["pose"].shape[0]
    pose = clip["pose"].clone()
    bad = axis_angle_to_matrix(torch.tensor([0.5, 0.0, 0.3]))
    for j in (4, 5, 18, 19):  # knees, elbows
        pose[4, j] = bad @ pose[4, j]
    betas = clip["betas"].reshape(1, 10).expand(T, 10).contiguous()
    from wearpose.estimators.empose.model import encode_pose  # the 6D of the pose, as Omega carries it

    omega = torch.cat([encode_pose(pose, "rot6d"), betas], -1)
    ctx = kernel.forward(omega, clip["position"], clip["orientation"], clip["off_R"], clip["off_t"])
    rec = ctx["rec"]
    others = torch.cat([rec[:4], rec[5:]])
    assert float(rec[4]) > 10 * float(others.max())  # the perturbation is what the gate sees
    thr = float(others.max()) * 2
    out = refine_frames(kernel, ctx["local_rot"], betas, rec, clip["position"], clip["orientation"], clip["off_R"],
                        clip["off_t"], steps=10, threshold=thr, weight=0.01)
    assert out.gated.tolist() == [t == 4 for t in range(T)]
    assert float(out.rec[4]) < 0.2 * float(rec[4])
    keep = torch.arange(T) != 4
    assert torch.equal(out.local_rot[keep], ctx["local_rot"][keep]) and torch.equal(out.rec[keep], rec[keep])
    joints = lambda R: body(R, clip["betas"], None, return_vertices=False).joints[0]  # noqa: E731
    truth = joints(clip["pose"][4:5])
    before = (joints(ctx["local_rot"][4:5]) - truth).norm(dim=-1).mean()
    after = (joints(out.local_rot[4:5]) - truth).norm(dim=-1).mean()
    assert float(after) < 0.5 * float(before)
    # L_r reported for the refined frame is the refined pose's own.
    again = kernel.forward(torch.cat([encode_pose(out.local_rot[4:5], "rot6d"), betas[4:5]], -1),
                           clip["position"][4:5], clip["orientation"][4:5], clip["off_R"], clip["off_t"])
    assert torch.allclose(again["rec"], out.rec[4:5], rtol=1e-4, atol=1e-7)


def test_estimate_with_refinement_off_is_unchanged_and_on_keeps_ungated_frames_bitwise(body: BodyModel) -> None:
    """refine_steps = 0 gives the model's output exactly; with refinement on, frames under the
    gate equal it bit for bit, the gated ones have L_r no higher, and the extras have the
    documented shapes and dtypes; the online step gives the same as the offline estimate."""
    torch.manual_seed(0)
    est = EmposeEstimator(tiny_cfg(), body=body)
    clip = _clip(body, T=16, noise="default")
    rec = recording_from_clip(clip, est.config)
    base = est.estimate(rec)
    assert "refined" not in base.extras and "rec_loss_learned" not in base.extras
    est.set_refine_steps(0)
    est.set_refine_threshold(0.0)
    same = est.estimate(rec)
    assert torch.equal(same.local_rot, base.local_rot) and torch.equal(same.extras["rec_loss"], base.extras["rec_loss"])

    srt = base.extras["rec_loss"].sort().values
    thr = float(srt[7] + srt[8]) / 2  # half the frames, the gate away from any frame's L_r (online = offline to ~1e-6)
    est.set_refine_threshold(thr)
    est.set_refine_steps(3)
    ref = est.estimate(rec)
    T = base.local_rot.shape[0]
    gated = ref.extras["refined"]
    assert gated.dtype == torch.bool and gated.shape == (T,)
    assert torch.equal(gated, base.extras["rec_loss"] > thr) and 0 < int(gated.sum()) < T
    assert ref.local_rot.shape == (T, 24, 3, 3) and ref.local_rot.dtype == torch.float32
    assert ref.extras["rec_loss"].shape == (T,) and ref.extras["rec_loss"].dtype == torch.float32
    assert torch.equal(ref.extras["rec_loss_learned"], base.extras["rec_loss"])
    assert torch.equal(ref.local_rot[~gated], base.local_rot[~gated])
    assert bool((ref.extras["rec_loss"][gated] <= base.extras["rec_loss"][gated]).all())
    assert not torch.equal(ref.local_rot[gated], base.local_rot[gated])
    assert torch.equal(ref.betas, base.betas)  # the shape is not refined
    eye = torch.eye(3).expand(int(gated.sum()), 24, 3, 3)
    assert torch.allclose(ref.local_rot[gated].transpose(-1, -2) @ ref.local_rot[gated], eye, atol=1e-5)

    est.reset()
    est.set_offsets(clip["off_R"], clip["off_t"])
    frames = [est.step(f) for f in iter_frames(rec, est.sensor_names)]
    assert [f.extras["refined"] for f in frames] == gated.tolist()
    assert torch.allclose(torch.stack([f.local_rot for f in frames]), ref.local_rot, atol=1e-4)


def test_settings_are_checked_and_reachable_through_set(body: BodyModel) -> None:
    est = EmposeEstimator(tiny_cfg(), body=body)
    clip = _clip(body, T=6)
    rec = recording_from_clip(clip, est.config)
    apply_settings(est, {"refine_steps": "4", "refine_threshold": "0.05", "refine_weight": "0.1"})
    assert (est.config.refine_steps, est.config.refine_threshold, est.config.refine_weight) == (4, 0.05, 0.1)
    assert est.model.cfg is est.config
    est.set_refine_threshold(0.0)
    est._set_config(refine_threshold=None)
    with pytest.raises(ConfigError, match="refine_threshold"):
        est.estimate(rec)  # on without a calibrated gate
    for bad in (dict(refine_steps=-1), dict(refine_steps=True), dict(refine_threshold=-1.0), dict(refine_weight=-0.5)):
        with pytest.raises(ConfigError, match="refine_"):
            EmposeConfig.preset("tiny", 12).override(**bad)


def test_calibrate_threshold_is_the_percentile_of_val_rec_and_leaves_the_setting(tmp_path: Path, body: BodyModel) -> None:
    torch.manual_seed(0)
    est = EmposeEstimator(tiny_cfg(), body=body)
    est.set_refine_threshold(1.0)
    est.set_refine_steps(2)
    store = FakeStore(tmp_path, {"val": 2})
    cal = calibrate_threshold(est, store, clips=2, percentile=90.0)
    assert est.config.refine_steps == 2 and est.config.refine_threshold == 1.0
    est.set_refine_steps(0)
    from wearpose.estimators.empose.evaluate import simulate_eval_clip  # the evaluation's simulation

    recs = []
    for cid in store.clips("val"):
        track = est.estimate(recording_from_clip(simulate_eval_clip(store.load(cid), est, cid, 0), est.config))
        recs.append(track.extras["rec_loss"][track.valid].double())
    x = torch.cat(recs)
    assert cal["frames"] == x.numel() and cal["clips"] == 2 and cal["split"] == "val"
    assert cal["threshold"] == pytest.approx(float(torch.quantile(x, 0.9)))
    with pytest.raises(ConfigError, match="percentile"):
        calibrate_threshold(est, store, percentile=100.0)
