"""EM-POSE L-BFGS optimisation baseline with our pose-prior VAE (tiny, synthetic)."""

from __future__ import annotations

from pathlib import Path

import torch

from test_empose import FakeStore, synthetic_motion  # tests/estimators is on sys.path (pytest rootdir mode)
from wearpose.body import BodyModel
from wearpose.estimators import get_estimator
from wearpose.estimators.empose import EmposeConfig
from wearpose.estimators.empose.data import recording_from_clip, simulate_clip
from wearpose.estimators.empose.optimization import LbfgsEstimator, train_pose_prior


def test_prior_training_checkpoint_and_lbfgs_fit(tmp_path: Path, body: BodyModel) -> None:
    store = FakeStore(tmp_path, {"train": 2, "val": 1})
    res = train_pose_prior(str(tmp_path / "prior"), epochs=1, batch=16, store=store, cache_root=tmp_path / "cache")
    assert res["history"] and (tmp_path / "prior" / "prior.pt").is_file()
    est = LbfgsEstimator.load(tmp_path / "prior" / "prior.pt", body=body)
    assert get_estimator("empose-lbfgs") is LbfgsEstimator
    est.max_iter = 15
    cfg = EmposeConfig.preset("tiny", 12)
    r = simulate_clip(synthetic_motion(4, T=3), cfg, body, seed=1, noise="none")
    track = est.estimate(recording_from_clip(r, cfg))
    assert track.local_rot.shape == (3, 24, 3, 3) and torch.isfinite(track.local_rot).all()
    # The optimisation explains the measurements far better than its starting point (rest pose).
    from wearpose.estimators.empose.model import reconstruction_loss

    T, S = r["position"].shape[:2]
    ph, Rh, _ = est.sensors(torch.eye(3).expand(T, 24, 3, 3), torch.zeros(T, 10), r["off_R"].expand(T, S, 3, 3),
                            r["off_t"].expand(T, S, 3))
    first = reconstruction_loss(ph, Rh, r["position"], r["orientation"])
    assert float(track.extras["rec_loss"].mean()) < 0.5 * float(first.mean())
    # L_r is blind to the root; the estimator puts the body's source site at the source frame, which
    # recovers the ground-truth root (the simulator's convention) up to the fit of the spine.
    from wearpose.geometry import matrix_to_axis_angle

    err = matrix_to_axis_angle(track.local_rot[:, 0].transpose(-1, -2) @ r["pose"][:, 0]).norm(dim=-1)
    assert float(err.max()) < 0.5  # rad
