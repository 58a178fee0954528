"""EM-POSE LGD-RNN: sensor model, data, training loop, checkpoints and the estimator protocol.

Everything here runs on synthetic motion (no corpus needed) with the ``tiny`` preset, one torch
thread, in a few seconds.
"""

from __future__ import annotations

import json
import math
import zlib
from pathlib import Path

import pytest
import torch

from wearpose.body import BodyModel
from wearpose.errors import ConfigError, ShapeError
from wearpose.estimators import (
    CheckpointMismatchError, PoseTrack, get_estimator, iter_frames, load_checkpoint, save_checkpoint,
)
from wearpose.estimators.empose import EmposeConfig, EmposeEstimator, VirtualSensors, lgd_loss
from wearpose.estimators.empose.data import build_split, recording_from_clip, simulate_clip
from wearpose.estimators.empose.estimator import _sites
from wearpose.estimators.empose.model import PRED_JOINTS, UNOBSERVED_JOINTS, sensor_features
from wearpose.estimators.empose.train import evaluate_empose, train_empose
from wearpose.geometry import axis_angle_to_matrix
from wearpose.motion import MotionSequence


def synthetic_motion(seed: int, T: int = 40, fps: float = 30.0) -> MotionSequence:
    """Smooth random motion: per-joint sinusoids of small amplitude, random root yaw and shape."""
    g = torch.Generator().manual_seed(seed)
    t = torch.arange(T, dtype=torch.float32)[:, None, None] / fps
    amp = 0.4 * torch.rand(1, 24, 3, generator=g)
    freq = 0.5 + 1.5 * torch.rand(1, 24, 3, generator=g)
    phase = 6.28 * torch.rand(1, 24, 3, generator=g)
    aa = amp * torch.sin(6.28 * freq * t + phase)
    aa[:, 0] = torch.tensor([0.0, 1.0, 0.0]) * (6.28 * torch.rand(1, generator=g) + 0.3 * t[:, 0, :1])
    trans = torch.cat([0.2 * t[:, 0], torch.full((T, 1), 0.9), torch.zeros(T, 1)], dim=1)
    return MotionSequence(axis_angle_to_matrix(aa), 0.5 * torch.randn(10, generator=g), trans, fps,
                          {"split": "synthetic"})


class FakeStore:
    """Duck-typed :class:`~wearpose.motion.CorpusStore` over synthetic clips."""

    def __init__(self, root: Path, n: dict[str, int]) -> None:
        self.root = root
        self._ids = {split: [f"synthetic/{split}_{i:02d}" for i in range(k)] for split, k in n.items()}

    def clips(self, split: str | None = None) -> list[str]:
        return list(self._ids.get(split, []))

    def load(self, clip_id: str) -> MotionSequence:
        # crc32, not hash(): str hashes change with PYTHONHASHSEED, so the clips would differ run to run
        return synthetic_motion(zlib.crc32(clip_id.encode()) % 10_000, T=36 + len(clip_id) % 7)


def tiny_cfg(**kw) -> EmposeConfig:
    return EmposeConfig.preset("tiny", 12).override(**kw)


# --------------------------------------------------------------------------- sensor model
def test_virtual_sensors_reproduce_the_simulator(body: BodyModel) -> None:
    """sigma(Omega_gt, O_p) equals the noise-free simulated measurements (so L_r = 0 at the truth)."""
    cfg = tiny_cfg()
    r = simulate_clip(synthetic_motion(1), cfg, body, seed=3, noise="none")
    sites, src = _sites(cfg.kit, body)
    vs = VirtualSensors(body, sites, src)
    T, S = r["position"].shape[:2]
    p, R, J = vs(r["pose"], r["betas"].expand(T, 10), r["off_R"].expand(T, S, 3, 3), r["off_t"].expand(T, S, 3))
    assert (p - r["position"]).abs().max() < 1e-4  # m
    assert (R - r["orientation"]).abs().max() < 1e-4
    assert torch.allclose(J, r["joints"], atol=1e-5)
    # Offsets matter: identity offsets do not explain the data.
    p0, _, _ = vs(r["pose"], r["betas"].expand(T, 10), torch.eye(3).expand(T, S, 3, 3), torch.zeros(T, S, 3))
    assert (p0 - r["position"]).norm(dim=-1).mean() > 5e-3


# --------------------------------------------------------------------------- config / registry / types
def test_presets_follow_table5() -> None:
    p12, p6 = EmposeConfig.preset("paper", 12), EmposeConfig.preset("paper", 6)
    assert (p12.hidden, p12.width, p12.mlp_layers, p12.iterations, p12.alpha, p12.batch_size, p12.seq_len) == \
        (512, 512, 5, 4, 0.1, 12, 32)
    assert (p12.lr, p12.dropout_input, p12.dropout_mlp, p12.lambda_pose, p12.lambda_joints, p12.lambda_rec) == \
        (1e-4, 0.2, 0.2, 1.0, 1.0, 0.01)
    assert p12.rep == "axis_angle" and EmposeConfig.preset("cpu", 12).rep == "rot6d"
    assert (p6.iterations, p6.lr, p6.dropout_mlp, p6.lambda_pose, p6.lambda_joints, p6.kit) == (2, 5e-4, 0.0, 10.0, 0.1, "em6")
    assert EmposeConfig.preset("cpu", 12).override(hidden=64).hidden == 64
    with pytest.raises(ConfigError):
        EmposeConfig.preset("huge", 12)
    with pytest.raises(ConfigError, match="unknown fields"):
        EmposeConfig.from_dict({"sensors": 12, "bogus": 1})
    assert len(PRED_JOINTS) == 20 and not set(PRED_JOINTS) & set(UNOBSERVED_JOINTS)


def test_registry_and_posetrack_validation() -> None:
    assert get_estimator("empose") is EmposeEstimator
    with pytest.raises(ConfigError, match="empose"):
        get_estimator("nope")
    with pytest.raises(ShapeError, match="local_rot"):
        PoseTrack(torch.zeros(3, 23, 3, 3), torch.zeros(10), None, torch.ones(3, dtype=torch.bool), 30.0)
    with pytest.raises(ShapeError, match="valid"):
        PoseTrack(torch.eye(3).expand(3, 24, 3, 3), torch.zeros(10), None, torch.ones(4, dtype=torch.bool), 30.0)


# --------------------------------------------------------------------------- checkpoints
def test_checkpoint_round_trip_and_mismatch_errors(tmp_path: Path, body: BodyModel) -> None:
    est = EmposeEstimator(tiny_cfg(), body=body)
    est.data_fingerprint, est.train_command = "abc123", "wearpose train empose --config tiny"
    path = est.save(tmp_path / "m.pt")
    back = EmposeEstimator.load(path, kit="em12", body=body)
    for (k, v), (k2, v2) in zip(est.model.state_dict().items(), back.model.state_dict().items()):
        assert k == k2 and torch.equal(v, v2)
    assert back.data_fingerprint == "abc123" and back.train_command.endswith("--config tiny")
    assert back.config == est.config and back.sensor_names == est.sensor_names
    with pytest.raises(CheckpointMismatchError, match=r"'em12'.*'em6'"):
        EmposeEstimator.load(path, kit="em6")
    ck = load_checkpoint(path)
    ck.body_asset = "smpl-neutral-v1"
    save_checkpoint(ck, tmp_path / "other_body.pt")
    with pytest.raises(CheckpointMismatchError, match=r"smpl-neutral-v1.*wearpose-anny-v1"):
        EmposeEstimator.load(tmp_path / "other_body.pt", body=body)
    ck = load_checkpoint(path)
    assert ck.meta["sites"]["right_shoulder"] == "right_shoulder"  # the asset's own shoulder site, no substitution
    ck.meta["sites"]["head"] = "sternum"
    save_checkpoint(ck, tmp_path / "other_sites.pt")
    with pytest.raises(CheckpointMismatchError, match="sternum -> head"):
        EmposeEstimator.load(tmp_path / "other_sites.pt", body=body)


# --------------------------------------------------------------------------- learning
@pytest.mark.parametrize("rep", ["rot6d", "axis_angle"])
def test_loss_decreases_on_a_fixed_batch(tmp_path: Path, body: BodyModel, rep: str) -> None:
    torch.manual_seed(0)
    cfg = tiny_cfg(rep=rep)
    data = build_split("train", cfg, body, store=FakeStore(tmp_path, {"train": 3}), cache_root=tmp_path / "c")
    batch = data.batch(data.windows(cfg.seq_len, cfg.seq_len)[:4], cfg.seq_len)
    est = EmposeEstimator(cfg, body=body)
    opt = torch.optim.Adam(est.model.parameters(), lr=3e-3)
    x = sensor_features(batch["position"], batch["orientation"])
    losses = []
    for _ in range(25):
        outs, _ = est.model(x, batch["position"], batch["orientation"], batch["off_R"], batch["off_t"], est.sensors)
        loss, parts = lgd_loss(outs, batch["pose"], batch["betas"], batch["joints"], cfg)
        opt.zero_grad()
        loss.backward()
        opt.step()
        losses.append(loss.item())
    assert all(math.isfinite(v) for v in losses)
    assert losses[-1] < 0.5 * losses[0], losses
    # The gradient of L_r reaches the update network (learned gradient descent is live).
    assert est.model.update.net[0].weight.grad is not None and est.model.update.net[0].weight.grad.abs().sum() > 0


def test_train_save_resume_estimate_and_step(tmp_path: Path, body: BodyModel) -> None:
    cfg = tiny_cfg()
    store = FakeStore(tmp_path, {"train": 4, "val": 2, "test": 1})
    kw = dict(store=store, cache_root=tmp_path / "cache", quiet=True, checkpoint_every=2)
    est = EmposeEstimator(cfg, body=body)
    run = tmp_path / "run"
    r1 = train_empose(est, run, epochs=2, max_steps=3, train_command="test", **kw)
    assert r1["steps"] == 3 and (run / "last.pt").is_file()
    assert load_checkpoint(run / "last.pt").train_state["global_step"] == 3
    # Cache hit: the second build does not re-simulate (same fingerprint, same file).
    assert len(list((tmp_path / "cache").glob("train-*.pt"))) == 1
    est2 = EmposeEstimator(cfg, body=body)
    r2 = train_empose(est2, run, epochs=2, resume=True, **kw)
    assert r2["steps"] > 3 and len(r2["history"]) == 2 and (run / "best.pt").is_file()
    rows = [json.loads(line) for line in (run / "log.jsonl").read_text().splitlines()]
    assert [r["epoch"] for r in rows if r["type"] == "epoch"] == [1, 2]
    assert all(math.isfinite(r["val_mpjpe_mm"]) for r in rows if r["type"] == "epoch")

    best = EmposeEstimator.load(run / "best.pt", kit="em12", body=body)
    assert best.data_fingerprint and best.train_command == "test"
    clip = simulate_clip(store.load("synthetic/test_00"), cfg, body, seed=11, noise="default")
    rec = recording_from_clip(clip, cfg)
    track = best.estimate(rec)
    T = clip["position"].shape[0]
    assert track.local_rot.shape == (T, 24, 3, 3) and track.betas.shape == (10,) and track.trans is None
    assert torch.allclose(track.local_rot.transpose(-1, -2) @ track.local_rot, torch.eye(3).expand(T, 24, 3, 3), atol=1e-4)
    assert torch.equal(track.local_rot[:, list(UNOBSERVED_JOINTS)], torch.eye(3).expand(T, 4, 3, 3))
    assert torch.equal(track.valid, clip["valid"].all(1)) and track.extras["frame"] == "em_source"
    # Online = offline for this causal model (LSTM state carried, LGD per frame).
    best.reset()
    best.set_offsets(clip["off_R"], clip["off_t"])
    online = torch.stack([best.step(f).local_rot for f in iter_frames(rec, best.sensor_names)])
    assert torch.allclose(online, track.local_rot, atol=1e-4)

    res = evaluate_empose(best, split="test", store=store)
    assert res["clips"] == 1 and math.isfinite(res["mpjpe_mm"]) and res["mpjpe_mm"] > 0


def test_to_world_recovers_the_world_motion(body: BodyModel) -> None:
    """Source-frame ground truth placed with the true source pose gives back the world motion."""
    cfg = tiny_cfg()
    est = EmposeEstimator(cfg, body=body)
    clip = simulate_clip(synthetic_motion(4, T=15), cfg, body, seed=2, noise="none")
    T = clip["pose"].shape[0]
    track = PoseTrack(clip["pose"], clip["betas"], None, torch.ones(T, dtype=torch.bool), cfg.rate,
                      extras={"frame": "em_source"})
    src = clip["sim"].em_source[cfg.rate]
    world = est.to_world(track, src["orientation"], src["position"])
    m = clip["motion"]
    assert torch.allclose(world.local_rot[:, 0], m.pose[:, 0], atol=1e-4)
    assert torch.allclose(world.trans, m.trans, atol=1e-4)
    assert world.extras["frame"] == "world"


def test_estimate_rejects_wrong_sensors_and_rate(body: BodyModel) -> None:
    cfg = tiny_cfg()
    est = EmposeEstimator(cfg, body=body)
    clip = simulate_clip(synthetic_motion(2, T=12), cfg, body, seed=1)
    rec = recording_from_clip(clip, cfg)
    with pytest.raises(ShapeError, match="head"):
        est.estimate(rec.select([n for n in rec.names if n != "head"]))
    clip60 = simulate_clip(synthetic_motion(2, T=12), cfg.override(rate=60.0), body, seed=1)
    with pytest.raises(ShapeError, match="60"):
        est.estimate(recording_from_clip(clip60, cfg.override(rate=60.0)))


def test_missing_offsets_warn_and_fall_back_to_identity(body: BodyModel) -> None:
    cfg = tiny_cfg()
    est = EmposeEstimator(cfg, body=body)
    rec = recording_from_clip(simulate_clip(synthetic_motion(5, T=10), cfg, body, seed=1), cfg)
    rec.subject.pop("offsets")
    with pytest.warns(UserWarning, match="no subject offsets"):
        track = est.estimate(rec)
    assert track.num_frames == 10
    rec.subject["offsets"] = {"R": [[0.0]]}
    with pytest.raises(ShapeError, match="translation_mean_m"):
        est.estimate(rec)
