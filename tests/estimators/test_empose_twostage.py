"""EM-POSE two-stage model (joint mapper + LGD IK, supp. Sec. 9): pieces, tiny training, estimate
with dropped sensors. Synthetic motion, tiny preset, a few seconds."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
import torch

from test_empose import FakeStore, synthetic_motion  # tests/estimators is on sys.path (pytest rootdir mode)
from wearpose.body import BodyModel
from wearpose.errors import ConfigError
from wearpose.estimators import get_estimator
from wearpose.estimators.empose.baselines import OfflineOnlyError, load_any
from wearpose.estimators.empose.data import build_split, recording_from_clip, simulate_clip
from wearpose.estimators.empose.model import PRED_JOINTS
from wearpose.estimators.checkpoint import CheckpointMismatchError, load_checkpoint, save_checkpoint
from wearpose.estimators.empose.train import train_empose
from wearpose.estimators.empose.twostage import (
    FK_JOINT_WEIGHT, MAP_JOINT_WEIGHT, MAX_REMOVED, JointSensors, TwoStageEstimator, closed_form_pose, fit_betas,
    masked_features, polish_pose, removal_mask, site_poses, twostage_config, warm_start,
)


def test_removal_mask_removes_one_to_three_sensors_for_half_the_window() -> None:
    g = torch.Generator().manual_seed(0)
    keep = removal_mask(200, 16, 12, g)
    removed = (~keep).any(1).sum(-1)  # sensors removed per window
    assert int(removed.max()) <= MAX_REMOVED and 0.6 < float((removed > 0).float().mean()) < 0.95
    w = int(torch.nonzero(removed > 0)[0, 0])
    s = int(torch.nonzero((~keep[w]).any(0))[0, 0])
    assert int((~keep[w, :, s]).sum()) == 8  # half of 16 frames, one contiguous span
    span = torch.nonzero(~keep[w, :, s])[:, 0]
    assert int(span.max() - span.min()) == 7


def test_masked_features_zero_unavailable_sensors_even_nan() -> None:
    p = torch.randn(4, 2, 3)
    R = torch.eye(3).expand(4, 2, 3, 3).clone()
    p[1, 0] = float("nan")
    avail = torch.ones(4, 2, dtype=torch.bool)
    avail[1, 0] = False
    f = masked_features(p, R, avail).reshape(4, 2, 12)
    assert torch.isfinite(f).all() and (f[1, 0] == 0).all() and (f[1, 1] != 0).any()


def test_joint_sensors_are_joints_and_global_rotations(body: BodyModel) -> None:
    m = synthetic_motion(2, T=5)
    p, R, J = JointSensors(body)(m.pose, m.betas.expand(5, 10))
    out = body(m.pose, m.betas, None, return_vertices=False)
    assert torch.allclose(p, out.joints[:, list(PRED_JOINTS)]) and torch.allclose(R, out.global_rot[:, list(PRED_JOINTS)])


def test_config_and_registry() -> None:
    cfg = twostage_config("cpu", 12)
    assert cfg.model == "twostage" and cfg.iterations == 2
    with pytest.raises(ConfigError):
        TwoStageEstimator(twostage_config("cpu", 12).override(model="lgd"))
    assert get_estimator("empose-twostage") is TwoStageEstimator


def test_tiny_training_and_estimate_with_dropped_sensors(tmp_path: Path, body: BodyModel) -> None:
    cfg = twostage_config("tiny", 12)
    est = TwoStageEstimator(cfg, body=body)
    store = FakeStore(tmp_path, {"train": 3, "val": 1})
    res = train_empose(est, tmp_path / "run", epochs=1, max_steps=3, store=store, cache_root=tmp_path / "cache", quiet=True)
    assert res["steps"] == 3 and (tmp_path / "run" / "last.pt").is_file()
    rec = _dropped_recording(cfg, body)
    track = est.estimate(rec)
    assert track.local_rot.shape == (20, 24, 3, 3) and bool(track.valid.all())
    assert torch.isfinite(track.local_rot).all() and torch.isfinite(track.betas).all()
    assert not bool(track.extras["sensors_valid"][5:13, 3].any())
    loaded = load_any(tmp_path / "run" / "last.pt")
    assert isinstance(loaded, TwoStageEstimator)
    assert torch.allclose(loaded.estimate(rec).local_rot, track.local_rot, atol=1e-5)
    with pytest.raises(OfflineOnlyError):
        est.step(None)


def test_drop_sensors_and_table10_evaluation(tmp_path: Path, body: BodyModel) -> None:
    from wearpose.estimators.empose import EmposeConfig, EmposeEstimator
    from wearpose.estimators.empose.evaluate import drop_sensors, evaluate_dropped, table10_markdown

    cfg = EmposeConfig.preset("tiny", 12)
    r = simulate_clip(synthetic_motion(3, T=120), cfg, body, seed=2, noise="none")
    rec = recording_from_clip(r, cfg)
    names = [s.name for s in rec.sensors if s.kind == "em6dof"][:12]
    new, removed = drop_sensors(rec, names, torch.Generator().manual_seed(0))
    per_frame = removed.sum(1)
    assert int(per_frame.max()) <= 2 and 0.2 < float((per_frame > 0).float().mean()) < 0.9
    grid = new.on_common_grid(names)
    assert np.array_equal(~grid.valid, removed.numpy())  # noise-free: only our removals
    assert np.isnan(grid.channels["position"][~grid.valid]).all()
    # The same generator seed gives the same removals (a reproducible table).
    assert torch.equal(drop_sensors(rec, names, torch.Generator().manual_seed(0))[1], removed)
    store = FakeStore(tmp_path, {"test": 1})
    res = evaluate_dropped({"LGD-RNN": EmposeEstimator(cfg, body=body),
                            "2-stage": TwoStageEstimator(twostage_config("tiny", 12), body=body)}, store=store)
    c = res["frame_counts"]
    assert c["all"] == c["avail"] + c["miss"] and c["miss"] >= c["miss1"] + c["miss2"] > 0
    for m in res["models"].values():
        assert set(m["sets"]) == {"all", "avail", "miss", "miss1", "miss2"}
        assert m["sets"]["all"]["mpjpe_mm"] > 0
    assert "| miss | 2-stage |" in table10_markdown(res)


# --------------------------------------------------------------------------- ik="closed"
def _posed(body: BodyModel, seed: int, T: int = 12) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """A synthetic motion with non-zero betas: local rotations with identity feet/hands, betas,
    joints (T, 20, 3) and global orientations (T, 20, 3, 3) of PRED_JOINTS."""
    m = synthetic_motion(seed, T=T)
    pose = m.pose.clone()
    pose[:, [10, 11, 22, 23]] = torch.eye(3)  # not mapped: the closed form gives them identity
    out = body(pose, m.betas, None, return_vertices=False)
    return pose, m.betas, out.joints[:, list(PRED_JOINTS)], out.global_rot[:, list(PRED_JOINTS)]


def test_closed_form_pose_inverts_forward_kinematics(body: BodyModel) -> None:
    pose, betas, J, G = _posed(body, 1)
    local = closed_form_pose(G)
    assert local.shape == (12, 24, 3, 3)
    assert torch.allclose(local, pose, atol=1e-4)
    assert torch.allclose(body(local, betas, None, return_vertices=False).joints[:, list(PRED_JOINTS)], J, atol=1e-5)
    # A wrong parent order would not give the pose back.
    assert not torch.allclose(closed_form_pose(G.flip(-3)), pose, atol=1e-2)


def test_fit_betas_recovers_the_shape_and_the_prior_pulls_to_the_mean(body: BodyModel) -> None:
    pose, betas, J, G = _posed(body, 2)
    b = fit_betas(body, closed_form_pose(G), J, prior=1e-9)
    assert torch.allclose(b, betas, atol=2e-3)
    assert float(fit_betas(body, closed_form_pose(G), J, prior=1e3).abs().max()) < 1e-2
    # Noise on the joints moves an unregularised fit more than a regularised one.
    Jn = J + 0.01 * torch.randn(J.shape, generator=torch.Generator().manual_seed(0))
    assert (fit_betas(body, closed_form_pose(G), Jn, prior=1e-2) - betas).norm() < (
        fit_betas(body, closed_form_pose(G), Jn, prior=1e-9) - betas).norm() + 1.0


def test_polish_pose_moves_towards_the_mapped_joints(body: BodyModel) -> None:
    from wearpose.geometry import axis_angle_to_matrix

    pose, betas, J, G = _posed(body, 3)
    g = torch.Generator().manual_seed(1)
    noisy = G @ axis_angle_to_matrix(0.15 * torch.randn(G.shape[:-1], generator=g))  # 0.15 rad per axis
    start = closed_form_pose(noisy)
    _, res0 = polish_pose(body, start, betas, J, noisy, iters=0)
    local, res = polish_pose(body, start, betas, J, noisy, iters=15, rot_weight=1e-3)
    assert float(res.mean()) < 0.5 * float(res0.mean())
    assert torch.allclose(local[:, [10, 11, 22, 23]], torch.eye(3).expand(12, 4, 3, 3), atol=1e-5)
    # Exact inputs: the closed form is already the optimum, the polish keeps it.
    exact, r = polish_pose(body, closed_form_pose(G), betas, J, G, iters=5)
    assert float(r.max()) < 1e-8 and torch.allclose(exact, pose, atol=1e-3)


def _dropped_recording(cfg, body: BodyModel):  # noqa: ANN001, ANN202
    """A 20-frame noise-free recording with sensor 3 dropped for frames 5..12 (NaN + invalid, as a
    recording marks dropped frames)."""
    r = simulate_clip(synthetic_motion(9, T=20), cfg, body, seed=4, noise="none")
    rec = recording_from_clip(r, cfg)
    s = rec.sensors[3]
    valid = s.valid.copy()
    valid[5:13] = False
    pos, ori = s.position.copy(), s.orientation.copy()
    pos[~valid], ori[~valid] = np.nan, np.nan
    return dataclasses.replace(rec, sensors=[*rec.sensors[:3], dataclasses.replace(s, valid=valid, position=pos,
                                                                                    orientation=ori), *rec.sensors[4:]])


def test_tiny_training_closed_ik_and_warm_start(tmp_path: Path, body: BodyModel) -> None:
    cfg = twostage_config("tiny", 12)
    store = FakeStore(tmp_path, {"train": 3, "val": 1})
    lgd = TwoStageEstimator(cfg, body=body)
    train_empose(lgd, tmp_path / "lgd", epochs=1, max_steps=2, store=store, cache_root=tmp_path / "cache", quiet=True)
    est = TwoStageEstimator(cfg.override(ik="closed", mapper_input="site"), body=body)
    assert est.model.ik is None
    opt = warm_start(est, tmp_path / "lgd" / "last.pt")
    assert opt is not None and len(opt["state"]) == len(list(est.model.parameters()))
    for k, v in est.model.mapper.state_dict().items():
        assert torch.equal(v, lgd.model.mapper.state_dict()[k])
    lgd.save(tmp_path / "plain.pt")
    assert warm_start(est, tmp_path / "plain.pt") is None  # no optimizer state (like best.pt)
    res = train_empose(est, tmp_path / "closed", epochs=1, max_steps=3, store=store, cache_root=tmp_path / "cache",
                       quiet=True)
    assert res["steps"] == 3
    data = build_split("train", est.config, body, store=store, cache_root=tmp_path / "cache")
    loss, parts = est.make_task(data, None).loss(next(data.iter_batches(8, 8, 2, shuffle=False)), torch.device("cpu"))
    assert parts["fk_joints"] > 0 and "pose" not in parts  # the FK joint term, no stage-2 LGD loss
    assert float(loss.detach()) == pytest.approx(MAP_JOINT_WEIGHT * parts["map_joints"] + parts["map_rot"]
                                        + FK_JOINT_WEIGHT * parts["fk_joints"], rel=1e-4)
    rec = _dropped_recording(cfg, body)
    track = est.estimate(rec)
    assert track.local_rot.shape == (20, 24, 3, 3) and bool(track.valid.all()) and track.extras["ik"] == "closed"
    assert torch.isfinite(track.local_rot).all() and track.betas.shape == (10,)
    loaded = load_any(tmp_path / "closed" / "last.pt")
    assert loaded.config.ik == "closed" and loaded.config.mapper_input == "site" and loaded.model.ik is None
    assert torch.allclose(loaded.estimate(rec).local_rot, track.local_rot, atol=1e-5)
    with pytest.raises(CheckpointMismatchError):
        warm_start(TwoStageEstimator(cfg.override(hidden=48), body=body), tmp_path / "lgd" / "last.pt")


def test_checkpoint_without_ik_field_loads_as_the_lgd_ik(tmp_path: Path, body: BodyModel) -> None:
    """Checkpoints written before ``EmposeConfig.ik`` existed load and estimate as before."""
    est = TwoStageEstimator(twostage_config("tiny", 12), body=body)
    ck = est.checkpoint()
    ck.config.pop("ik")
    ck.config.pop("mapper_input")
    save_checkpoint(ck, tmp_path / "old.pt")
    assert "ik" not in load_checkpoint(tmp_path / "old.pt").config
    old = load_any(tmp_path / "old.pt")
    assert old.config.ik == "lgd" and old.config.mapper_input == "raw" and old.model.ik is not None
    rec = _dropped_recording(est.config, body)
    assert torch.allclose(old.estimate(rec).local_rot, est.estimate(rec).local_rot, atol=1e-6)


def test_zero_dropped_and_the_zeros_rows(tmp_path: Path, body: BodyModel) -> None:
    from wearpose.estimators.empose import EmposeConfig, EmposeEstimator
    from wearpose.estimators.empose.evaluate import evaluate_dropped, table10_markdown, zero_dropped

    cfg = EmposeConfig.preset("tiny", 12)
    rec = _dropped_recording(cfg, body)
    names = [s.name for s in rec.sensors if s.kind == "em6dof"][:12]
    z = zero_dropped(rec, names).on_common_grid(names)
    assert z.valid.all() and (z.channels["position"][5:13, 3] == 0).all() and np.allclose(z.channels["orientation"][5:13, 3], np.eye(3))
    assert (z.channels["position"][:5, 3] != 0).any()
    lgd = EmposeEstimator(cfg, body=body)
    store = FakeStore(tmp_path, {"test": 1})
    res = evaluate_dropped({"LGD-RNN": lgd, "LGD-RNN zeros": lgd}, store=store, zeros=["LGD-RNN zeros"])
    a, b = res["models"]["LGD-RNN"], res["models"]["LGD-RNN zeros"]
    assert a["dropped_input"] == "missing" and b["dropped_input"] == "zeros"
    assert a["sets"]["miss"]["mpjpe_mm"] != b["sets"]["miss"]["mpjpe_mm"]
    md = table10_markdown(res)
    assert "| miss | LGD-RNN zeros |" in md and "| all | LGD-RNN zeros | " in md
    zrow = next(ln for ln in md.splitlines() if ln.startswith("| miss | LGD-RNN zeros |"))
    assert "**" not in zrow and "*" in zrow
    with pytest.raises(ConfigError):
        evaluate_dropped({"LGD-RNN": lgd}, store=store, zeros=["nope"])


def test_site_poses_undo_the_subject_offsets(body: BodyModel) -> None:
    """Noise-free simulated measurements + the recording's offsets -> the skin sites the body model
    puts there (source frame), i.e. what the LGD-RNN's sensors give with identity offsets."""
    from wearpose.estimators.empose import EmposeConfig, EmposeEstimator

    cfg = EmposeConfig.preset("tiny", 12)
    r = simulate_clip(synthetic_motion(5, T=6), cfg, body, seed=3, noise="none")
    lgd = EmposeEstimator(cfg, body=body)
    S = len(lgd.sensor_names)
    ps, Rs = site_poses(r["position"], r["orientation"], r["off_R"], r["off_t"])
    p0, R0, _ = lgd.sensors(r["pose"], r["betas"].expand(6, 10), torch.eye(3).expand(6, S, 3, 3), torch.zeros(6, S, 3))
    assert torch.allclose(ps, p0, atol=2e-3) and torch.allclose(Rs, R0, atol=2e-3)
    # The offsets are not negligible: the raw measurements are farther from the sites.
    assert float((r["position"] - p0).norm(dim=-1).max()) > 5e-3
