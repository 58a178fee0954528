"""PIP kinematics module: input normalisation, targets (Eq. 14, contact labels), the RNN chain
(shapes, causality, learned initialisation), the cumulative velocity loss, training, and the
estimator protocol without physics. Synthetic motion, tiny preset, one thread."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
import torch

from tests.sensors.sensor_testutils import smooth_motion
from wearpose.errors import ConfigError, ShapeError
from wearpose.estimators import PoseTrack, SensorFrame, get_estimator
from wearpose.estimators.pip import PipConfig, PipEstimator, PipNet, cumulative_velocity_loss, imu_features, pip_loss
from wearpose.estimators.pip.data import (
    FOOT_JOINTS, LEAF_JOINTS, build_split, root_frame_targets, simulate_clip,
)
from wearpose.estimators.pip.model import run_windows
from wearpose.estimators.pip.train import train_pip
from wearpose.geometry import axis_angle_to_matrix, geodesic_angle, rotation_y
from wearpose.motion import MotionSequence


def tiny(**kw) -> PipConfig:
    return PipConfig.preset("tiny").override(**kw)


def motion(seed: int = 0, T: int = 60) -> MotionSequence:
    return smooth_motion(T=T, fps=60.0, seed=seed, amp=0.3).to(torch.float32)


class FakeStore:
    """Duck-typed CorpusStore over synthetic clips."""

    def __init__(self, root: Path, n: dict[str, int]) -> None:
        self.root = root
        self._ids = {s: [f"synthetic/{s}_{i:02d}" for i in range(k)] for s, k in n.items()}

    def clips(self, split: str | None = None) -> list[str]:
        return list(self._ids.get(split, []))

    def load(self, clip_id: str) -> MotionSequence:
        return motion(sum(map(ord, clip_id)) % 1000, T=50 + len(clip_id) % 5)


def test_presets_and_config_errors() -> None:
    p = PipConfig.preset("paper")
    assert (p.hidden, p.rnn_layers, p.dropout, p.seq_len, p.batch_size) == (256, 2, 0.4, 200, 256)
    assert 2 * p.rnn_layers * p.hidden == 1024  # I_PL / I_VA output: hidden + cell of 2 LSTM layers
    assert PipConfig.from_dict(PipConfig.preset("cpu").to_dict()) == PipConfig.preset("cpu")
    with pytest.raises(ConfigError):
        PipConfig.preset("huge")
    with pytest.raises(ConfigError):
        PipConfig(dropout=1.0)
    with pytest.raises(ConfigError):
        PipConfig.from_dict({"hidden": 8, "nope": 1})
    for bad in ({"aug_speed_range": (1.25, 0.8)}, {"aug_speed_range": (0.0, 1.0)}, {"aug_speed_copies": -1},
                {"sitting_stand_s": (4.0, 1.0)}, {"min_window": -1}, {"min_window": 201},
                {"sitting_window": 1}):
        with pytest.raises(ConfigError, match=next(iter(bad))):
            PipConfig(**bad)


def test_imu_features_are_root_relative() -> None:
    g = torch.Generator().manual_seed(0)
    acc = torch.randn(5, 6, 3, generator=g)
    ori = axis_angle_to_matrix(torch.randn(5, 6, 3, generator=g))
    x = imu_features(acc, ori, 30.0)
    assert x.shape == (5, 72)
    # A yaw of the whole world (heading) changes only the root orientation entries.
    Ry = rotation_y(torch.tensor(0.7))
    x2 = imu_features((Ry @ acc.unsqueeze(-1)).squeeze(-1), Ry @ ori, 30.0)
    assert torch.allclose(x[:, :63], x2[:, :63], atol=1e-5)
    assert not torch.allclose(x[:, 63:], x2[:, 63:], atol=1e-3)
    # The leading entries are R_root^T (a_0 - a_root) / 30.
    want = ori[:, 5].transpose(-1, -2) @ (acc[:, 0] - acc[:, 5]).unsqueeze(-1) / 30.0
    assert torch.allclose(x[:, :3], want.squeeze(-1), atol=1e-6)


def test_targets_eq14_and_contacts(body) -> None:
    cfg = tiny()
    T = 30
    yaw = rotation_y(torch.tensor(0.5))
    pose = torch.eye(3).repeat(T, 24, 1, 1)
    pose[:, 0] = yaw
    v = torch.tensor([0.3, 0.0, 0.0])  # m/s, world
    trans = torch.arange(T, dtype=torch.float32)[:, None] / 60.0 * v
    joints = body(pose, torch.zeros(10), trans, return_vertices=False).joints
    tg = root_frame_targets(pose, joints, 60.0, cfg)
    vel = tg["vel"].view(T, 24, 3) * cfg.vel_scale
    assert torch.allclose(vel, (yaw.T @ v).expand(T, 24, 3), atol=1e-4)  # Eq. 14: root frame
    assert tg["leaf"].shape == (T, 15) and tg["joints"].shape == (T, 69) and tg["rot6"].shape == (T, 138)
    assert bool((tg["contact"] == 1).all())  # 0.3 m/s < 0.48 m/s, feet on the lowest level
    fast = root_frame_targets(pose, body(pose, torch.zeros(10), trans * 3, return_vertices=False).joints, 60.0, cfg)
    assert bool((fast["contact"] == 0).all())  # 0.9 m/s: sliding feet are not in contact
    # One foot lifted 20 cm (static): that foot is out of contact, the other in.
    j2 = joints.clone()
    j2[:, FOOT_JOINTS[0], 1] += 0.2
    j2[:, :, 0] = joints[:1, :, 0]
    lifted = root_frame_targets(pose, j2, 60.0, cfg)["contact"]
    assert bool((lifted[:, 0] == 0).all()) and bool((lifted[:, 1] == 1).all())
    assert len(LEAF_JOINTS) == 5


def test_simulate_clip_shapes_and_trim(body) -> None:
    r = simulate_clip(motion(1, T=40), tiny(), body, seed=3)
    assert r["x"].shape == (32, 72) and r["motion"].num_frames == 32  # 4 frames cut at each end
    assert torch.isfinite(r["x"]).all()
    # The bone orientation of the pelvis sensor is the root rotation (noise 0.5 deg).
    ang = geodesic_angle(r["ori"][:, 5], r["pose"][:, 0])
    assert float(ang.max()) < math.radians(3)


def test_cumulative_velocity_loss() -> None:
    gt = torch.zeros(2, 27, 72)
    assert float(cumulative_velocity_loss(gt, gt, (1, 3, 9, 27))) == 0.0
    bias = torch.zeros(2, 27, 72)
    bias[..., 0::3] = 0.1  # a constant x error at every joint
    # window n sums n errors: |n 0.1|^2 / n = 0.01 n, summed over n
    got = float(cumulative_velocity_loss(bias, gt, (1, 3, 9, 27)))
    assert got == pytest.approx(0.01 * (1 + 3 + 9 + 27), rel=1e-5)
    # An alternating error cancels in longer windows: the loss penalises drift, not noise.
    alt = torch.zeros(2, 27, 72)
    alt[:, 0::2, 0::3] = 0.1
    alt[:, 1::2, 0::3] = -0.1
    assert float(cumulative_velocity_loss(alt, gt, (1, 3, 9, 27))) < got / 5


def test_padded_windows_cover_short_clips_and_tails() -> None:
    from wearpose.estimators.pip.data import TENSORS, PipData
    from wearpose.estimators.pip.sitting import sitting_clip_id

    lengths = [5, 12, 30]  # shorter than min_len, shorter than seq_len, longer with a tail
    F = sum(lengths)
    data = PipData(**{k: torch.arange(F, dtype=torch.float32)[:, None].repeat(1, 2) for k in TENSORS},
                   starts=torch.tensor([0, 5, 17]), lengths=torch.tensor(lengths), clip_ids=["a", "b", "c"],
                   fingerprint="x", settings={})
    # min_len 0: only full windows (the old behaviour): clip c (frames 17-46) at 17 and 25, its
    # last 2 frames left out, clips a and b left out
    assert data.windows(20, 8).tolist() == [[17, 20], [25, 20]]
    w = data.windows(20, 8, min_len=6)
    # clip b whole (padded), clip c's tail gets a window ending at its last frame, clip a still out
    assert w.tolist() == [[5, 12], [17, 20], [25, 20], [27, 20]]
    b = data.batch(w)
    assert b["x"].shape == (4, 20, 2) and b["mask"].sum(1).tolist() == [12, 20, 20, 20]
    assert b["x"][0, :12, 0].tolist() == list(range(5, 17)) and (b["x"][0, 12:, 0] == 16).all()  # pads repeat
    # bucketed shuffling: every window exactly once per epoch, reproducible, skip drops batches
    got = [tuple(bb["x"][:, 0, 0].long().tolist()) for bb in data.iter_batches(20, 8, 1, torch.Generator().manual_seed(3),
                                                                                min_len=6)]
    again = [tuple(bb["x"][:, 0, 0].long().tolist()) for bb in data.iter_batches(20, 8, 1, torch.Generator().manual_seed(3),
                                                                                  min_len=6)]
    assert got == again and sorted(x for t in got for x in t) == [5, 17, 25, 27]
    skipped = [tuple(bb["x"][:, 0, 0].long().tolist()) for bb in data.iter_batches(20, 8, 1, torch.Generator().manual_seed(3),
                                                                                    min_len=6, skip=1)]
    assert skipped == got[1:]
    # sitting_len: synthetic sitting clips get their own window length (stride half of it)
    sit = PipData(**{k: torch.arange(F, dtype=torch.float32)[:, None].repeat(1, 2) for k in TENSORS},
                  starts=torch.tensor([0, 5, 17]), lengths=torch.tensor(lengths),
                  clip_ids=["a", "b", sitting_clip_id("train", 0)], fingerprint="x", settings={})
    assert sit.windows(20, 8, min_len=6, sitting_len=10).tolist() == [[5, 12], [17, 10], [22, 10], [27, 10], [32, 10],
                                                                       [37, 10]]


def test_padding_does_not_change_the_loss() -> None:
    """A window padded into a longer batch has the loss it has alone (masked means)."""
    cfg = tiny()
    torch.manual_seed(0)
    net = PipNet(cfg).eval()
    T, L = 12, 7
    b = {"x": torch.randn(1, T, 72), "leaf": torch.randn(1, T, 15), "joints": torch.randn(1, T, 69),
         "rot6": torch.randn(1, T, 138), "vel": torch.randn(1, T, 72), "contact": torch.rand(1, T, 2).round()}
    short = {k: v[:, :L] for k, v in b.items()}
    padded = {k: torch.cat([v[:, :L], v[:, L - 1:L].expand(1, T - L, v.shape[-1])], 1) for k, v in b.items()}
    padded["mask"] = torch.arange(T)[None] < L
    with torch.no_grad():
        alone, parts_alone = pip_loss(run_windows(net, short)[0], short, cfg)
        pad, parts_pad = pip_loss(run_windows(net, padded)[0], padded, cfg)
    for k in parts_alone:
        if k != "loss_vel":  # the cumulative loss chunks differently (T // n) -- compared below
            assert parts_pad[k] == pytest.approx(parts_alone[k], rel=1e-5), k
    # cumulative velocity loss: chunks of the padded window that start on valid frames count
    e = torch.randn(1, T, 72)
    full = cumulative_velocity_loss(e, torch.zeros_like(e), (1, 3))
    same = cumulative_velocity_loss(e, torch.zeros_like(e), (1, 3), torch.ones(1, T, dtype=torch.bool))
    assert float(same) == pytest.approx(float(full), rel=1e-6)
    m = torch.arange(T)[None] < 6
    assert float(cumulative_velocity_loss(e, torch.zeros_like(e), (1, 3), m)) == pytest.approx(
        float(cumulative_velocity_loss(e[:, :6], torch.zeros_like(e[:, :6]), (1, 3))), rel=1e-5)


def test_network_shapes_causality_and_init() -> None:
    torch.manual_seed(0)
    net = PipNet(tiny()).eval()
    x = torch.randn(2, 10, 72)
    leaf0, vel0 = torch.randn(2, 15), torch.randn(2, 72)
    out, states = net(x, net.initial_states(leaf0, vel0))
    assert out["leaf"].shape == (2, 10, 15) and out["joints"].shape == (2, 10, 69)
    assert out["rot6"].shape == (2, 10, 138) and out["vel"].shape == (2, 10, 72) and out["contact_logit"].shape == (2, 10, 2)
    # causal: changing frame 7 leaves frames 0..6 untouched
    x2 = x.clone()
    x2[:, 7] += 5.0
    out2, _ = net(x2, net.initial_states(leaf0, vel0))
    assert torch.allclose(out["rot6"][:, :7], out2["rot6"][:, :7]) and not torch.allclose(out["rot6"][:, 7], out2["rot6"][:, 7])
    # frame-by-frame with carried state == whole sequence
    st = net.initial_states(leaf0, vel0)
    steps = []
    for t in range(10):
        o, st = net(x[:, t:t + 1], st)
        steps.append(o["vel"])
    assert torch.allclose(torch.cat(steps, 1), out["vel"], atol=1e-5)
    # the learned initial state matters; without init nets the model has none
    out3, _ = net(x, net.initial_states(leaf0 + 1.0, vel0))
    assert not torch.allclose(out3["leaf"][:, 0], out["leaf"][:, 0])
    plain = PipNet(tiny(learned_init=False))
    assert plain.pl.init_net is None and plain.va.init_net is None
    assert plain.initial_states(leaf0, vel0) == [None] * 5


def test_training_reduces_loss_and_resumes(body, tmp_path: Path) -> None:
    store = FakeStore(tmp_path / "store", {"train": 4, "val": 2})
    cfg = tiny(lr=1e-2)
    data = build_split("train", cfg, body, store=store, cache_root=tmp_path / "cache")
    again = build_split("train", cfg, body, store=store, cache_root=tmp_path / "cache")  # cache hit
    assert torch.equal(data.x, again.x) and data.fingerprint == again.fingerprint
    torch.manual_seed(0)
    net = PipNet(cfg)
    b = data.batch(data.windows(cfg.seq_len, cfg.window_stride)[:4], cfg.seq_len)
    opt = torch.optim.Adam(net.parameters(), lr=1e-2)
    first = None
    for _ in range(40):
        loss, parts = pip_loss(run_windows(net, b)[0], b, cfg)
        first = first if first is not None else float(loss.detach())
        opt.zero_grad()
        loss.backward()
        opt.step()
    assert float(loss.detach()) < 0.5 * first, first
    est = PipEstimator(cfg, body=body, physics=False)
    res = train_pip(est, tmp_path / "run", max_steps=3, quiet=True, store=store, cache_root=tmp_path / "cache")
    assert res["steps"] == 3 and (tmp_path / "run" / "last.pt").is_file()
    res2 = train_pip(PipEstimator(cfg, body=body, physics=False), tmp_path / "run", epochs=1, resume=True, quiet=True,
                     store=store, cache_root=tmp_path / "cache")
    assert res2["steps"] >= 3 and (tmp_path / "run" / "best.pt").is_file()


def _recording(body, m: MotionSequence, cfg: PipConfig):
    from wearpose.recording import Recording

    r = simulate_clip(m, cfg, body, seed=0, noise="none", trim=0)
    return r, Recording.from_simulation(r["sim"], r["motion"], meta={"orientation_frame": "segment"})


def test_estimator_protocol_without_physics(body, tmp_path: Path) -> None:
    cfg = tiny()
    est = PipEstimator(cfg, body=body, physics=False)
    assert get_estimator("pip") is PipEstimator and est.causal and est.sensor_names[-1] == "pelvis"
    r, rec = _recording(body, motion(2, T=30), cfg)
    est.set_initial_state(r["pose"][0], trans=r["trans"][0])
    track = est.estimate(rec)
    assert isinstance(track, PoseTrack) and track.local_rot.shape == (30, 24, 3, 3) and track.trans.shape == (30, 3)
    assert track.extras["frame"] == "world" and track.extras["contacts"].shape == (30, 2)
    assert torch.allclose(track.trans[0], r["trans"][0])
    # root orientation is the pelvis IMU's
    assert torch.allclose(track.local_rot[:, 0], r["ori"][:, 5], atol=1e-5)
    # online == offline
    est.reset()
    from wearpose.estimators import iter_frames

    frames = [est.step(f) for f in iter_frames(rec, est.sensor_names)]
    assert torch.allclose(torch.stack([f.local_rot for f in frames]), track.local_rot, atol=1e-4)
    assert torch.allclose(torch.stack([f.trans for f in frames]), track.trans, atol=1e-4)
    # save / load round trip; options pass through load
    p = est.save(tmp_path / "pip.pt")
    est2 = PipEstimator.load(p, physics=False, learned_init=False)
    assert not est2.learned_init
    est2.set_initial_state(r["pose"][0], trans=r["trans"][0])
    assert not torch.allclose(est2.estimate(rec).local_rot, track.local_rot)  # zero init differs
    est3 = PipEstimator.load(p, physics=False)
    est3.set_initial_state(r["pose"][0], trans=r["trans"][0])
    assert torch.allclose(est3.estimate(rec).local_rot, track.local_rot, atol=1e-5)


def test_estimator_input_errors(body) -> None:
    est = PipEstimator(tiny(), body=body, physics=False)
    with pytest.raises(ShapeError):
        est.set_initial_state(torch.eye(3).repeat(23, 1, 1))
    bad = SensorFrame(0.0, ("head",), torch.ones(1, dtype=torch.bool).numpy(), {})
    with pytest.raises(ShapeError, match="pelvis"):
        est.step(bad)


def test_train_pip_cli_help() -> None:
    from typer.testing import CliRunner

    from wearpose.cli import app

    res = CliRunner().invoke(app, ["train", "pip", "--help"])
    assert res.exit_code == 0 and "Example: wearpose train pip" in res.output


def test_numpy_stepper_matches_torch_and_fast_path_equals_torch_path(body) -> None:
    from wearpose.estimators.pip.model import NumpyStepper

    torch.manual_seed(1)
    net = PipNet(tiny()).eval()
    x = torch.randn(1, 8, 72)
    st0 = net.initial_states(torch.randn(1, 15), torch.randn(1, 72))
    with torch.no_grad():
        out, _ = net(x, st0)
    s = NumpyStepper(net)
    s.set_states(st0)
    steps = [s.step(x[0, t].numpy()) for t in range(8)]
    for k in out:
        got = torch.from_numpy(__import__("numpy").stack([o[k] for o in steps]))
        assert torch.allclose(got, out[k][0], atol=1e-5), k
    # estimator: numpy online path == torch online path
    cfg = tiny()
    est = PipEstimator(cfg, body=body, physics=False)
    r, _ = _recording(body, motion(3, T=20), cfg)
    est.set_initial_state(r["pose"][0], trans=r["trans"][0])
    res = {}
    for fast in (True, False):
        est.fast_step = fast
        est.reset()
        res[fast] = torch.stack([est.step_tensors(r["acc"][t], r["ori"][t]).local_rot for t in range(20)])
    assert torch.allclose(res[True], res[False], atol=1e-5)


def test_synthetic_sitting_is_ambiguous_for_the_imus(body) -> None:
    from wearpose.body.skeleton import JOINT_INDEX
    from wearpose.estimators.pip.sitting import sitting_motion, sitting_sequence

    m = sitting_motion(torch.Generator().manual_seed(3), body)
    m2 = sitting_motion(torch.Generator().manual_seed(3), body)
    assert torch.equal(m.pose, m2.pose) and torch.equal(m.trans, m2.trans)  # seeded
    names = [s[0] for s in m.meta["segments"]]
    assert "sit" in names and sum(s[2] for s in m.meta["segments"]) == m.pose.shape[0]
    j = body(m.pose, m.betas, m.trans, return_vertices=False).joints
    ank = [JOINT_INDEX["left_ankle"], JOINT_INDEX["right_ankle"]]
    assert (j[:, ank].mean(1) - j[0, ank].mean(0)).norm(dim=-1).max() < 1e-4  # feet planted
    # the shank keeps its direction whether seated or standing: the lower-leg IMUs cannot tell
    shank = j[:, ank[0]] - j[:, JOINT_INDEX["left_knee"]]
    shank = shank / shank.norm(dim=-1, keepdim=True)
    assert (shank @ shank[0]).min() > math.cos(math.radians(0.5))
    # seated: pelvis lower by most of a thigh length
    first_sit = next(s for s in m.meta["segments"] if s[0] == "sit")[1]
    stand = next((s for s in m.meta["segments"] if s[0] == "stand"), None)
    if stand is not None:
        assert j[stand[1], 0, 1] - j[first_sit, 0, 1] > 0.2
    seq = sitting_sequence(body)
    assert seq.pose.shape[0] == 60 + 90 + 60
    # explicit default standing holds = the old clips (their cache stays valid); balanced holds
    # stand 3-20 s, seeded the same way otherwise
    m3 = sitting_motion(torch.Generator().manual_seed(3), body, stand_s=(1.0, 4.0))
    assert torch.equal(m.pose, m3.pose)
    for seed in range(6):
        b = sitting_motion(torch.Generator().manual_seed(seed), body, stand_s=(3.0, 20.0))
        stands = [s[2] for s in b.meta["segments"] if s[0] == "stand"]
        assert all(3 * 60 <= n <= 20 * 60 for n in stands)


def test_lean_transitions_change_only_the_transitions(body) -> None:
    from wearpose.body.skeleton import JOINT_INDEX
    from wearpose.estimators.pip.sitting import sitting_motion, sitting_sequence

    ank = [JOINT_INDEX["left_ankle"], JOINT_INDEX["right_ankle"]]
    seen = set()
    for seed in range(4):
        a = sitting_motion(torch.Generator().manual_seed(seed), body)
        b = sitting_motion(torch.Generator().manual_seed(seed), body, transitions="lean")
        assert a.meta["segments"] == b.meta["segments"]
        j = body(b.pose, b.betas, b.trans, return_vertices=False).joints
        assert (j[:, ank].mean(1) - j[0, ank].mean(0)).norm(dim=-1).max() < 1e-4  # feet still planted
        shank = j[:, ank[0]] - j[:, JOINT_INDEX["left_knee"]]
        shank = shank / shank.norm(dim=-1, keepdim=True)
        up = b.pose[:, 0, :, 1]  # the pelvis' up axis in the world
        for name, first, n in b.meta["segments"]:
            seen.add(name)
            sl = slice(first, first + n)
            if name in ("sit", "stand"):  # holds: the same frames as the slerp clip, still ambiguous
                assert torch.equal(a.pose[sl], b.pose[sl])
                continue
            # transition: the pelvis pitches >= 15 deg away from its hold orientation, the knees
            # travel forward (the shank leaves the vertical by >= 8 deg, ankle behind the knee)
            pitch = torch.rad2deg(torch.acos((up[sl] * up[first - 1 if first else first + n]).sum(-1).clamp(-1, 1)))
            assert pitch.max() > 14.0
            tilt = torch.rad2deg(torch.acos((shank[sl] @ shank[0]).clamp(-1, 1)))
            assert tilt.max() > 7.0 and tilt[0] < 1.0 and tilt[-1] < 1.0
            mid = first + int(n * 0.5)
            fwd = j[mid, JOINT_INDEX["left_knee"]] - j[mid, ank[0]]
            heading = b.pose[mid, 0][:, 2] * torch.tensor([1.0, 0.0, 1.0])  # pelvis forward, horizontal
            assert float(fwd @ heading / heading.norm()) > 0.02
    assert {"down", "up"} <= seen
    with pytest.raises(ValueError, match="transitions"):
        sitting_motion(torch.Generator().manual_seed(0), body, transitions="jump")
    s, le = sitting_sequence(body), sitting_sequence(body, transitions="lean")
    assert torch.equal(s.pose[-60:], le.pose[-60:]) and not torch.equal(s.pose[60:150], le.pose[60:150])


def test_hanging_arms_sitting_clips(body) -> None:
    from wearpose.body.skeleton import JOINT_INDEX
    from wearpose.calibration import calibration_pose
    from wearpose.estimators.pip.sitting import sitting_motion
    from wearpose.geometry import geodesic_angle

    ipose = calibration_pose("ipose").float()
    arm_joints = [JOINT_INDEX[f"{s}_{j}"] for s in ("left", "right") for j in ("shoulder", "elbow")]
    others = [j for j in range(24) if j not in arm_joints]

    def angle_deg(R1: torch.Tensor, R2: torch.Tensor) -> torch.Tensor:
        return torch.rad2deg(geodesic_angle(R1, R2))

    eye = torch.eye(3)
    bent = 0
    for seed in range(3):
        a = sitting_motion(torch.Generator().manual_seed(seed), body, transitions="lean")
        b = sitting_motion(torch.Generator().manual_seed(seed), body, transitions="lean", hanging_arms=1.0)
        assert torch.equal(a.pose[:, others], b.pose[:, others])  # only the arms change
        for j in arm_joints:  # near the I-pose in every frame (<= 8 + 8 deg swing, 15 elbow, 1.5 sway)
            assert angle_deg(ipose[j].expand_as(b.pose[:, j]), b.pose[:, j]).max() < 20.0
        elbow = a.pose[:, JOINT_INDEX["left_elbow"]]
        bent += int(angle_deg(eye.expand_as(elbow), elbow).max() > 20.0)
    assert bent >= 1  # the default posture is not already hanging straight


def test_sitting_transitions_config_cache_and_card(body) -> None:
    from wearpose.estimators.pip.data import _sitting_settings

    with pytest.raises(ConfigError, match="sitting_transitions"):
        PipConfig(sitting_transitions="jump")
    base, lean = PipConfig(sitting_clips=4), PipConfig(sitting_clips=4, sitting_transitions="lean")
    assert "sitting_transitions" not in _sitting_settings(base, body)  # the slerp clips keep their cache
    assert _sitting_settings(lean, body)["sitting_transitions"] == "lean"
    assert "trunk lean" in PipEstimator.training_data_description(lean.to_dict())
    assert "trunk lean" not in PipEstimator.training_data_description(base.to_dict())
    with pytest.raises(ConfigError, match="sitting_hanging_arms"):
        PipConfig(sitting_hanging_arms=1.5)
    arms = PipConfig(sitting_clips=4, sitting_hanging_arms=0.3)
    assert "sitting_hanging_arms" not in _sitting_settings(lean, body)
    assert _sitting_settings(arms, body)["sitting_hanging_arms"] == 0.3
    assert "30% of them with the arms hanging" in PipEstimator.training_data_description(arms.to_dict())


def test_sitting_drift_reports_series_and_upper_legs(body) -> None:
    from wearpose.estimators.pip.evaluate import sitting_drift

    torch.manual_seed(0)
    est = PipEstimator(tiny(), body=body, physics=False)
    r = sitting_drift(est, hours=2 / 60, start="seated", chunk=1000, every_s=60.0)
    assert r["frames"] == 7200 and [s["minutes"] for s in r["series"]] == [0.0, 1.0, 2.0]
    assert 0.0 <= r["upper_leg_error_at_end_deg"] <= 180.0 and r["drift_total_deg"] >= 0.0
    assert r["upper_leg_error_max_deg"] == max(s["upper_leg_error_deg"] for s in r["series"])


def test_heldout_sitting_clips_end_seated_and_are_not_training_clips(body) -> None:
    from wearpose.estimators.seeding import clip_seed
    from wearpose.estimators.pip.evaluate import sitting_drift
    from wearpose.estimators.pip.sitting import heldout_sitting_clip, sitting_clip_id, sitting_motion

    c0, c1 = heldout_sitting_clip(0, body), heldout_sitting_clip(1, body)
    assert not torch.equal(c0.pose[-1], c1.pose[-1])
    for c in (c0, c1):
        _, first, n = next(sg for sg in c.meta["segments"] if sg[0] == "sit")
        assert c.num_frames == first + n and n >= 3 * 60  # cut right after a seated hold of >= 3 s
    # The training clip with the same index (what build_split simulates for sitting_clips) differs.
    train0 = sitting_motion(torch.Generator().manual_seed(clip_seed(sitting_clip_id("train", 0), 0, "pip-sitting")), body)
    assert sitting_clip_id("test", 0) != sitting_clip_id("train", 0)
    assert train0.num_frames != c0.num_frames or not torch.equal(train0.pose[-1], c0.pose[-1])
    # sitting_drift measures against the clip's own last (seated) pose.
    torch.manual_seed(0)
    r = sitting_drift(PipEstimator(tiny(), body=body, physics=False), hours=1 / 60, start="seated", seq=c0)
    assert r["frames"] == 3600 and 0.0 <= r["upper_leg_error_at_end_deg"] <= 180.0


def test_augmented_train_split_mirror_and_speed(body, tmp_path: Path) -> None:
    from wearpose.body.skeleton import MIRROR
    from wearpose.estimators.trainmix import TrainingMix

    store = FakeStore(tmp_path / "store", {"train": 3, "val": 2})
    cfg = tiny(aug_mirror=True, aug_speed_copies=2, aug_speed_range=(0.7, 1.4))
    base = build_split("train", tiny(), body, store=store, cache_root=tmp_path / "cache")
    aug = build_split("train", cfg, body, store=store, cache_root=tmp_path / "cache")
    assert aug.clip_ids[:3] == base.clip_ids and len(aug.clip_ids) == 3 * 4
    assert aug.clip_ids[3:] == TrainingMix.from_config(cfg).extra_ids(base.clip_ids)
    assert torch.equal(aug.x[:base.num_frames], base.x)  # the corpus clips are untouched
    # Mirrored copy: each joint's root-frame velocity is its mirror joint's, x negated.
    i = aug.clip_ids.index(base.clip_ids[0] + "#mirror")
    s, L = int(aug.starts[i]), int(aug.lengths[i])
    assert L == int(base.lengths[0])
    v, vm = base.vel[:L].view(L, 24, 3), aug.vel[s:s + L].view(L, 24, 3)
    assert torch.allclose(vm, v[:, list(MIRROR)] * torch.tensor([-1.0, 1.0, 1.0]), atol=1e-4)
    assert torch.equal(aug.contact[s:s + L], base.contact[:L].flip(-1))
    # Speed copies: length scales by 1 / factor within the range (clips lose 2 * 4 edge frames).
    for k in range(2):
        j = aug.clip_ids.index(base.clip_ids[1] + f"#speed{k}")
        raw = int(base.lengths[1]) + 8
        assert raw / 1.4 - 10 <= int(aug.lengths[j]) <= raw / 0.7 + 2
    # Validation is never augmented.
    assert build_split("val", cfg, body, store=store, cache_root=tmp_path / "cache").clip_ids == store.clips("val")
