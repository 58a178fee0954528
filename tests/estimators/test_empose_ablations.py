"""EM-POSE Table 3 ablations as LGD-RNN config options ("no t", "pos only", "ori only", "no RNN";
"no [R|t]" is ``offsets="none"``): what each one changes, on the tiny config and synthetic motion."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
import torch

from tests.estimators.test_empose import FakeStore, synthetic_motion
from wearpose.body import BodyModel
from wearpose.errors import ConfigError
from wearpose.estimators import iter_frames
from wearpose.estimators.empose import EmposeConfig, EmposeEstimator
from wearpose.estimators.empose.config import TABLE3_ABLATIONS, ablation_config
from wearpose.estimators.empose.data import recording_from_clip, simulate_clip
from wearpose.estimators.empose.model import PRED_JOINTS, decode_omega
from wearpose.estimators.empose.train import train_empose
from wearpose.geometry import axis_angle_to_matrix, matrix_to_rot6d


def tiny(ablation: str = "full", **kw) -> EmposeConfig:
    return ablation_config(EmposeConfig.preset("tiny", 12).override(iterations=2, **kw), ablation)


def test_ablation_options_are_validated_and_cover_table3() -> None:
    assert {label for label, _ in TABLE3_ABLATIONS.values()} == {"full", "no [R,t]", "no t", "pos only", "ori only", "no RNN"}
    assert tiny("no_t").offsets == "rot" and tiny("pos_only").inputs == "position" and tiny("no_rnn").init == "mean"
    assert tiny("full") == EmposeConfig.preset("tiny", 12).override(iterations=2)
    for bad in ({"inputs": "pos"}, {"init": "rest"}, {"offsets": "t"}):
        with pytest.raises(ConfigError):
            EmposeConfig.preset("tiny", 12).override(**bad)
    with pytest.raises(ConfigError, match="ablation"):
        ablation_config(EmposeConfig(), "no_lstm")
    # Old checkpoints (configs without the new fields) load as the full model.
    d = EmposeConfig.preset("cpu", 12).to_dict()
    del d["inputs"], d["init"]
    assert EmposeConfig.from_dict(d).inputs == "both" and EmposeConfig.from_dict(d).init == "rnn"


def test_no_t_simulates_and_reconstructs_with_rotation_offsets_only(body: BodyModel) -> None:
    cfg = tiny("no_t")
    full = simulate_clip(synthetic_motion(1, T=10), tiny(), body, seed=5)
    rot = simulate_clip(synthetic_motion(1, T=10), cfg, body, seed=5)
    assert torch.allclose(rot["off_R"], full["off_R"]) and full["off_t"].abs().max() > 1e-3
    assert torch.equal(rot["off_t"], torch.zeros_like(rot["off_t"]))
    # At run time the recording's (full) offsets lose their translations.
    R, t = EmposeEstimator(cfg, body=body)._offsets_from(recording_from_clip(full, cfg))
    assert torch.allclose(R, full["off_R"], atol=1e-6) and torch.equal(t, torch.zeros_like(t))


@pytest.mark.parametrize("ablation,blind", [("pos_only", "orientation"), ("ori_only", "position")])
def test_single_modality_models_ignore_the_other_modality(body: BodyModel, ablation: str, blind: str) -> None:
    """Network input and L_r use one modality: perturbing the other changes nothing; the closed-form
    (lean) gradient path equals autograd with the weighted L_r."""
    cfg = tiny(ablation)
    torch.manual_seed(0)
    est = EmposeEstimator(cfg, body=body)
    assert est.model.in_dim == 12 * (3 if ablation == "pos_only" else 9)
    r = simulate_clip(synthetic_motion(3, T=12), cfg, body, seed=2)
    rec = recording_from_clip(r, cfg)
    a = est.estimate(rec)
    for s in rec.sensors:
        if blind == "orientation":
            s.orientation[:] = torch.linalg.qr(torch.randn(*s.orientation.shape, dtype=torch.float64))[0].numpy()
        else:
            s.position[:] += 0.3
    b = est.estimate(rec)
    assert torch.allclose(a.local_rot, b.local_rot, atol=1e-5) and torch.allclose(a.betas, b.betas, atol=1e-5)
    est.model.lean_inference = False
    c = est.estimate(rec)
    assert torch.allclose(b.local_rot, c.local_rot, atol=1e-4)
    assert torch.allclose(b.extras["rec_loss"], c.extras["rec_loss"], rtol=1e-4, atol=1e-6)


def test_no_rnn_starts_every_frame_from_one_learned_estimate(body: BodyModel) -> None:
    cfg = tiny("no_rnn")
    est = EmposeEstimator(cfg, body=body)
    assert not any(k.startswith(("rnn.", "head.")) for k in est.model.state_dict()) and "omega_init" in est.model.state_dict()
    x = torch.randn(2, 5, 12 * 12)
    omega0, _ = est.model.initial(x)
    assert omega0.shape == (2, 5, est.model.omega_dim) and torch.equal(omega0, omega0[:1, :1].expand_as(omega0))
    # The start is the mean training pose: a data set of one repeated pose starts there exactly.
    pose = axis_angle_to_matrix(0.5 * torch.randn(24, 3, generator=torch.Generator().manual_seed(0)))
    est.model.set_mean_start(matrix_to_rot6d(pose).expand(7, 24, 6))
    rot, betas = decode_omega(est.model.initial(x)[0][0, 0], cfg.rep)
    assert torch.allclose(rot[list(PRED_JOINTS)], pose[list(PRED_JOINTS)], atol=1e-5) and torch.equal(betas, torch.zeros(10))


@pytest.mark.parametrize("ablation", ["no_t", "pos_only", "ori_only", "no_rnn"])
def test_ablation_trains_saves_loads_and_streams(tmp_path: Path, body: BodyModel, ablation: str) -> None:
    """A few steps of training, a checkpoint round trip, and online step == offline estimate."""
    cfg = tiny(ablation)
    store = FakeStore(tmp_path, {"train": 2, "val": 1, "test": 1})
    est = EmposeEstimator(cfg, body=body)
    res = train_empose(est, tmp_path / "run", epochs=1, max_steps=2, store=store, cache_root=tmp_path / "cache",
                       quiet=True, train_command="test")
    assert res["steps"] == 2
    back = EmposeEstimator.load(tmp_path / "run" / "last.pt", body=body)
    assert back.config == cfg
    clip = simulate_clip(store.load("synthetic/test_00"), cfg, body, seed=11, noise="default", offsets="random")
    rec = recording_from_clip(clip, cfg)
    track = back.estimate(rec)
    assert all(math.isfinite(v) for v in track.local_rot.flatten().tolist()[:50])
    back.reset()
    R, t = back._offsets_from(rec)
    back.set_offsets(R, t)
    online = torch.stack([back.step(f).local_rot for f in iter_frames(rec, back.sensor_names)])
    assert torch.allclose(online, track.local_rot, atol=1e-4)
