"""Evaluation wearers (issue 23.6 / 24.6): ``bodies="heldout"`` puts every clip of every
method's protocol on a held-out body, decided in one place (:mod:`wearpose.estimators.bodies`)."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch

from tests.estimators.test_empose import FakeStore
from wearpose.body import BodyModel
from wearpose.errors import ConfigError
from wearpose.estimators.bodies import WearerStore, clip_bodies, heldout_betas, wearer_store
from wearpose.estimators.empose import EmposeConfig, EmposeEstimator
from wearpose.estimators.seeding import clip_seed
from wearpose.motion import refit_to_body
from wearpose.sensors import random_body_shape


def test_one_wearer_per_clip_from_the_heldout_stream(tmp_path: Path, body: BodyModel) -> None:
    a, b = heldout_betas("synthetic/test_00", 3), heldout_betas("synthetic/test_01", 3)
    assert a.shape == (10,) and torch.equal(a, heldout_betas("synthetic/test_00", 3))  # reproducible
    assert not torch.allclose(a, b, atol=1e-3)  # one wearer per clip
    assert not torch.allclose(a, heldout_betas("synthetic/test_00", 4), atol=1e-3)  # the seed matters
    assert float(a.abs().max()) <= 2.5  # the documented truncated distribution
    for ns in ("train", "eval", "pip", "pip-eval"):  # never a training wearer of that clip
        for draw in ("random", "heldout"):
            other = random_body_shape(clip_seed("synthetic/test_00", 3, ns), draw=draw)
            assert not torch.allclose(a, other, atol=1e-3), (ns, draw)
    store = FakeStore(tmp_path, {"test": 2})
    assert wearer_store(store, "corpus", body, 3) is store  # today's behaviour, untouched
    with pytest.raises(ConfigError, match="corpus, heldout"):
        wearer_store(store, "tall", body, 3)


def test_the_clip_is_refitted_to_its_wearer_as_the_simulator_does(tmp_path: Path, body: BodyModel) -> None:
    store = FakeStore(tmp_path, {"test": 2, "val": 1})
    worn = wearer_store(store, "heldout", body, 3)
    assert isinstance(worn, WearerStore) and worn.clips(split="test") == store.clips(split="test")  # delegated
    cid = "synthetic/test_01"
    m, src = worn.load(cid), store.load(cid)
    assert torch.equal(m.betas, heldout_betas(cid, 3))
    assert torch.equal(m.pose, src.pose)  # joint rotations kept
    want = refit_to_body(src, body, heldout_betas(cid, 3))  # what simulate(shape=...) does
    assert torch.equal(m.trans, want.trans) and not torch.allclose(m.trans, src.trans)
    assert clip_bodies(worn, [cid]) == {cid: pytest.approx(heldout_betas(cid, 3).tolist(), abs=1e-4)}
    assert clip_bodies(store, [cid]) == {}


def test_empose_is_simulated_and_scored_on_the_wearer(tmp_path: Path, body: BodyModel) -> None:
    """The sensors are simulated on the held-out body, the ground truth is that body's, and the
    shape figures compare the estimate with it."""
    from wearpose.estimators.empose.data import recording_from_clip
    from wearpose.estimators.empose.evaluate import evaluate_models, simulate_eval_clip
    from wearpose.estimators.empose.model import VirtualSensors
    from wearpose.estimators.empose.estimator import _sites
    from wearpose.body.shapes import standing_height
    from wearpose.evaluate.metrics import shape_errors

    torch.manual_seed(0)
    est = EmposeEstimator(EmposeConfig.preset("tiny", 12), body=body)
    store = FakeStore(tmp_path, {"test": 2})
    res = evaluate_models({"m": est}, "test", store=store, seed=3, bodies="heldout", noise="none")
    plain = evaluate_models({"m": est}, "test", store=store, seed=3, noise="none")
    assert (res["bodies"], plain["bodies"], plain["betas"]) == ("heldout", "corpus", {})
    ids = store.clips(split="test")
    assert set(res["betas"]) == set(ids)
    worn = wearer_store(store, "heldout", body, 3)
    for row in res["models"]["m"]["per_clip"]:
        cid = row["clip"]
        assert res["betas"][cid] == pytest.approx(heldout_betas(cid, 3).tolist(), abs=1e-4)
        r = simulate_eval_clip(worn.load(cid), est, cid, 3, noise="none")
        assert torch.equal(r["betas"], heldout_betas(cid, 3))
        # the noise-free measurements are those of the wearer's body (not the clip's own)
        sites, src = _sites(est.config.kit, body)
        vs = VirtualSensors(body, sites, src)
        T, S = r["position"].shape[:2]
        p, _, J = vs(r["pose"], r["betas"].expand(T, 10), r["off_R"].expand(T, S, 3, 3), r["off_t"].expand(T, S, 3))
        assert (p - r["position"]).abs().max() < 1e-4 and torch.allclose(J, r["joints"], atol=1e-5)
        p0, _, _ = vs(r["pose"], store.load(cid).betas.expand(T, 10), r["off_R"].expand(T, S, 3, 3),
                      r["off_t"].expand(T, S, 3))
        assert (p0 - r["position"]).norm(dim=-1).mean() > 2e-3
        # the shape figures: the estimate of this very recording against the wearer
        track = est.estimate(recording_from_clip(r, est.config))
        e = shape_errors(body, track.betas, heldout_betas(cid, 3))
        assert row["height_error_cm"] == pytest.approx(float(e.height_error) * 100, abs=1e-3)
        assert row["height_difference_cm"] == pytest.approx(float(e.height_difference) * 100, abs=1e-3)
        assert row["zero_pose_vertex_error_mm"] == pytest.approx(float(e.zero_pose_vertex_error) * 1000, abs=1e-2)
        assert row["wearer_height_cm"] == pytest.approx(float(standing_height(body, heldout_betas(cid, 3))) * 100, abs=1e-3)
    m = res["models"]["m"]
    rows = m["per_clip"]
    assert m["height_error_median_cm"] == pytest.approx(float(torch.tensor([r["height_error_cm"] for r in rows],
                                                                           dtype=torch.float64).median()))
    assert m["zero_pose_vertex_error_mean_mm"] == pytest.approx(sum(r["zero_pose_vertex_error_mm"] for r in rows) / 2)
    assert m["mpjpe_mm"] != plain["models"]["m"]["mpjpe_mm"]  # other bodies, other figures
    assert "height_error_median_cm" in plain["models"]["m"]  # the shape figures on the clips' own body too


def test_every_method_gets_the_same_wearer(tmp_path: Path, body: BodyModel) -> None:
    """PIP's evaluation path is the same one: its per-clip betas are the wearers EM-POSE's
    protocol uses for those clips (the body depends on the clip and the seed, not the method)."""
    from wearpose.estimators.empose.evaluate import evaluate_models
    from wearpose.estimators.pip import PipConfig, PipEstimator
    from wearpose.estimators.pip.evaluate import evaluate_variants

    torch.manual_seed(0)
    store = FakeStore(tmp_path, {"test": 2})
    pip = evaluate_variants({"kin": PipEstimator(PipConfig.preset("tiny"), body=body, physics=False)}, "test",
                            store=store, noise="none", seed=5, bodies="heldout")
    em = evaluate_models({"m": EmposeEstimator(EmposeConfig.preset("tiny", 12), body=body)}, "test", store=store,
                         seed=5, bodies="heldout", noise="none")
    for row in pip["rows"]["kin"]["per_clip"]:
        assert row["betas"] == pytest.approx(em["betas"][row["clip"]], abs=1e-4)
    assert pip["bodies"] == "heldout"


def test_miposer_scores_on_the_wearers_body(body: BodyModel) -> None:
    """MI-Poser has no shape: estimate and ground truth are posed on the wearer's body; the
    corpus body (beta = 0) gives exactly the mean-shape figure of before."""
    from wearpose.estimators.miposer.evaluate import joint_errors
    from wearpose.geometry import axis_angle_to_matrix

    g = torch.Generator().manual_seed(0)
    a = axis_angle_to_matrix(0.3 * torch.randn(5, 24, 3, generator=g))
    b = axis_angle_to_matrix(0.3 * torch.randn(5, 24, 3, generator=g))
    assert torch.equal(joint_errors(body, a, b, torch.zeros(10)), joint_errors(body, a, b))
    tall = torch.zeros(10)
    tall[0] = 2.0
    e_tall, e_mean = joint_errors(body, a, b, tall), joint_errors(body, a, b)
    assert float(e_tall.mean()) > float(e_mean.mean())  # longer bones, larger errors for one pose error
