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
from wearpose.estimators.empose.data import recording_from_clip, simulate_clip
from wearpose.estimators.empose.model import PRED_JOINTS
from wearpose.estimators.empose.train import train_empose
from wearpose.estimators.empose.twostage import (
    MAX_REMOVED, JointSensors, TwoStageEstimator, masked_features, removal_mask, twostage_config,
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
    r = simulate_clip(synthetic_motion(9, T=20), cfg, body, seed=4, noise="none")
    rec = recording_from_clip(r, cfg)
    # Drop one sensor for frames 5..12 (NaN + invalid, as a recording marks dropped frames).
    s = rec.sensors[3]
    valid = s.valid.copy()
    valid[5:13] = False
    pos, ori = s.position.copy(), s.orientation.copy()
    pos[~valid], ori[~valid] = np.nan, np.nan
    rec = dataclasses.replace(rec, sensors=[*rec.sensors[:3], dataclasses.replace(s, valid=valid, position=pos,
                                                                                   orientation=ori), *rec.sensors[4:]])
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
