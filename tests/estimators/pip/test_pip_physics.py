"""PIP estimator with the physics module (wearpose.physics): outputs, online == offline,
single vs dual PD option passed through. A tiny untrained network drives it for a few frames."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch

from wearpose.estimators.pip import PipConfig, PipEstimator
from wearpose.estimators.pip.estimator import physics_available

pytestmark = pytest.mark.skipif(not physics_available(), reason="wearpose.physics not available")


def _inputs(T: int = 8):
    ori = torch.eye(3).repeat(T, 6, 1, 1)
    return torch.zeros(T, 6, 3), ori


@pytest.fixture(scope="module")
def est(body) -> PipEstimator:
    torch.manual_seed(0)
    return PipEstimator(PipConfig.preset("tiny"), body=body, physics=True)


def test_physics_outputs_and_online_equals_offline(est) -> None:
    est.dual_pd = True
    est.set_initial_state(trans=torch.tensor([0.0, 0.9, 0.0]))
    acc, ori = _inputs(5)
    track = est.estimate_tensors(acc, ori)
    ex = track.extras
    assert ex["physics"] and ex["frame"] == "world"
    assert ex["torques"].shape == (5, 24, 3) and ex["grf"].shape == (5, 2, 3) and ex["contacts"].shape == (5, 2)
    assert torch.isfinite(track.trans).all() and torch.isfinite(track.local_rot).all()
    assert float(ex["penetration_m"].max()) < 0.01
    est.reset()
    online = [est.step_tensors(acc[t], ori[t]) for t in range(5)]
    assert torch.allclose(torch.stack([f.trans for f in online]), track.trans, atol=1e-4)
    assert torch.allclose(torch.stack([f.local_rot for f in online]), track.local_rot, atol=1e-4)
    assert online[-1].extras["grf"].shape == (2, 3)


def test_single_pd_option_reaches_the_optimizer(est) -> None:
    est.dual_pd = False
    est.set_initial_state()
    est.estimate_tensors(*_inputs(2))
    assert est._physics_optimizer().config.dual_pd is False
    est.dual_pd = True
    assert est._physics_optimizer().config.dual_pd is True


@pytest.mark.corpus
def test_demo_on_a_test_clip(body, tmp_path, corpus_store) -> None:
    from wearpose.viewer.demos.pip import run_demo
    from wearpose.motion import CorpusStore

    # Kinematics only: the physics path of the estimator is covered above; with an untrained
    # network the physics character flails and the test would take minutes on a busy machine.
    ck = PipEstimator(PipConfig.preset("tiny"), body=body, physics=False).save(tmp_path / "tiny.pt")
    clip = next(c for c in CorpusStore().clips(split="test") if "walk" in c)
    res = run_demo(clip, tmp_path / "demo", weights=str(ck), max_seconds=0.5, physics=False)
    assert Path(res["html"]).is_file() and 15 <= res["frames"] <= 22  # 0.5 s at 60 Hz minus 4 frames at each end
    m = res["metrics"]
    assert {"sip_error_deg", "mesh_error_cm", "jitter_abs_km_s3"} <= set(m)
    assert all(k.endswith(("_deg", "_cm", "_km_s3", "_pct", "_nm", "_kg")) for k in m)


def test_physics_options_reach_the_optimizer(est) -> None:
    est.physics_options = {"contact_no_lift": False}
    assert est._physics_optimizer().config.contact_no_lift is False
    est.physics_options = {}
    assert est._physics_optimizer().config.contact_no_lift is True


def test_evaluate_variants_per_clip_and_zmp(body) -> None:
    from wearpose.estimators.pip.evaluate import evaluate_variants
    from wearpose.motion import MotionSequence

    T = 40  # a person standing still, 4 frames trimmed at each end
    still = MotionSequence(torch.eye(3).repeat(T, 24, 1, 1), torch.zeros(10), torch.zeros(T, 3) + torch.tensor([0, 0.9, 0]),
                           60.0)

    class Store:
        def clips(self, split: str) -> list[str]:
            return ["synthetic/still"]

        def load(self, cid: str) -> MotionSequence:
            return still

    torch.manual_seed(0)
    v = {"phys": PipEstimator(PipConfig.preset("tiny"), body=body, physics=True),
         "kin": PipEstimator(PipConfig.preset("tiny"), body=body, physics=False)}
    res = evaluate_variants(v, "test", store=Store(), noise="none")
    gt = res["ground_truth"]
    assert gt["zmp_distance_m"] == 0.0 and gt["zmp_frames_pct"] > 80  # standing still is balanced
    for name, row in res["rows"].items():
        (clip,) = row["per_clip"]
        assert clip["clip"] == "synthetic/still" and clip["frames"] == T - 8
        assert clip["translation_error_cm"] >= 0 and "zmp_distance_m" in row
    at = res["rows"]["phys"]["per_clip"][0]["penetration_at"]
    assert 0 <= at["frame"] < T - 8 and at["joint"] in range(24)
    assert "penetration_at" not in res["rows"]["kin"]["per_clip"][0]


def test_travel_rule_counts_ground_plane_path_after_trimming() -> None:
    from wearpose.estimators.pip.evaluate import clip_travel_m, horizontal_path_m
    from wearpose.motion import MotionSequence

    T = 121  # 2 s at 60 Hz: 1 m/s along x and 3 m/s up and down along y (a jump does not travel)
    t = torch.arange(T) / 60.0
    trans = torch.stack([t, 0.9 + 0.3 * torch.sin(10 * t), torch.zeros(T)], -1)
    assert horizontal_path_m(trans) == pytest.approx(2.0, rel=1e-5)
    m = MotionSequence(torch.eye(3).repeat(T, 24, 1, 1), torch.zeros(10), trans, 60.0)
    assert clip_travel_m(m, 60.0) == pytest.approx((T - 1 - 8) / 60.0, rel=1e-5)  # 4 frames cut at each end
    assert clip_travel_m(m, 60.0, trim=0) == pytest.approx(2.0, rel=1e-5)
    # at 30 Hz the same clip (resampled to 60 Hz) travels the same way
    half = MotionSequence(m.pose[::2], m.betas, trans[::2], 30.0)
    assert clip_travel_m(half, 60.0, trim=0) == pytest.approx(2.0, rel=1e-4)
