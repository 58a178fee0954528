"""The closed-form L_r gradient of the LGD-RNN inference path against autograd."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import torch

from wearpose.body import BodyModel
from wearpose.body.asset import load_default_asset
from wearpose.estimators import iter_frames
from wearpose.estimators.empose import EmposeEstimator, VirtualSensors
from wearpose.estimators.empose.data import recording_from_clip, simulate_clip
from wearpose.estimators.empose.estimator import _sites
from wearpose.estimators.empose.fastgrad import LeanSensorGrad
from wearpose.estimators.empose.model import decode_omega, reconstruction_loss
from wearpose.geometry import axis_angle_to_matrix
from wearpose.weights import weight_path

from test_empose import synthetic_motion  # tests/estimators is on sys.path (pytest rootdir mode)


def _problem(dtype: torch.dtype, N: int = 4, S: int = 12, seed: int = 0):
    g = torch.Generator().manual_seed(seed)
    r = lambda *s, k=1.0: k * torch.randn(*s, generator=g, dtype=dtype)  # noqa: E731
    omega = torch.cat([r(N, 120), r(N, 10, k=0.5)], 1)
    return (omega, r(N, S, 3, k=0.3), axis_angle_to_matrix(r(N, S, 3)), axis_angle_to_matrix(r(N, S, 3, k=0.2)),
            r(N, S, 3, k=0.02))


def _autograd(vs: VirtualSensors, omega, mp, mR, oR, ot):
    om = omega.clone().requires_grad_(True)
    R, b = decode_omega(om, "rot6d")
    p_hat, R_hat, J = vs(R, b, oR, ot)
    rec = reconstruction_loss(p_hat, R_hat, mp, mR)
    grad, = torch.autograd.grad(rec.sum(), om)
    return rec.detach(), grad, J.detach(), R.detach()


@pytest.mark.parametrize("posedirs", [False, True])
def test_closed_form_gradient_matches_autograd_float64(posedirs: bool) -> None:
    """L_r, joints, pose and dL_r/dOmega equal autograd through BodyModel.sites to 1e-6 (float64),
    with and without pose blend shapes (the embedded asset has none; SMPL files do)."""
    asset = load_default_asset()
    if posedirs:
        rng = np.random.default_rng(0)
        asset = dataclasses.replace(asset, posedirs=1e-2 * rng.standard_normal((207, asset.v_template.size)))
    body = BodyModel(asset, dtype=torch.float64)
    sites, src = _sites("em12", body)
    vs = VirtualSensors(body, sites, src)
    kernel = vs.lean()
    args = _problem(torch.float64)
    rec, grad, J, R = _autograd(vs, *args)
    ctx = kernel.forward(*args)
    g = kernel.backward(ctx)
    assert torch.allclose(ctx["rec"], rec, atol=1e-9, rtol=0)
    assert torch.allclose(ctx["joints"], J, atol=1e-12, rtol=0)
    assert torch.allclose(ctx["local_rot"], R, atol=1e-12, rtol=0)
    assert float((g - grad).abs().max()) < 1e-6 * max(1.0, float(grad.abs().max()))
    assert float(grad.abs().max()) > 1e-2  # a non-trivial gradient was compared
    # Shared offsets (S, 3, 3) broadcast like per-frame ones (the online path passes them so).
    ctx2 = kernel.forward(args[0], args[1], args[2], args[3][0], args[4][0])
    rec2, _, _, _ = _autograd(vs, args[0], args[1], args[2], args[3][:1].expand_as(args[3]), args[4][:1].expand_as(args[4]))
    assert torch.allclose(ctx2["rec"], rec2, atol=1e-9, rtol=0)


def test_kernel_is_cached_per_device_and_dtype(body: BodyModel) -> None:
    sites, src = _sites("em6", body)
    vs = VirtualSensors(body, sites, src)
    assert vs.lean() is vs.lean()
    assert isinstance(vs.lean(), LeanSensorGrad)


def test_shipped_checkpoint_lean_path_equals_autograd_path() -> None:
    """Online step and offline estimate of the shipped 12-sensor model: the closed-form path gives
    the same pose and shape as the autograd path (float32, ~1e-5)."""
    paths = {}
    for lean in (True, False):
        est = EmposeEstimator.load(weight_path("empose12_cpu"))
        est.model.lean_inference = lean
        paths[lean] = est
    r = simulate_clip(synthetic_motion(5, T=24), paths[True].config, paths[True].body, seed=1, noise="default")
    rec = recording_from_clip(r, paths[True].config)
    tracks = {k: e.estimate(rec) for k, e in paths.items()}
    assert float((tracks[True].local_rot - tracks[False].local_rot).abs().max()) < 1e-5
    assert float((tracks[True].betas - tracks[False].betas).abs().max()) < 1e-5
    assert torch.allclose(tracks[True].extras["rec_loss"], tracks[False].extras["rec_loss"], atol=1e-5, rtol=1e-4)
    for e in paths.values():
        e.set_offsets(torch.as_tensor(r["off_R"]), torch.as_tensor(r["off_t"]))
        e.reset()
    for k, frame in enumerate(iter_frames(rec, paths[True].sensor_names)):
        if k >= 6:
            break
        a, b = paths[True].step(frame), paths[False].step(frame)
        assert float((a.local_rot - b.local_rot).abs().max()) < 1e-5
        assert float((a.betas - b.betas).abs().max()) < 1e-5
        assert not a.local_rot.requires_grad and not b.local_rot.requires_grad


def test_update_net_inference_folds_batch_norm_exactly() -> None:
    """Eval + no-grad UpdateNet (batch norm folded into the dense layers) equals the module
    stack, and follows later changes of the weights / running statistics."""
    from wearpose.estimators.empose.model import UpdateNet

    torch.manual_seed(0)
    net = UpdateNet(20, 16, 3, 5, 0.2)
    for _ in range(3):
        net(torch.randn(8, 20))  # training mode: moves the running statistics off their init
    net.eval()
    x = torch.randn(4, 20)
    with torch.no_grad():
        assert torch.allclose(net(x), net.net(x), atol=1e-6)
        net.net[1].running_mean += 0.5
        net.net[0].weight.mul_(1.1)
        assert torch.allclose(net(x), net.net(x), atol=1e-6)
    assert net(x).requires_grad  # with grad enabled the module stack runs (training through it)


def test_traced_online_step_equals_eager_and_follows_weight_changes(body: BodyModel) -> None:
    """The traced per-frame function gives the eager step's numbers, and is rebuilt when the
    weights change (a stale trace would keep the old constants)."""
    from wearpose.estimators.empose import EmposeConfig

    cfg = EmposeConfig.preset("tiny", 12).override(iterations=2)
    torch.manual_seed(0)
    traced = EmposeEstimator(cfg, body=body)
    eager = EmposeEstimator(cfg, body=body)
    eager.model.load_state_dict(traced.model.state_dict())
    eager._online_fn = lambda: None  # force the eager path
    r = simulate_clip(synthetic_motion(6, T=12), cfg, body, seed=2, noise="default")
    rec = recording_from_clip(r, cfg)
    frames = list(iter_frames(rec, traced.sensor_names))
    for e in (traced, eager):
        e.set_offsets(torch.as_tensor(r["off_R"]), torch.as_tensor(r["off_t"]))
    for k, frame in enumerate(frames):
        if k == 6:  # change the weights mid-stream, identically in both
            for e in (traced, eager):
                with torch.no_grad():
                    e.model.head.bias.add_(0.05)
                    e.model.update.net[0].weight.mul_(1.05)
                    e.model.rnn.weight_hh_l1.mul_(1.05)  # the written-out LSTM cell's fused weights follow
        a, b = traced.step(frame), eager.step(frame)
        assert torch.allclose(a.local_rot, b.local_rot, atol=1e-6), k
        assert torch.allclose(a.betas, b.betas, atol=1e-6), k
    assert traced._traced is not None


def test_set_iterations_runs_n_updates_like_a_model_built_with_n(body: BodyModel) -> None:
    """``set_iterations`` (``wearpose bench latency ... --set iterations=4``): the online step then
    equals that of an estimator configured with that N and the same weights, and the trace is
    rebuilt; a negative or fractional N is refused."""
    from wearpose.errors import ConfigError
    from wearpose.estimators.empose import EmposeConfig

    cfg = EmposeConfig.preset("tiny", 12).override(iterations=1)
    torch.manual_seed(0)
    changed = EmposeEstimator(cfg, body=body)
    built = EmposeEstimator(cfg.override(iterations=3), body=body)
    built.model.load_state_dict(changed.model.state_dict())
    r = simulate_clip(synthetic_motion(6, T=8), cfg, body, seed=2, noise="default")
    frames = list(iter_frames(recording_from_clip(r, cfg), changed.sensor_names))
    for e in (changed, built):
        e.set_offsets(torch.as_tensor(r["off_R"]), torch.as_tensor(r["off_t"]))
    one = changed.step(frames[0])
    changed.set_iterations(3)
    assert changed.config.iterations == 3 and changed.model.cfg.iterations == 3
    for k, frame in enumerate(frames):
        a, b = changed.step(frame), built.step(frame)
        assert torch.equal(a.local_rot, b.local_rot) and torch.equal(a.betas, b.betas), k
    assert not torch.equal(one.local_rot, built.step(frames[0]).local_rot)  # N changed the output
    for bad in (-1, 2.5, True):
        with pytest.raises(ConfigError, match="whole number of LGD updates"):
            changed.set_iterations(bad)


def test_written_out_lstm_step_equals_nn_lstm(body: BodyModel) -> None:
    """``LGDRNN.initial_step`` (the online LSTM cell as addmm + gates, no oneDNN kernel) gives
    ``nn.LSTM``'s outputs and state to float rounding, over several frames."""
    from wearpose.estimators.empose import EmposeConfig

    torch.manual_seed(0)
    m = EmposeEstimator(EmposeConfig.preset("tiny", 12), body=body).model.eval()
    x = torch.randn(1, 10, m.in_dim)
    with torch.no_grad():
        ref, (h_ref, c_ref) = m.initial(x)
        z = torch.zeros(m.cfg.rnn_layers, 1, m.cfg.hidden)
        state = (z, z)
        for t in range(10):
            out, state = m.initial_step(x[:, t], state)
            assert torch.allclose(out, ref[:, t], atol=1e-6, rtol=0), t
    assert torch.allclose(state[0], h_ref, atol=1e-6) and torch.allclose(state[1], c_ref, atol=1e-6)
