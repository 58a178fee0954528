"""BiRAE: representations, network, loss, uncertainty, data synthesis, training, fine-tuning and
the estimator protocol (offline, online sliding window, frame rate). Synthetic motion, ``tiny``
preset, one torch thread."""

from __future__ import annotations

import math
import warnings
from pathlib import Path

import pytest
import torch

from tests.estimators.test_empose import FakeStore, synthetic_motion
from wearpose.errors import ConfigError, ShapeError
from wearpose.estimators import CheckpointMismatchError, PoseTrack, get_estimator, iter_frames
from wearpose.estimators.birae import BiraeConfig, BiraeEstimator, BiRAE, nll_loss
from wearpose.estimators.birae.data import (
    SCENARIOS, augmentation_noise, build_split, make_recording, sensor_orientations, synthesize,
)
from wearpose.estimators.birae.representations import (
    angular_rate, features, input_dim, pose_to_target, relative_orientations, target_to_pose,
)
from wearpose.estimators.birae.uncertainty import (
    GAUSS_1SIGMA, calibration_report, combine, coverage, fit_sigma_scale, pearson, reliability_curve,
)
from wearpose.geometry import axis_angle_to_matrix, rotation_x, rotation_y


def rand_R(n: int, seed: int) -> torch.Tensor:
    g = torch.Generator().manual_seed(seed)
    return axis_angle_to_matrix(torch.randn(n, 3, generator=g))


def tiny(rep: str = "6param", **kw) -> BiraeConfig:
    return BiraeConfig.preset("tiny", rep).override(**kw)


# --------------------------------------------------------------------------- representations
def test_3param_is_yaw_free_and_6param_is_not() -> None:
    """A heading error on one sensor (root upright) leaves the 3-param input unchanged only."""
    R = rand_R(6, 0).reshape(1, 6, 3, 3)
    R[:, 5] = rotation_x(torch.tensor(0.0))  # upright root (identity)
    Ry = rotation_y(torch.tensor(0.7))
    R2 = R.clone()
    R2[:, 1] = Ry @ R[:, 1]
    a3, b3 = features(relative_orientations(R), "3param"), features(relative_orientations(R2), "3param")
    a6, b6 = features(relative_orientations(R), "6param"), features(relative_orientations(R2), "6param")
    assert a3.shape == (1, 15) and a6.shape == (1, 30)
    assert torch.allclose(a3, b3, atol=1e-6)
    assert (a6 - b6).abs().max() > 0.1


@pytest.mark.parametrize("tilt_deg", [0.0, 10.0, 40.0])
def test_heading_error_of_one_sensor_enters_3param_only_through_root_tilt(tilt_deg: float) -> None:
    """Eq. 1 + 3-param: ``(r31, r32, r33)`` of ``R_root^T R_i`` is the root's up axis seen from
    sensor i; a world heading error ``d`` of sensor i moves it by exactly
    ``2 sin(|d| / 2) sin(tilt)`` (tilt = angle of the root's up axis from vertical): zero for an
    upright root, a leak for a tilted one. The 6-param input moves by O(|d|) at any tilt."""
    g = torch.Generator().manual_seed(7)
    for trial in range(5):
        R = rand_R(6, 10 + trial).reshape(1, 6, 3, 3)
        axis = torch.nn.functional.normalize(torch.tensor([1.0, 0.0, float(torch.randn(1, generator=g))]), dim=0)
        R[:, 5] = rotation_y(torch.rand(1, generator=g)[0] * 6) @ axis_angle_to_matrix(math.radians(tilt_deg) * axis)
        d = float(torch.empty(1).uniform_(0.3, 1.2, generator=g))
        R2 = R.clone()
        R2[:, 2] = rotation_y(torch.tensor(d)) @ R[:, 2]
        f3 = [features(relative_orientations(x), "3param").reshape(5, 3) for x in (R, R2)]
        f6 = [features(relative_orientations(x), "6param").reshape(5, 6) for x in (R, R2)]
        leak = float((f3[1][2] - f3[0][2]).norm())
        assert leak == pytest.approx(2 * math.sin(d / 2) * math.sin(math.radians(tilt_deg)), abs=1e-5)
        assert torch.allclose(f3[0][[0, 1, 3, 4]], f3[1][[0, 1, 3, 4]])  # other sensors untouched
        assert float((f6[1][2] - f6[0][2]).norm()) > 0.2 * d


def test_common_heading_error_cancels_and_per_sensor_scenario_does_not() -> None:
    """A heading error shared by all six sensors (e.g. one disturbance seen by the whole body)
    cancels exactly in Eq. 1 for every representation; the ``magnetic`` scenario draws its
    heading errors per sensor, so the root-relative heading errors are not zero."""
    R = rand_R(12, 3).reshape(2, 6, 3, 3)
    common = rotation_y(torch.tensor([0.9, -1.4]))[:, None] @ R
    for rep in ("6param", "3param", "zhou6d"):
        assert torch.allclose(features(relative_orientations(R), rep), features(relative_orientations(common), rep), atol=1e-5)
    m = synthetic_motion(6, T=240, fps=60.0)
    mag = synthesize(m, 60.0, SCENARIOS["magnetic"], seed=5)
    rel = (mag["yaw_error"][:, :5] - mag["yaw_error"][:, 5:]).abs()
    assert float(rel.mean()) > math.radians(5.0)
    noise = synthesize(m, 60.0, SCENARIOS["noise"], seed=5)
    assert float((noise["yaw_error"][:, :5] - noise["yaw_error"][:, 5:]).abs().mean()) < float(rel.mean()) / 3


def test_exponential_learning_rate_decay_in_the_shared_loop(tmp_path: Path) -> None:
    """Sec. IV-E: lr x ``lr_decay`` every ``lr_decay_steps`` (continuous), wired from the config."""
    from wearpose.estimators.train import _lr_at, loop_settings  # train_birae's settings

    cfg = BiraeConfig.preset("cpu")
    assert cfg.lr_schedule == "exp" and BiraeConfig.preset("paper").lr_decay_steps == 5000
    s = loop_settings(cfg, tmp_path, 1, resume=False, threads=1, device="cpu", checkpoint_every=10, max_steps=None, quiet=True)
    assert s.lr_schedule == "exp" and s.lr_decay == cfg.lr_decay and s.lr_decay_steps == cfg.lr_decay_steps
    assert _lr_at(s, 0, 50) == pytest.approx(cfg.lr)
    assert _lr_at(s, 2 * cfg.lr_decay_steps, 50) == pytest.approx(cfg.lr * cfg.lr_decay ** 2)
    assert _lr_at(s, cfg.lr_decay_steps // 2, 10 ** 6) == pytest.approx(cfg.lr * cfg.lr_decay ** 0.5)


def test_inputs_invariant_to_a_common_world_rotation() -> None:
    """Eq. 1: turning the whole body (all sensors) changes no representation."""
    R = rand_R(12, 1).reshape(2, 6, 3, 3)
    G = rand_R(1, 2)[0]
    for rep in ("6param", "3param", "zhou6d"):
        assert torch.allclose(features(relative_orientations(R), rep), features(relative_orientations(G @ R), rep), atol=1e-5)
        assert features(relative_orientations(R), rep).shape[-1] == input_dim(rep)


def test_angular_rate_recovers_a_constant_rotation_rate() -> None:
    fps, w = 60.0, torch.tensor([0.3, -1.2, 0.5])
    t = torch.arange(10, dtype=torch.float32)[:, None] / fps
    Rr = axis_angle_to_matrix(t * w).reshape(10, 1, 3, 3).expand(10, 5, 3, 3)
    r = angular_rate(Rr, fps)
    assert r.shape == (10, 5, 3) and torch.all(r[0] == 0)
    assert torch.allclose(r[1:], w.expand(9, 5, 3), atol=1e-4)
    with pytest.raises(ShapeError):
        features(Rr, "3param_rate")


def test_expmap_target_round_trip_and_identity_elsewhere() -> None:
    pose = synthetic_motion(3, T=5).pose
    y = pose_to_target(pose)
    back = target_to_pose(y)
    assert y.shape == (5, 15, 3)
    from wearpose.body import MAJOR_JOINTS

    assert torch.allclose(back[:, list(MAJOR_JOINTS)], pose[:, list(MAJOR_JOINTS)], atol=1e-5)
    other = [j for j in range(24) if j not in MAJOR_JOINTS]
    assert torch.allclose(back[:, other], torch.eye(3).expand(5, len(other), 3, 3))


# --------------------------------------------------------------------------- network and loss
def test_network_shapes_packing_and_mc_dropout() -> None:
    cfg = tiny("3param_rate")
    net = BiRAE(cfg).eval()
    x = torch.randn(3, 12, input_dim(cfg.rep))
    out = net(x)
    assert out["mu"].shape == (3, 12, 45) and out["logvar"].shape == (3, 12, 45) and out["aux"].shape == (3, 12, 15)
    # A padded row gives the same outputs on its real frames as the row alone (packing).
    lengths = torch.tensor([12, 7, 12])
    packed = net(x, lengths)["mu"]
    alone = net(x[1:2, :7])["mu"]
    assert torch.allclose(packed[1, :7], alone[0], atol=1e-5)
    # MC-dropout: reproducible for a seeded generator, different between draws, off by default.
    g1, g2 = torch.Generator().manual_seed(1), torch.Generator().manual_seed(1)
    a, b = net(x, mc=True, generator=g1)["mu"], net(x, mc=True, generator=g2)["mu"]
    assert torch.equal(a, b) and not torch.allclose(a, net(x, mc=True, generator=g1)["mu"])
    assert torch.equal(net(x)["mu"], net(x)["mu"])


def test_nll_is_minimised_at_the_true_error_scale() -> None:
    y = torch.zeros(1, 1, 45)
    mu = torch.full((1, 1, 45), 0.2)
    lv = torch.linspace(-8, 2, 201)
    vals = torch.stack([nll_loss(mu, torch.full_like(mu, float(v)), y) for v in lv])
    assert abs(float(lv[vals.argmin()]) - math.log(0.04)) < 0.06
    mask = torch.tensor([[True, False]])
    two = torch.cat([mu, mu + 100], 1), torch.zeros(1, 2, 45), torch.zeros(1, 2, 45)
    assert torch.isclose(nll_loss(*two, mask), nll_loss(mu, torch.zeros_like(mu), y))


# --------------------------------------------------------------------------- uncertainty
def test_combine_follows_eq7_eq8() -> None:
    mus = torch.tensor([[1.0], [3.0]])
    lvs = torch.log(torch.tensor([[1.0], [3.0]]))
    c = combine(mus, lvs)
    assert torch.allclose(c["mu"], torch.tensor([2.0]))
    assert torch.allclose(c["sigma_e"] ** 2, torch.tensor([1.0]))
    assert torch.allclose(c["sigma_a"] ** 2, torch.tensor([2.0]))
    assert torch.allclose(c["sigma"] ** 2, torch.tensor([3.0]))


def test_sigma_scaling_calibrates_an_overconfident_gaussian() -> None:
    g = torch.Generator().manual_seed(0)
    sigma = 0.05 + 0.1 * torch.rand(20000, 15, 3, generator=g)
    res = 2.5 * sigma * torch.randn(20000, 15, 3, generator=g)
    assert coverage(res, sigma) < 0.4
    s = fit_sigma_scale(res, sigma, "nll")
    assert abs(s - 2.5) < 0.05
    assert abs(coverage(res, s * sigma) - GAUSS_1SIGMA) < 0.01
    q = fit_sigma_scale(res, sigma, "quantile")
    assert abs(coverage(res, q * sigma) - GAUSS_1SIGMA) < 0.001
    rep = calibration_report(res, s * sigma)
    assert set(rep["groups"]) == {"distal", "tracking", "other"} and rep["pearson_r_sigma_error"] > 0.1
    rel = reliability_curve(res, s * sigma)
    assert max(abs(a - b) for a, b in zip(rel["expected"], rel["observed"])) < 0.02
    assert math.isnan(pearson(torch.ones(4), torch.arange(4.0)))
    with pytest.raises(ValueError):
        fit_sigma_scale(res, sigma, "bogus")


# --------------------------------------------------------------------------- data
def test_synthesis_matches_the_sensor_simulator(body) -> None:
    """Ideal orientations by FK equal ``simulate(kit mimu6, imu_orientation='segment')``."""
    from wearpose.sensors import simulate

    m = synthetic_motion(5, T=20, fps=60.0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sim = simulate(m, "mimu6", body, noise="none", imu_orientation="segment")
    ref = torch.stack([sim[n].orientation for n in sim.kit.sensor_names], 1).float()
    assert torch.allclose(sensor_orientations(m.pose), ref, atol=1e-5)


def test_scenarios_disturb_heading_as_declared() -> None:
    m = synthetic_motion(6, T=120, fps=60.0)
    clean = synthesize(m, 60.0, None)
    mag = synthesize(m, 60.0, SCENARIOS["magnetic"], seed=3)
    again = synthesize(m, 60.0, SCENARIOS["magnetic"], seed=3)
    assert torch.equal(mag["R_world"], again["R_world"])
    assert float(clean["yaw_error"].abs().max()) == 0.0
    assert float(mag["yaw_error"].abs().max()) > math.radians(1.0)
    assert clean["R_rel"].shape == (clean["target"].shape[0], 5, 3, 3)
    assert augmentation_noise(tiny()).mag_rate == 0.0  # training never sees magnetic disturbance


# --------------------------------------------------------------------------- training and estimator
@pytest.fixture(scope="module")
def trained(tmp_path_factory) -> tuple[BiraeEstimator, Path, FakeStore]:
    tmp = tmp_path_factory.mktemp("birae")
    store = FakeStore(tmp, {"train": 4, "val": 2, "test": 1})
    est = BiraeEstimator(tiny())
    res = est.fit(tmp / "run", store=store, cache_root=tmp / "cache", quiet=True, checkpoint_every=2, threads=1)
    assert res["best_checkpoint"] and (tmp / "run" / "clean" / "best.pt").is_file() and (tmp / "run" / "aug" / "best.pt").is_file()
    return est, tmp, store


def test_loss_decreases_on_a_fixed_batch(tmp_path: Path) -> None:
    torch.manual_seed(0)
    cfg = tiny("3param_rate", lr=1e-2)
    data = build_split("train", cfg, store=FakeStore(tmp_path, {"train": 3}), cache_root=tmp_path / "c")
    b = next(data.iter_batches(cfg, augmented=True, shuffle=False))
    est = BiraeEstimator(cfg)
    from wearpose.estimators.birae.train import batch_loss

    opt = torch.optim.Adam(est.model.parameters(), lr=cfg.lr)
    first = None
    for _ in range(40):
        loss, parts, _ = batch_loss(est, b, torch.device("cpu"))
        first = first if first is not None else float(loss.detach())
        opt.zero_grad()
        loss.backward()
        opt.step()
    assert float(loss.detach()) < first - 0.2 and "aux_mse" in parts


def test_decoupled_loss_trains_the_mean_by_squared_error() -> None:
    """``loss="decoupled"``: the mean's gradient is the squared error's, the log-variance's Eq. 6's."""
    from wearpose.estimators.birae.train import batch_loss

    est = BiraeEstimator(tiny(loss="decoupled"))
    b = {"x": torch.randn(2, 9, 30), "y": torch.randn(2, 9, 45), "rate": torch.zeros(2, 9, 15),
         "mask": torch.ones(2, 9, dtype=torch.bool), "lengths": torch.tensor([9, 9])}
    loss, parts, out = batch_loss(est, b, torch.device("cpu"))
    assert {"mse", "nll"} <= set(parts)
    assert math.isclose(float(loss.detach()), parts["mse"] + parts["nll"], rel_tol=1e-5)
    g_mu = torch.autograd.grad(loss, out["mu"], retain_graph=True)[0]
    assert torch.allclose(g_mu, 2 * (out["mu"] - b["y"]).detach() / g_mu.numel(), atol=1e-7)
    with pytest.raises(ConfigError):
        tiny(loss="l1")


def test_train_resume_save_load_estimate(trained, tmp_path: Path) -> None:
    est, tmp, store = trained
    # resume of a finished run is a no-op that keeps the checkpoints
    again = BiraeEstimator(tiny())
    again.fit(tmp / "run", store=store, cache_root=tmp / "cache", quiet=True, resume=True, threads=1)
    m = store.load("synthetic/test_00")
    s = synthesize(m, 60.0, SCENARIOS["noise"], seed=1, channels=True)
    rec = make_recording(s["R_world"], 60.0, s["sim"])
    track = est.estimate(rec)
    T = s["pose"].shape[0]
    assert isinstance(track, PoseTrack) and track.local_rot.shape == (T, 24, 3, 3) and track.uncertainty.shape == (T, 24)
    assert track.extras["sigma"].shape == (T, 15, 3) and bool((track.extras["sigma"] > 0).all())
    assert track.extras["frame"] == "root" and track.uncertainty[:, 0].eq(0).all() and track.uncertainty[:, 1].gt(0).all()
    p = est.save(tmp_path / "e.pt")
    loaded = get_estimator("birae").load(p)
    t2 = loaded.estimate(rec)
    assert torch.allclose(t2.local_rot, track.local_rot, atol=1e-6)
    assert torch.allclose(t2.extras["sigma"], track.extras["sigma"], atol=1e-6)  # seeded MC-dropout
    with pytest.raises(CheckpointMismatchError):
        BiraeEstimator.load(p, kit="imu6")
    world = est.with_root(track, rec)
    assert world.extras["frame"] == "world" and torch.allclose(world.local_rot[:, 0], s["R_world"][:, 5], atol=1e-6)


def test_init_from_continues_a_checkpoint_and_zero_epochs_skip_a_phase(trained, tmp_path: Path) -> None:
    est, tmp, store = trained
    src = tmp / "run" / "best.pt"
    ref = BiraeEstimator.load(src)
    fresh = BiraeEstimator(tiny())
    res = fresh.fit(tmp_path / "cont", store=store, cache_root=tmp / "cache", quiet=True, threads=1,
                    epochs_clean=0, epochs_aug=0, init_from=src)
    assert res["best_checkpoint"] is None and fresh.meta["init_from"] == str(src)
    assert all(torch.equal(a, b) for a, b in zip(fresh.model.state_dict().values(), ref.model.state_dict().values()))
    with pytest.raises(CheckpointMismatchError):
        BiraeEstimator(tiny("3param")).fit(tmp_path / "bad", store=store, cache_root=tmp / "cache", quiet=True,
                                           threads=1, epochs_clean=0, epochs_aug=0, init_from=src)


def test_sigma_phase_refits_the_log_variance_head_alone_on_the_corpus_clips(trained, tmp_path: Path) -> None:
    """``epochs_sigma``: only ``logvar.*`` moves, on the train split without the mix; kept by val NLL."""
    import json

    est, tmp, store = trained
    src = tmp / "run" / "best.pt"
    ref = BiraeEstimator.load(src).model.state_dict()
    fresh = BiraeEstimator(tiny(aug_mirror=True, epochs_sigma=2, lr_sigma=3e-2))
    res = fresh.fit(tmp_path / "sig", store=store, cache_root=tmp / "cache", quiet=True, threads=1,
                    epochs_clean=0, epochs_aug=0, init_from=src)
    assert res["best_checkpoint"] == str(tmp_path / "sig" / "best.pt")
    kept = BiraeEstimator.load(tmp_path / "sig" / "best.pt")
    assert kept.meta["phase"] == "sigma" and math.isfinite(kept.meta["val_nll"])
    moved = {k for k, v in kept.model.state_dict().items() if not torch.equal(v, ref[k])}
    assert moved == {"logvar.weight", "logvar.bias"}
    assert all(p.requires_grad for p in fresh.model.parameters())  # the freeze ends with the phase
    rows = [json.loads(x) for x in (tmp_path / "sig" / "sigma" / "log.jsonl").read_text().splitlines()]
    start = next(r for r in rows if r["type"] == "start")
    epochs = [r for r in rows if r["type"] == "epoch"]
    assert len(epochs) == 2 and kept.meta["val_nll"] == min(r["val_nll"] for r in epochs)
    # the phase's windows come from the 4 corpus clips, not from them and their 4 mirror images
    cfg = fresh.config
    own, mixed = (build_split("train", c, store=store, cache_root=tmp / "cache") for c in (cfg.without_mix(), cfg))
    assert len(mixed.clip_ids) == 2 * len(own.clip_ids) == 8
    batches = [math.ceil(len(d.windows(cfg.seq_len, cfg.min_len)) / cfg.batch_size) for d in (own, mixed)]
    assert start["batches_per_epoch"] == batches[0] < batches[1]
    with pytest.raises(ConfigError, match="epochs_sigma"):
        tiny(epochs_sigma=-1)


def test_training_chain_follows_init_from_and_counts_kept_steps(trained, tmp_path: Path) -> None:
    import json
    import shutil

    from wearpose.estimators.birae.evaluate import budget_summary, training_chain

    _, tmp, store = trained
    src = tmp / "run" / "best.pt"
    cont = tmp_path / "cont"
    BiraeEstimator(tiny()).fit(cont, store=store, cache_root=tmp / "cache", quiet=True, threads=1, epochs_clean=0,
                               epochs_aug=2, init_from=src, train_command=f"wearpose train birae --out {cont}")

    def steps_at(log: Path, epoch: int) -> int:  # independent reading: batches per epoch x kept epoch
        start = json.loads(log.read_text().splitlines()[0])
        return start["batches_per_epoch"] * epoch

    kept = {ph: BiraeEstimator.load(tmp / "run" / ph / "best.pt").meta["epoch"] for ph in ("clean", "aug")}
    kept_cont = BiraeEstimator.load(cont / "best.pt").meta["epoch"]
    first = steps_at(tmp / "run" / "clean" / "log.jsonl", kept["clean"]) + steps_at(tmp / "run" / "aug" / "log.jsonl", kept["aug"])
    second = steps_at(cont / "aug" / "log.jsonl", kept_cont)
    # a shipped copy elsewhere finds its run through the --out of its command
    shipped = tmp_path / "weights" / "w.pt"
    shipped.parent.mkdir()
    shutil.copyfile(cont / "best.pt", shipped)
    for p in (cont / "best.pt", shipped):
        chain = training_chain(p)
        assert [c["run"] for c in chain] == [str(tmp / "run"), str(cont)]
        assert chain[0]["phases"]["clean"]["epochs"] == kept["clean"] and chain[0]["steps"] == first
        assert chain[1]["phases"]["clean"]["epochs"] == 0 and chain[1]["steps"] == second
        s = budget_summary(chain)
        assert s["steps"] == first + second and s["epochs_aug"] == kept["aug"] + kept_cont and s["runs"] == 2
        assert "run (" in s["text"] and "-> cont (" in s["text"]
    # a checkpoint without logs or command: one run of unknown budget
    lone = tmp_path / "lone.pt"
    BiraeEstimator(tiny()).save(lone)
    assert budget_summary(training_chain(lone))["steps"] is None and training_chain(lone)[0]["run"] is None


def test_online_step_equals_windowed_and_declares_latency(trained) -> None:
    est, _, store = trained
    est.set_window(6, 3)
    est.mc_samples = 0  # MC-dropout masks are drawn per call; the deterministic pass must agree exactly
    assert est.lookahead == 3 and math.isclose(est.latency_s, 3 / 60)
    s = synthesize(store.load("synthetic/test_00"), 60.0, None, channels=True)
    rec = make_recording(s["R_world"], 60.0, s["sim"])
    win = est.estimate_windowed(rec, frames=[0, 5, 10])
    est.reset()
    outs = [est.step(f) for f in iter_frames(rec, est.sensor_names)]
    assert not outs[0].valid and outs[0].extras.get("warming_up")
    for t in (0, 5, 10):
        o = outs[t + 3]
        assert math.isclose(o.timestamp, t / 60.0, abs_tol=1e-6) and o.valid
        assert torch.allclose(o.local_rot, win.local_rot[t], atol=1e-5)
        assert torch.allclose(o.extras["sigma"], win.extras["sigma"][t], atol=1e-5)
    assert not bool(win.valid[1])  # frames not asked for are marked invalid
    est.set_window(*est.config.window)
    est.mc_samples = est.config.mc_samples


def test_streamed_step_equals_its_batched_form_and_window_at_the_start(trained) -> None:
    """online='stream': step by step equals estimate_streamed (every frame, sigma = aleatoric x
    scale); its first output frame equals the window mode's (same past, same future)."""
    est, _, store = trained
    est.set_window(6, 3)
    s = synthesize(store.load("synthetic/test_00"), 60.0, None, channels=True)
    rec = make_recording(s["R_world"], 60.0, s["sim"])
    est.mc_samples = 0
    win = est.estimate_windowed(rec, frames=[0])
    est.set_online("stream")
    batched = est.estimate_streamed(rec)
    outs = [est.step(f) for f in iter_frames(rec, est.sensor_names)]
    assert not outs[2].valid and outs[3].valid and outs[3].extras["online"] == "stream"
    T = len(outs)
    for t in range(0, T - 3):
        o = outs[t + 3]
        assert math.isclose(o.timestamp, t / 60.0, abs_tol=1e-6)
        assert torch.allclose(o.local_rot, batched.local_rot[t], atol=1e-5), t
        assert torch.allclose(o.extras["sigma"], batched.extras["sigma"][t], atol=1e-5), t
    assert torch.allclose(outs[3].local_rot, win.local_rot[0], atol=1e-5)
    assert torch.allclose(outs[3].extras["sigma"], win.extras["sigma"][0], atol=1e-5)
    assert float((batched.extras["sigma_epistemic"]).abs().max()) == 0.0
    est.set_online("window")
    est.set_window(*est.config.window)
    est.mc_samples = est.config.mc_samples
    with pytest.raises(ShapeError):
        est.set_online("chunked")


def test_frame_rate_flexibility_and_input_errors(trained) -> None:
    est, _, store = trained
    m = store.load("synthetic/test_00")
    s30 = synthesize(m, 30.0, None, channels=True)
    rec = make_recording(s30["R_world"], 30.0, s30["sim"])
    t30 = est.estimate(rec)
    assert t30.fps == 30.0 and t30.local_rot.shape[0] == s30["pose"].shape[0]
    with pytest.raises(ShapeError):
        est.estimate(rec.select(["head", "root"]))
    with pytest.raises(ShapeError):
        est.set_window(-1, 3)
    with pytest.raises(ConfigError):
        BiraeConfig.preset("huge")
    with pytest.raises(ConfigError):
        BiraeConfig(rep="9param")


def test_finetune_improves_the_fit_on_target_motions(trained, tmp_path: Path) -> None:
    from wearpose.estimators.birae.evaluate import evaluate, scenario_recordings

    est, tmp, store = trained
    target = [synthetic_motion(40 + i, T=60) for i in range(2)]
    recs = []
    for i, m in enumerate(target):
        s = synthesize(m, 60.0, None, channels=True)
        recs.append((f"t{i}", make_recording(s["R_world"], 60.0, s["sim"]), s["pose"]))
    before = evaluate(est, recs, mc_samples=0)["mpjae_all_deg"]
    tuned = BiraeEstimator.load(tmp / "run" / "best.pt")
    tuned.finetune(target, tmp_path / "ft", epochs=15, lr=1e-2, augmented=False)
    after = evaluate(tuned, recs, mc_samples=0)["mpjae_all_deg"]
    assert after < before and "finetuned_on" in tuned.meta
    assert len(scenario_recordings("test", "clean", store=store)) == 1


def test_motion_content_folds_never_split_a_content() -> None:
    from wearpose.estimators.birae.evaluate import content_folds, motion_content

    assert motion_content("bandai/bandai-C/dataset-2_run_normal_003") == "bandai/bandai-C/dataset-2_run"
    assert motion_content("cmu_daz/indian/indian_13") == "cmu_daz/indian/indian"
    ids = [f"b/x/d_{c}_{st}_{i:03d}" for c in ("run", "walk", "wave", "jump") for st in ("normal", "active") for i in range(3)]
    fold = content_folds(ids, 3)
    assert sorted(set(fold)) == [0, 1, 2]
    by = {}
    for i, f in zip(ids, fold):
        by.setdefault(motion_content(i), set()).add(f)
    assert all(len(v) == 1 for v in by.values())


def test_calibrate_auto_picks_a_rule_on_validation_folds_and_heading_offsets(trained) -> None:
    from wearpose.estimators.birae.evaluate import calibrate, evaluate, scenario_recordings
    from wearpose.estimators.birae.uncertainty import coverage

    est, tmp, store = trained
    est = BiraeEstimator.load(tmp / "run" / "best.pt")
    recs = []
    for i in range(6):
        s = synthesize(synthetic_motion(60 + i, T=50), 60.0, SCENARIOS["noise"], seed=i, channels=True)
        recs.append((f"v/s/d_{('run', 'walk', 'wave')[i % 3]}_normal_{i:03d}", make_recording(s["R_world"], 60.0, s["sim"]),
                     s["pose"]))
    cal = calibrate(est, recs, "auto", mc_samples=2)
    assert cal["cv"]["folds"] == 3 and set(cal["cv"]) >= {"quantile", "nll"}
    assert len(cal["cv"]["quantile"]["fold_coverage"]) == 3
    best = min(("quantile", "nll"), key=lambda m: cal["cv"][m]["mean_abs_dev"])
    assert cal["method"] == best and est.sigma_scale == pytest.approx(cal["scales"][best])
    r = evaluate(est, recs, mc_samples=2, keep_uncertainty=True)  # sigma now calibrated
    if best == "quantile":
        assert coverage(r["_residual"], r["_sigma"]) == pytest.approx(GAUSS_1SIGMA, abs=0.01)
    with pytest.raises(ValueError):
        calibrate(est, recs, "bogus")
    # the heading-offset diagnostic turns each sensor about the vertical by its own constant angle
    (_, a, _), = scenario_recordings("test", "clean", store=store)
    (_, b, _), = scenario_recordings("test", "clean", store=store, heading_offset_deg=45.0)
    Ra = torch.as_tensor(a.on_common_grid(list(a.names)).channels["orientation"])
    Rb = torch.as_tensor(b.on_common_grid(list(b.names)).channels["orientation"])
    E = Rb @ Ra.transpose(-1, -2)
    yaw = torch.atan2(E[..., 0, 2], E[..., 0, 0])
    assert torch.allclose(E[..., 1, 1], torch.ones_like(E[..., 1, 1]), atol=1e-5)
    assert torch.allclose(yaw, yaw[:1].expand_as(yaw), atol=1e-5) and float(yaw.abs().max()) <= math.radians(45.0) + 1e-6
    assert float(yaw[0].std()) > 0.01


def test_demo_runs_with_given_weights(trained, tmp_path: Path, monkeypatch) -> None:
    """The mimu6 demo on a motion file, with the tiny model standing in for the shipped weights."""
    import json

    import wearpose.weights as weights
    from wearpose.cli.demo import kit_demo

    est, tmp, _ = trained
    p = est.save(tmp_path / "w.pt")
    monkeypatch.setattr(weights, "weight_path", lambda name: p)
    monkeypatch.setattr(weights, "card", lambda name: {"licence": "test"})
    clip = synthetic_motion(9, T=30, fps=30.0).save(tmp_path / "clip.npz")
    res = kit_demo("mimu6")(str(clip), tmp_path / "demo")
    assert res["frames"] == 59 and Path(res["html"]).is_file() and Path(res["plot"]).stat().st_size > 10_000
    assert {"mpjae_all_deg", "within_1sigma_pct", "magnetic_mpjae_3param_deg"} <= set(res["metrics"])
    assert all(math.isfinite(v) for v in res["metrics"].values())
    assert json.loads((tmp_path / "demo" / "metrics.json").read_text())["clip"] == str(clip)


# --------------------------------------------------------------------------- CLI
def test_train_birae_help_and_bad_representation(tmp_path: Path) -> None:
    from typer.testing import CliRunner

    from wearpose.cli import app

    runner = CliRunner()
    res = runner.invoke(app, ["train", "birae", "--help"])
    assert res.exit_code == 0 and "Example: wearpose train birae" in res.output
    res = runner.invoke(app, ["train", "birae", "--rep", "9param", "--out", str(tmp_path / "r")])
    assert res.exit_code != 0 and "9param" in res.output


@pytest.mark.corpus
def test_tiny_cli_run_on_the_corpus(tmp_path: Path, corpus_store: Path) -> None:
    import json

    from typer.testing import CliRunner

    from wearpose.cli import app

    n = torch.get_num_threads()
    try:
        res = CliRunner().invoke(app, ["train", "birae", "--rep", "3param", "--config", "tiny", "--threads", "1",
                                       "--out", str(tmp_path / "run"), "--json"])
    finally:
        torch.set_num_threads(n)
    assert res.exit_code == 0, res.output
    out = json.loads(res.output[res.output.index("{"):])
    assert out["method"] == "birae" and out["rep"] == "3param" and (tmp_path / "run" / "best.pt").is_file()
    assert BiraeEstimator.load(tmp_path / "run" / "best.pt").config.rep == "3param"
