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
from wearpose.estimators.empose import refine
from wearpose.estimators.empose.model import encode_pose
from wearpose.estimators.empose.refine import (POSE_DIM, calibrate_threshold, gauss_newton, lbfgs, refine_frames,
                                             residual_jacobian)
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
                        clip["off_t"], steps=10, threshold=thr, weight=0.01, solver="lbfgs")
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


@pytest.mark.parametrize("solver", ["lbfgs", "gn"])
def test_estimate_with_refinement_off_is_unchanged_and_on_keeps_ungated_frames_bitwise(body: BodyModel,
                                                                                       solver: str) -> None:
    """refine_steps = 0 gives the model's output exactly; with refinement on (either solver),
    frames under the gate equal it bit for bit, the gated ones have L_r no higher, and the extras
    have the documented shapes and dtypes; the online step gives the same as the offline estimate."""
    torch.manual_seed(0)
    est = EmposeEstimator(tiny_cfg(), body=body)
    est.set_refine_solver(solver)
    # An untrained network leaves L_r ~17 and 3 iterations take it to ~0.003: with the default
    # prior weight (1e-3) Levenberg-Marquardt's accept/reject can flip on float32 rounding between a
    # batched and a single-frame solve; the prior of 0.01 keeps the problem conditioned enough for
    # online and offline to agree (the property under test: one refinement in both paths).
    est.set_refine_weight(0.01)
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
    # Gauss-Newton takes these frames' L_r from about 17 to 0.003-0.09 in 3 float32 solves, where a
    # batched and a single-frame solve differ in summation order: agreement to 1e-3, not 1e-4.
    assert torch.allclose(torch.stack([f.local_rot for f in frames]), ref.local_rot, atol=1e-4 if solver == "lbfgs" else 1e-3)


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
    apply_settings(est, {"refine_solver": "gn"})
    assert est.config.refine_solver == "gn"
    for bad in (dict(refine_steps=-1), dict(refine_steps=True), dict(refine_threshold=-1.0), dict(refine_weight=-0.5),
                dict(refine_solver="newton")):
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


def _perturbed(body: BodyModel, dtype: torch.dtype = torch.float32) -> tuple:
    """A synthetic clip's noise-free measurements and its true 6D pose, every frame's knees and
    elbows rotated 0.5 rad away from the truth (the start of a refinement)."""
    clip = _clip(body, T=5)
    T = clip["pose"].shape[0]
    bad = axis_angle_to_matrix(torch.tensor([0.5, 0.0, 0.3]))
    pose = clip["pose"].clone()
    for j in (4, 5, 18, 19):
        pose[:, j] = bad @ pose[:, j]
    betas = clip["betas"].reshape(1, 10).expand(T, 10).contiguous()
    c = lambda t: t.to(dtype)  # noqa: E731
    return (c(encode_pose(pose, "rot6d")), c(encode_pose(clip["pose"], "rot6d")), c(betas), c(clip["position"]),
            c(clip["orientation"]), c(clip["off_R"]), c(clip["off_t"]), clip)


def test_residual_jacobian_equals_autograd_in_float64(monkeypatch: pytest.MonkeyPatch) -> None:
    """The Jacobian read off the closed-form backward equals autograd's through the kernel's
    forward (float64, 1e-8), with unequal L_r weights, also in chunks; and ||rho||^2 is L_r."""
    body = BodyModel(dtype=torch.float64)
    est = EmposeEstimator(tiny_cfg(), body=body)
    kernel = est.sensors.lean()
    u, _, b, mp, mR, oR, ot, _ = _perturbed(body, torch.float64)
    u, b, mp, mR = u[:2], b[:2], mp[:2], mR[:2]
    w = (1.0, 0.3)
    ctx = kernel.forward(torch.cat([u, b], -1), mp, mR, oR, ot)
    rho, J = residual_jacobian(kernel, ctx, w)
    S = mp.shape[1]
    assert rho.shape == (2, 12 * S) and J.shape == (2, 12 * S, POSE_DIM)
    wrec = kernel.forward(torch.cat([u, b], -1), mp, mR, oR, ot, w)["rec"]
    assert torch.allclose((rho ** 2).sum(-1), wrec, rtol=1e-10)

    def res(x: torch.Tensor) -> torch.Tensor:
        c = kernel.forward(torch.cat([x, b], -1), mp, mR, oR, ot)
        return torch.cat([w[0] ** 0.5 * (c["p_hat"] - mp).reshape(2, -1),
                          w[1] ** 0.5 * (c["R_hat"] - mR).reshape(2, -1)], -1)

    Jad = torch.autograd.functional.jacobian(res, u)  # (2, R, 2, 120): frames are independent
    for n in range(2):
        assert torch.allclose(J[n], Jad[n, :, n], atol=1e-8)
        assert float(Jad[n, :, 1 - n].abs().max()) == 0.0
    monkeypatch.setattr(refine, "JACOBIAN_CHUNK", 1)  # the chunked path (one frame per call): the same values
    rho_c, J_c = refine._jacobian_chunked(kernel, ctx, w)
    assert torch.allclose(rho_c, rho, atol=1e-12) and torch.allclose(J_c, J, atol=1e-12)


def test_gauss_newton_is_monotone_and_beats_lbfgs_at_equal_iterations(body: BodyModel) -> None:
    """Noise-free measurements, knees and elbows 0.5 rad off in every frame: f never rises with
    more iterations, 5 Gauss-Newton iterations bring L_r below 1 % of its start on every frame
    and below what 5 L-BFGS iterations reach, and the joints land within 1 cm of the truth."""
    est = EmposeEstimator(tiny_cfg(), body=body)
    kernel = est.sensors.lean()
    u0, u_true, b, mp, mR, oR, ot, clip = _perturbed(body)
    f0 = kernel.forward(torch.cat([u0, b], -1), mp, mR, oR, ot)["rec"]
    prev = f0
    for k in (1, 2, 3, 5):
        u, f, _ = gauss_newton(kernel, u0, b, mp, mR, oR, ot, steps=k, weight=1e-4)
        assert bool((f <= prev + 1e-7).all())
        prev = f
    rec_gn = kernel.forward(torch.cat([u, b], -1), mp, mR, oR, ot)["rec"]
    assert bool((rec_gn < 0.01 * f0).all())
    # The context it returns is the forward at its u, bit for bit: after steps every frame kept,
    # some kept (started at the noise-free truth, where rounding decides), and none kept (a
    # damping that makes every step vanish: u comes back as it went in).
    for start, damping in ((u0, 1e-3), (u_true, 1e-3), (u0, 1e30)):
        v, _, ctx = gauss_newton(kernel, start, b, mp, mR, oR, ot, steps=2, weight=1e-4, damping=damping)
        fresh = kernel.forward(torch.cat([v, b], -1), mp, mR, oR, ot)
        assert all(torch.equal(a, c) for a, c in zip(ctx["_"], fresh["_"])) and torch.equal(ctx["rec"], fresh["rec"])
    assert torch.equal(v, u0)

    def fg(x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        ctx = kernel.forward(torch.cat([x, b], -1), mp, mR, oR, ot)
        return ctx["rec"] + 1e-4 * ((x - u0) ** 2).sum(-1), kernel.backward(ctx)[:, :POSE_DIM] + 2e-4 * (x - u0)

    u_lb, _ = lbfgs(fg, u0, 5)
    rec_lb = kernel.forward(torch.cat([u_lb, b], -1), mp, mR, oR, ot)["rec"]
    assert bool((rec_gn < rec_lb).all())
    joints = lambda x: kernel.forward(torch.cat([x, b], -1), mp, mR, oR, ot)["joints"]  # noqa: E731
    err = (joints(u) - joints(u_true)).norm(dim=-1)
    assert float(err.max()) < 0.01, float(err.max())


def test_miscalibrate_moves_each_offset_by_exactly_the_stated_error(body: BodyModel) -> None:
    """Every sensor's rotation offset turns by the stated angle and its translation moves by the
    stated distance; the measurements and the rest of the subject stay; the same generator seed
    gives the same error."""
    import math

    import numpy as np

    from wearpose.estimators.empose.evaluate import miscalibrate

    est = EmposeEstimator(tiny_cfg(), body=body)
    rec = recording_from_clip(_clip(body), est.config)
    out = miscalibrate(rec, 2.0, 5.0, torch.Generator().manual_seed(1))
    a, b = rec.subject["offsets"], out.subject["offsets"]
    R0, R1 = (torch.tensor(np.asarray(x["rotation"], dtype=np.float64)) for x in (a, b))
    cos = ((R0.transpose(-1, -2) @ R1).diagonal(dim1=-2, dim2=-1).sum(-1) - 1) / 2
    assert torch.allclose(torch.rad2deg(torch.acos(cos.clamp(-1, 1))), torch.full_like(cos, 2.0), atol=1e-3)
    dt = (torch.tensor(np.asarray(b["translation_mean_m"], dtype=np.float64))
          - torch.tensor(np.asarray(a["translation_mean_m"], dtype=np.float64)))
    assert torch.allclose(dt.norm(dim=-1) * 1000, torch.full((dt.shape[0],), 5.0, dtype=torch.float64), atol=1e-6)
    assert all(np.array_equal(x.position, y.position) and np.array_equal(x.orientation, y.orientation)
               for x, y in zip(out.sensors, rec.sensors, strict=True))  # the measurements stay
    assert rec.subject["offsets"] is a  # the input recording is not changed
    again = miscalibrate(rec, 2.0, 5.0, torch.Generator().manual_seed(1)).subject["offsets"]
    assert again["rotation"] == b["rotation"] and not math.isnan(float(dt.sum()))


def test_evaluation_with_calibration_error_gives_the_models_the_wrong_offsets(tmp_path: Path, body: BodyModel) -> None:
    """(0, 0) is the plain evaluation; a calibration error changes what the model reads, and is
    recorded in the result."""
    from wearpose.estimators.empose.evaluate import evaluate_models

    torch.manual_seed(0)
    est = EmposeEstimator(tiny_cfg(), body=body)
    store = FakeStore(tmp_path, {"test": 1})
    plain = evaluate_models({"m": est}, "test", store=store, noise="none")
    zero = evaluate_models({"m": est}, "test", store=store, noise="none", calibration_error=(0.0, 0.0))
    off = evaluate_models({"m": est}, "test", store=store, noise="none", calibration_error=(5.0, 10.0))
    assert zero["models"]["m"]["mpjpe_mm"] == plain["models"]["m"]["mpjpe_mm"]
    assert off["models"]["m"]["mpjpe_mm"] != plain["models"]["m"]["mpjpe_mm"]
    assert off["calibration_error"] == {"deg": 5.0, "mm": 10.0}


@pytest.mark.parametrize("solver", ["lbfgs", "gn"])
def test_refined_root_is_the_one_the_source_site_gives(body: BodyModel, solver: str) -> None:
    """L_r cannot see the root, so a refined frame's root comes from the source's own skin site:
    with the start's root turned 10 degrees off, the output's source site frame is the identity,
    its root equals the true one (noise-free measurements, the true rest of the pose), and L_r is
    the same as with the turned root."""
    est = EmposeEstimator(tiny_cfg(), body=body)
    kernel = est.sensors.lean()
    clip = _clip(body, T=4)
    T = clip["pose"].shape[0]
    pose = clip["pose"].clone()
    pose[:, 0] = axis_angle_to_matrix(torch.tensor([0.0, 0.0, 0.1745])) @ pose[:, 0]
    betas = clip["betas"].reshape(1, 10).expand(T, 10).contiguous()
    omega = torch.cat([encode_pose(pose, "rot6d"), betas], -1)
    ctx = kernel.forward(omega, clip["position"], clip["orientation"], clip["off_R"], clip["off_t"])
    out = refine_frames(kernel, ctx["local_rot"], betas, ctx["rec"], clip["position"], clip["orientation"],
                        clip["off_R"], clip["off_t"], steps=2, threshold=0.0, weight=0.01, solver=solver)
    assert bool(out.gated.all())
    again = kernel.forward(torch.cat([encode_pose(out.local_rot, "rot6d"), betas], -1), clip["position"],
                           clip["orientation"], clip["off_R"], clip["off_t"])
    eye = torch.eye(3).expand(T, 3, 3)
    assert torch.allclose(again["R_src"], eye, atol=1e-5)
    assert torch.allclose(out.local_rot[:, 0], clip["pose"][:, 0], atol=1e-4)
    assert torch.allclose(ctx["rec"], kernel.forward(torch.cat([encode_pose(clip["pose"], "rot6d"), betas], -1),
                                                     clip["position"], clip["orientation"], clip["off_R"],
                                                     clip["off_t"])["rec"], atol=1e-6)  # blind to the root


def test_a_checkpoint_does_not_restore_inference_settings(tmp_path: Path, body: BodyModel) -> None:
    """The refinement and shape-fit settings a checkpoint was saved with are not the network's:
    loading it gives today's defaults (docs: INFERENCE_FIELDS), the trained fields come back."""
    from wearpose.estimators.empose.baselines import load_any
    from wearpose.estimators.empose.config import INFERENCE_FIELDS

    cfg = tiny_cfg().override(refine_steps=7, refine_threshold=0.3, refine_weight=0.5, refine_solver="lbfgs",
                              shape_fit_frames=5, shape_fit_steps=9, shape_fit_prior=0.2)
    est = EmposeEstimator(cfg, body=body)
    back = load_any(est.save(tmp_path / "m.pt"), body=body)
    fresh = EmposeConfig()
    for key in INFERENCE_FIELDS:
        assert getattr(back.config, key) == getattr(fresh, key), key
    assert (back.config.hidden, back.config.iterations, back.config.sensors) == (cfg.hidden, cfg.iterations, cfg.sensors)
    assert (fresh.refine_steps, fresh.refine_solver, fresh.refine_threshold) == (0, "gn", 0.0)  # off; on = every frame


def test_refinement_without_offsets_is_refused_naming_the_fix(body: BodyModel) -> None:
    """Identity offsets would make the refinement explain the mounting with the joints: a
    recording (or an online stream) without offsets is refused with the calibration to run; with
    the refinement off it still runs (with the documented warning)."""
    import dataclasses

    est = EmposeEstimator(tiny_cfg(), body=body)
    rec = recording_from_clip(_clip(body, T=6), est.config)
    bare = dataclasses.replace(rec, subject={k: v for k, v in rec.subject.items() if k != "offsets"})
    with pytest.warns(UserWarning, match="no subject offsets"):
        est.estimate(bare)
    est.set_refine_steps(3)
    with pytest.raises(ConfigError, match="empose-offsets"):
        est.estimate(bare)
    est.reset()
    with pytest.raises(ConfigError, match="set_offsets"):
        est.step(next(iter(iter_frames(rec, est.sensor_names))))
    est.reset()
    est.set_offsets(torch.eye(3).expand(len(est.sensor_names), 3, 3), torch.zeros(len(est.sensor_names), 3))
    assert est.step(next(iter(iter_frames(rec, est.sensor_names)))).extras["refined"]  # given offsets: it runs


def _angle(A: torch.Tensor, B: torch.Tensor) -> torch.Tensor:
    """Geodesic angle (rad) between rotations ``(..., 3, 3)``."""
    M = A.transpose(-1, -2) @ B
    return torch.acos(((M.diagonal(dim1=-2, dim2=-1).sum(-1) - 1) / 2).clamp(-1, 1))


def test_recording_turn_finds_a_constant_offset_of_the_learned_pose(body: BodyModel) -> None:
    """Noise-free measurements; the "learned" pose is the truth with the knees and elbows turned by
    a constant 0.3 rad in their own frames. The prior-free solve finds the truth, so the turn is
    that offset undone on those joints (within 0.01 rad), the identity on the others, the turned
    pose is the truth there, and summing chunk by chunk is the same as at once."""
    from wearpose.estimators.empose.model import PRED_JOINTS

    est = EmposeEstimator(tiny_cfg(), body=body)
    kernel = est.sensors.lean()
    clip = _clip(body, T=8)
    T = clip["pose"].shape[0]
    off = axis_angle_to_matrix(torch.tensor([0.3, -0.1, 0.2]))
    moved = (4, 5, 18, 19)  # knees, elbows
    learned = clip["pose"].clone()
    learned[:, list(moved)] = learned[:, list(moved)] @ off
    betas = clip["betas"].reshape(1, 10).expand(T, 10).contiguous()
    args = (clip["position"], clip["orientation"], clip["off_R"], clip["off_t"])
    whole = refine.turn_sums(kernel, learned, betas, *args, steps=8)
    turn = refine.recording_turn([whole])
    assert turn.shape == (len(PRED_JOINTS), 3, 3) and turn.dtype == torch.float64
    for i, j in enumerate(PRED_JOINTS):
        if j == 0:
            continue  # the root: L_r cannot see it, the source sets it
        want = off.T if j in moved else torch.eye(3)
        assert float(_angle(turn[i].float(), want)) < 0.01, (j, float(_angle(turn[i].float(), want)))
    fixed = refine.turned(learned, turn)
    assert float(_angle(fixed[:, list(moved)], clip["pose"][:, list(moved)]).max()) < 0.01
    halves = [refine.turn_sums(kernel, learned[s], betas[s], *(a[s] for a in args[:2]), *args[2:], steps=8)
              for s in (slice(0, 3), slice(3, T))]
    assert torch.allclose(refine.recording_turn(halves), turn, atol=1e-5)


def test_prior_centred_on_the_recording_runs_offline_and_is_refused_online(body: BodyModel) -> None:
    """``refine_centre="recording"``: reachable through ``--set``, checked; offline it refines every
    frame to another answer than the default centre's; an online step (a stream's hello) is
    refused before the first frame, naming both ways out."""
    est = EmposeEstimator(tiny_cfg(), body=body)
    clip = _clip(body, T=10, noise="default")
    rec = recording_from_clip(clip, est.config)
    apply_settings(est, {"refine_steps": "3", "refine_centre": "recording"})
    assert est.config.refine_centre == "recording"
    track = est.estimate(rec)
    T = clip["pose"].shape[0]
    assert track.local_rot.shape == (T, 24, 3, 3) and bool(track.extras["refined"].all())
    assert bool(torch.isfinite(track.extras["rec_loss"]).all())
    est.set_refine_centre("learned")
    plain = est.estimate(rec)
    assert not torch.equal(plain.local_rot, track.local_rot)  # a different prior, a different answer
    est.set_refine_centre("recording")
    with pytest.raises(ConfigError, match="refine_centre_frames=1"):
        est.set_offsets(clip["off_R"], clip["off_t"])
    est.reset()
    with pytest.raises(ConfigError, match="offline"):
        est.step(next(iter(iter_frames(rec, est.sensor_names))))
    with pytest.raises(ConfigError, match="refine_centre"):
        EmposeConfig.preset("tiny", 12).override(refine_centre="median")
    for bad in (-1, True, 2.5):
        with pytest.raises(ConfigError, match="refine_centre_frames"):
            EmposeConfig.preset("tiny", 12).override(refine_centre_frames=bad)


def test_recording_centre_on_the_first_frames_is_the_same_offline_and_online(body: BodyModel) -> None:
    """``refine_centre_frames = n``: the turn comes from the first n valid frames (not the whole
    recording's) and is used from the n-th on, online and offline alike: online each of the first
    n valid frames adds its solve, frames before the n-th keep the learned centre (the plain
    refinement's answer, offline too), and every step gives what the offline estimate gives (so
    later frames never changed the offline turn); a recording with fewer than n valid frames is
    never turned."""
    est = EmposeEstimator(tiny_cfg(), body=body)
    clip = _clip(body, T=14, noise="default")
    rec = recording_from_clip(clip, est.config)
    ok = clip["valid"].all(1)
    n = 5
    # A strong prior keeps the refined pose at its centre, so the comparisons below see the turn
    # (this untrained model's refinement can turn the traced step's 1e-5 rounding into 0.2 on a frame).
    apply_settings(est, {"refine_steps": "3", "refine_centre": "recording", "refine_centre_frames": str(n),
                         "refine_weight": "10"})
    first = est.estimate(rec)
    est.set_refine_centre_frames(0)
    assert not torch.equal(first.local_rot, est.estimate(rec).local_rot)  # n frames, not the whole recording
    est.set_refine_centre("learned")
    plain = est.estimate(rec)
    apply_settings(est, {"refine_centre": "recording", "refine_centre_frames": str(n)})
    est.set_offsets(clip["off_R"], clip["off_t"])
    online = [est.step(f) for f in iter_frames(rec, est.sensor_names)]
    turned_at = (ok.cumsum(0) >= n).tolist()
    assert [f.extras["centre_turned"] for f in online] == turned_at
    assert [f.extras["centre_measured"] for f in online] == (ok & (ok.cumsum(0) <= n)).tolist()
    rot = torch.stack([f.local_rot for f in online])
    k = turned_at.index(True)
    assert torch.equal(first.local_rot[:k], plain.local_rot[:k])  # offline: not turned before the n-th either
    assert torch.allclose(rot[:k], plain.local_rot[:k], atol=1e-2)  # measured: 7e-7
    assert torch.allclose(rot[k:], first.local_rot[k:], atol=1e-2)  # measured: 1.3e-3
    assert float((rot[k:] - plain.local_rot[k:]).abs().amax()) > 0.2  # the turn changed the answer: 0.47
    short = recording_from_clip(_clip(body, T=3, noise="none"), est.config)  # fewer than n valid frames
    no_turn = est.estimate(short)
    est.set_refine_centre("learned")
    assert torch.equal(no_turn.local_rot, est.estimate(short).local_rot)  # as a stream this short: never turned


def test_recording_centre_renewed_every_k_frames_is_the_same_offline_and_online(body: BodyModel) -> None:
    """``refine_centre_every = k``: after the n-th valid frame every k-th adds its solve and the
    turn is renewed from every measured frame so far, online and offline alike; up to the first
    renewal the answer is the fixed turn's; with ``refine_centre_frames=0`` it is refused
    (nothing to add to), and the setting is checked."""
    est = EmposeEstimator(tiny_cfg(), body=body)
    clip = _clip(body, T=13, noise="default")
    rec = recording_from_clip(clip, est.config)
    ok = clip["valid"].all(1)
    n, k = 4, 3
    # A strong prior keeps the refined pose at its centre: the comparison then sees the turns (this
    # untrained model's refinement turns the traced step's 1e-5 rounding into up to 0.2 on a frame).
    apply_settings(est, {"refine_steps": "3", "refine_centre": "recording", "refine_centre_frames": str(n),
                         "refine_weight": "10"})
    fixed = est.estimate(rec)
    est.set_refine_centre_every(k)
    renewed = est.estimate(rec)
    pos = ok.long().cumsum(0) - 1
    first_renewal = int(((pos == n - 1 + k) & ok).nonzero()[0])
    assert torch.equal(renewed.local_rot[:first_renewal], fixed.local_rot[:first_renewal])
    assert float((renewed.local_rot[first_renewal:] - fixed.local_rot[first_renewal:]).abs().amax()) > 1e-3
    est.set_offsets(clip["off_R"], clip["off_t"])
    online = torch.stack([est.step(f).local_rot for f in iter_frames(rec, est.sensor_names)])
    assert torch.allclose(online, renewed.local_rot, atol=1e-2)  # measured: at most 4e-3
    assert float((online[first_renewal:] - fixed.local_rot[first_renewal:]).abs().amax()) > 0.05  # measured: 0.12
    est.set_refine_centre_frames(0)
    with pytest.raises(ConfigError, match="refine_centre_frames=1"):
        est.estimate(rec)
    for bad in (-1, True, 1.5):
        with pytest.raises(ConfigError, match="refine_centre_every"):
            EmposeConfig.preset("tiny", 12).override(refine_centre_every=bad)


def test_running_turn_from_the_first_frame_ends_at_the_whole_recordings_turn(body: BodyModel) -> None:
    """``refine_centre_frames=1, refine_centre_every=1`` (the running turn, docs/empose.md): every
    valid frame adds its solve and is turned by the turn over the valid frames up to it, online
    and offline alike; on the last valid frame that is the whole recording's turn, so its answer
    is the offline whole-recording form's."""
    est = EmposeEstimator(tiny_cfg(), body=body)
    clip = _clip(body, T=12, noise="default")
    rec = recording_from_clip(clip, est.config)
    ok = clip["valid"].all(1)
    last = int(ok.nonzero()[-1])
    # A strong prior keeps the refined pose at its centre, so the comparisons see the turns (see above).
    apply_settings(est, {"refine_steps": "3", "refine_centre": "recording", "refine_weight": "10"})
    whole = est.estimate(rec)
    apply_settings(est, {"refine_centre_frames": "1", "refine_centre_every": "1"})
    running = est.estimate(rec)
    assert torch.allclose(running.local_rot[last], whole.local_rot[last], atol=1e-4)  # float64 sums in another order; measured: 0
    first = int(ok.nonzero()[0])
    assert float((running.local_rot[first] - whole.local_rot[first]).abs().amax()) > 0.1  # one frame's turn is not the recording's: 0.63
    est.set_offsets(clip["off_R"], clip["off_t"])
    online = [est.step(f) for f in iter_frames(rec, est.sensor_names)]
    assert [f.extras["centre_measured"] for f in online] == ok.tolist()
    assert [f.extras["centre_turned"] for f in online] == (ok.cumsum(0) >= 1).tolist()
    rot = torch.stack([f.local_rot for f in online])
    assert torch.allclose(rot, running.local_rot, atol=1e-2)  # measured: 2e-3
