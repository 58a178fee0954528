"""MI-Poser: data synthesis + calibration, features, IK network, estimator (offline/online), IMU baseline."""

from __future__ import annotations

import warnings

import pytest
import torch

from miposer_testutils import FakeStore, synthetic_motion
from wearpose.errors import ConfigError
from wearpose.estimators import get_estimator
from wearpose.estimators.checkpoint import CheckpointMismatchError
from wearpose.estimators.miposer import MiposerConfig, MiposerEstimator, frames, train_miposer
from wearpose.estimators.miposer.data import build_split, calibrated_inputs, raw_inputs, simulate_clip, tpose_then, uncalibrated
from wearpose.estimators.miposer.evaluate import ErrorTable, evaluate_miposer, format_fig5
from wearpose.motion.store import motion_class
from wearpose.estimators.miposer.model import window_features
from wearpose.geometry import geodesic_angle, rotation_y

TINY = MiposerConfig.preset("tiny")


def test_presets_and_errors():
    cpu = MiposerConfig.preset("cpu")
    assert (cpu.layers, cpu.d_model, cpu.window, cpu.rate) == (3, 256, 40, 60.0)
    paper = MiposerConfig.preset("paper")
    assert paper.batch_size == 32 and paper.lr == 1e-3 and paper.stride == 6 and not paper.dense
    assert MiposerConfig.preset("cpu", wrists=1).kit == "miposer1"
    assert MiposerConfig.preset("cpu", model="imuposer").kit == "imu3-head-wrists"
    with pytest.raises(ConfigError, match="preset"):
        MiposerConfig.preset("huge")
    with pytest.raises(ConfigError, match="wrists"):
        MiposerConfig(wrists=3)
    with pytest.raises(ConfigError, match="unknown fields"):
        MiposerConfig.from_dict({"nope": 1})


def test_registry_names():
    assert get_estimator("miposer") is MiposerEstimator
    assert get_estimator("imuposer").__name__ == "ImuPoserEstimator"


def test_tpose_prefix_faces_the_clip_heading():
    m = synthetic_motion(3, 1.0)
    mm, prefix = tpose_then(m, 0.5, 0.25)
    assert prefix == 45 and mm.num_frames == m.num_frames + 45
    assert torch.allclose(mm.pose[prefix:], m.pose)
    # T-pose (identity body joints), root turned to the clip's first heading about +Y only.
    assert torch.allclose(mm.pose[0, 1:], torch.eye(3).expand(23, 3, 3), atol=1e-6)
    f0, fm = m.pose[0, 0, :, 2], mm.pose[0, 0, :, 2]
    assert abs(float(mm.pose[0, 0, 1, 1]) - 1.0) < 1e-6
    assert abs(float(torch.atan2(f0[0], f0[2]) - torch.atan2(fm[0], fm[2]))) < 1e-5


def test_calibrated_inputs_are_the_target_joints(body):
    """Noise-free: the calibrated head / wrist inputs equal SMPL joints 15/20/21 (positions, head-relative)
    and the head / forearm rotations, up to the skin site sliding on the body."""
    cfg = TINY.override(tpose_s=0.5)
    r = simulate_clip(synthetic_motion(5, 1.5), cfg, body, seed=1, noise="none")
    # The wearer is the model; the random EM sensor offsets (a few mm off the wrist sites) move the span a little.
    assert abs(r["calibration"].scale - 1.0) < 0.02
    out = body(r["pose"], None, None, return_vertices=False)
    rel = (r["p"][:, 1:] - r["p"][:, :1]) - (out.joints[:, [20, 21]] - out.joints[:, [15]])
    assert rel.norm(dim=-1).max() < 0.03
    rot = torch.rad2deg(geodesic_angle(r["R"], out.global_rot[:, [15, 18, 19]]))
    # head: only the heading of the world alignment, taken from the offset wrist sensors (< 1 deg)
    assert rot[:, 0].max() < 1.0 and rot.max() < 6.0
    # Without calibration the same data is far off (sensor frames and lever arms not removed).
    Ru, pu = calibrated_inputs(r["raw"], uncalibrated(r["calibration"]))
    assert torch.rad2deg(geodesic_angle(Ru, out.global_rot[:, [15, 18, 19]])).median() > 10.0


def test_features_invariant_to_heading_and_floor_position():
    g = torch.Generator().manual_seed(0)
    R = torch.linalg.qr(torch.randn(2, 6, 3, 3, 3, generator=g)).Q
    R = R * torch.linalg.det(R)[..., None, None]
    p = torch.randn(2, 6, 3, 3, generator=g)
    C = rotation_y(torch.tensor(1.1))
    shift = torch.tensor([0.7, 0.0, -2.0])
    x1, _, _ = window_features(R, p, 60.0)
    x2, _, _ = window_features(C @ R, p @ C.T + shift, 60.0)
    assert torch.allclose(x1, x2, atol=1e-5)
    x3, _, _ = window_features(R, p + torch.tensor([0.0, 0.3, 0.0]), 60.0)  # height is kept
    assert not torch.allclose(x1, x3, atol=1e-3)


@pytest.fixture(scope="module")
def trained(tmp_path_factory, body):
    tmp = tmp_path_factory.mktemp("mp")
    est = MiposerEstimator(TINY, body=body)
    res = train_miposer(est, tmp / "run", store=FakeStore(tmp, n=1, seconds=1.0), cache_root=tmp / "cache", max_steps=8,
                        quiet=True, epochs=20, limit_val=1)
    return est, res, tmp


def test_training_reduces_the_loss(trained):
    _, res, tmp = trained
    import json

    rows = [json.loads(l) for l in (tmp / "run" / "log.jsonl").read_text().splitlines()]
    ep = [r for r in rows if r["type"] == "epoch"]
    assert len(ep) >= 2 and ep[-1]["train_loss"] < ep[0]["train_loss"]
    assert (tmp / "run" / "best.pt").is_file() and (tmp / "run" / "last.pt").is_file()


def test_checkpoint_roundtrip_and_kit_check(trained, tmp_path, body):
    est, _, _ = trained
    path = est.save(tmp_path / "m.pt")
    back = MiposerEstimator.load(path, body=body)
    R = torch.eye(3).expand(30, 3, 3, 3).clone()
    p = torch.randn(30, 3, 3)
    a, b = est.infer(R, p), back.infer(R, p)
    assert torch.allclose(a[0], b[0]) and torch.allclose(a[1], b[1])
    with pytest.raises(CheckpointMismatchError):
        MiposerEstimator.load(path, kit="miposer1")


def test_offline_equals_online_and_frame_subsets(trained, body):
    est, _, _ = trained
    r = simulate_clip(synthetic_motion(11, 1.0), est.config, body, seed=4, native_rates=True)
    rec = r["recording"]
    track = est.estimate(rec, calibration=r["calibration"])
    T = track.num_frames
    assert track.local_rot.shape == (T, 24, 3, 3) and track.trans.shape == (T, 3)
    assert track.extras["frame"] == "calibrated"
    # online == offline (same causal window, same calibration)
    est.reset()
    est.set_calibration(r["calibration"])
    outs = [est.step(f) for f in frames(rec, est.kit_name)]
    assert len(outs) == T
    on = torch.stack([o.local_rot for o in outs])
    assert torch.rad2deg(geodesic_angle(on, track.local_rot)).max() < 0.05
    assert torch.allclose(torch.stack([o.trans for o in outs]), track.trans, atol=1e-4)
    # a subset of frames gives the same estimates there
    raw = raw_inputs(rec, est.kit_name)
    Rc, pc = calibrated_inputs(raw, r["calibration"])
    f = torch.tensor([0, 7, T - 1])
    sub, _ = est.infer(Rc, pc, f)
    assert torch.rad2deg(geodesic_angle(sub, track.local_rot[f])).max() < 1e-3


def test_estimate_calibration_sources(trained, body):
    from wearpose.calibration import store_calibration

    est, _, _ = trained
    r = simulate_clip(synthetic_motion(12, 0.6), est.config, body, seed=2, native_rates=True)
    a = est.estimate(store_calibration(r["recording"], r["calibration"]))
    b = est.estimate(r["recording"], calibration_window=tuple(r["calibration"].params["window"]))
    assert torch.rad2deg(geodesic_angle(a.local_rot, b.local_rot)).max() < 0.01
    with pytest.warns(UserWarning, match="no calibration"):
        est.estimate(r["recording"])
    with pytest.raises(Exception, match=r"a recording not loaded from a file \(made in memory\): no sensors \["):
        est.estimate(r["recording"].select(["head_vio"]))


def test_evaluate_and_table(trained, tmp_path):
    est, _, _ = trained
    res = evaluate_miposer({"m": est}, limit=1, store=FakeStore(tmp_path, n=1, seconds=1.0), frame_stride=3)
    s = res["models"]["m"]["calibrated"]
    assert s["frames"] > 0 and set(s["per_joint_cm"]) >= {"pelvis", "head", "left_wrist"}
    assert s["per_joint_cm"]["pelvis"] == 0.0  # root-aligned
    assert "| head |" in format_fig5(res)
    assert motion_class({"description": "wave-left-hand (style: x)"}) == "wave-left-hand"
    assert ErrorTable().summary() == {"frames": 0}


def test_smartwatch_variant_shapes(body, tmp_path):
    est = MiposerEstimator(MiposerConfig.preset("tiny", wrists=1), body=body)
    assert est.kit_name == "miposer1" and len(est.sensor_names) == 3
    r = simulate_clip(synthetic_motion(2, 0.6), est.config, body, seed=0, native_rates=True)
    assert r["R"].shape[1] == 2
    track = est.estimate(r["recording"], calibration=r["calibration"])
    assert track.local_rot.shape[0] == r["R"].shape[0]


def test_imuposer_baseline(body, tmp_path):
    from wearpose.estimators.empose.baselines import OfflineOnlyError
    from wearpose.estimators.miposer.baselines import ImuPoserEstimator, simulate_imu_clip

    cfg = MiposerConfig.preset("tiny", model="imuposer")
    est = ImuPoserEstimator(cfg, body=body)
    res = train_miposer(est, tmp_path / "run", store=FakeStore(tmp_path, n=2), cache_root=tmp_path / "c", max_steps=6,
                        quiet=True, epochs=10)
    assert res["steps"] == 6
    r = simulate_imu_clip(synthetic_motion(1, 1.0), cfg, body, seed=0)
    rot = est.infer(r["R"], r["a"])
    assert rot.shape == (60, 24, 3, 3)
    with pytest.raises(OfflineOnlyError):
        est.step(None)
    back = ImuPoserEstimator.load(est.save(tmp_path / "i.pt"), body=body)
    assert torch.allclose(back.infer(r["R"], r["a"]), rot)


def test_mim_glue_offline_and_online(trained, body):
    """MIM on the interfered wrist EM of a short clip: the recording path and the online path run,
    report per-frame flags, and leave interference-free streams (almost) untouched."""
    pytest.importorskip("wearpose.interference")
    from wearpose.estimators.miposer.evaluate import interference_recording
    from wearpose.estimators.miposer.mim import mitigate_recording
    from wearpose.interference import MIMConfig, simulate_condition

    est, _, _ = trained
    mm, prefix = tpose_then(synthetic_motion(8, 0.5), 0.5, 0.25)
    cs = simulate_condition(mm, "open-space", sensors=("left_wrist", "right_wrist"), seed=1, body=body)
    imu = {"left_wrist_em": (cs["left_wrist"].gyro, cs["left_wrist"].acc),
           "right_wrist_em": (cs["right_wrist"].gyro, cs["right_wrist"].acc)}
    rec = interference_recording(mm, est, cs, "true", seed=0)
    cfg = MIMConfig(position="odometry")
    out, info = mitigate_recording(rec, est.kit_name, cfg, imu)
    flags = info["left_wrist_em"]["interfered"]
    assert flags.shape == (rec.sensor("left_wrist_em").num_frames,) and flags.mean() < 0.2
    d = abs(out.sensor("left_wrist_em").position - rec.sensor("left_wrist_em").position).max()
    assert d < 0.02
    # the recording-derived IMU path runs too (no imu= given)
    _, info2 = mitigate_recording(rec, est.kit_name, cfg)
    assert "right_wrist_em" in info2
    on = MiposerEstimator(est.config, body=body, mim=True, mim_config=cfg)
    on.model.load_state_dict(est.model.state_dict())
    on.reset()
    o = [on.step(f) for f in list(frames(rec, est.kit_name))[:5]]
    assert set(o[-1].extras["interference"]) == {"left_wrist_em", "right_wrist_em"}


def test_room_fixed_source_reaches_the_estimator_through_the_headset(trained, body):
    """End-to-end with a room-fixed source (User Study 2): the EM poses are re-expressed relative
    to the headset through its VIO pose, so composing them back (raw_inputs) gives the room-fixed
    measurement in the headset's world."""
    pytest.importorskip("wearpose.interference")
    import numpy as np

    from wearpose.estimators.miposer.evaluate import interference_recording, world_source_pose
    from wearpose.interference import simulate_condition

    est, _, _ = trained
    mm, _ = tpose_then(synthetic_motion(8, 0.5), 0.5, 0.25)
    sp = world_source_pose(mm, body)
    cs = simulate_condition(mm, "open-space", sensors=("left_wrist", "right_wrist"), seed=1, body=body,
                            source="world", source_pose=sp)
    rec = interference_recording(mm, est, cs, "true", seed=0, source_pose=sp)
    raw = raw_inputs(rec, est.kit_name, est.fps)
    T = raw["p"].shape[0]
    pw = cs["left_wrist"].p_true[: 2 * T: 2] + sp[1]  # world-aligned source: world = source offset
    np.testing.assert_allclose(raw["p"][:, 1].numpy()[: len(pw)], pw[: T], atol=1e-4)


@pytest.mark.budget(30)  # MIM / the interference simulator per frame on a shared 2-core machine
def test_the_protocol_reports_interference_detection(corpus_store) -> None:  # noqa: ANN001
    """``wearpose evaluate miposer_cpu``'s detection part (MI-Poser Table 3) on one clip."""
    from wearpose.estimators.miposer.entry import DETECTION_E_P_CM, protocol
    from wearpose.interference import study
    from wearpose.motion import CorpusStore

    store = CorpusStore(corpus_store)
    est = MiposerEstimator(MiposerConfig.preset("tiny"))
    ids = store.clips(split="test")[:1]
    res = protocol(est, store, "test", 1, 0, "default", None, frame_stride=8)
    d = res["detail"]["detection"]
    assert res["metrics"]["detection_positive_ratio_at_10cm"] == d["metrics"]["10"]["positive_ratio"]
    assert "Table 3" in res["protocol"]
    assert d["threshold_deg"] == 5.0 and d["condition"] == "standard" and d["wrists"] + d["out_of_range"] == 2, d
    clips, _ = study.world_clips(((c, store.load(c)) for c in ids), "test", "standard", est.body)
    assert d["metrics"] == {f"{e:g}": study.detection_metrics(clips, 5.0, e) for e in DETECTION_E_P_CM}
    assert d["metrics"]["2"]["frames"] == sum(len(c["p"]) for c in clips) > 0
