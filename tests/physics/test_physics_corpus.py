"""Integration: the optimizer on ground-truth kinematics of a held-out (test split) walking clip."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from wearpose.body import BodyModel
from wearpose.motion import CorpusStore
from wearpose.physics import PhysicsCharacter, PhysicsConfig, PhysicsOptimizer, kinematic_reference

CLIP = "bandai/bandai-B/dataset-2_walk_feminine_003"  # test split (bandai-B)


@pytest.fixture(scope="module")
def walk(corpus_root):
    store = CorpusStore(corpus_root)
    seq = store.load(CLIP)
    assert store.entry(CLIP)["split"] == "test"
    body = BodyModel()
    return seq.slice(0, 120), body  # 4 s at 30 fps -> 240 frames at 60 fps


@pytest.mark.corpus
def test_ground_truth_walk_carries_weight_alternates_and_stays_above_ground(walk):
    seq, body = walk
    ref = kinematic_reference(seq, body)
    char = PhysicsCharacter.from_body(body, seq.betas)
    out = PhysicsOptimizer(char, PhysicsConfig()).run(ref.pose, ref.joint_vel, ref.contact, ref.trans[0])
    fy = out["grf"][..., 1].double().numpy()
    ratio = fy.sum(1).mean() / (char.mass_kg * 9.81)
    assert abs(ratio - 1.0) < 0.15, ratio
    assert float(out["penetration_m"].max()) < 0.01
    lab = ref.contact.numpy() > 0.5
    single = lab.sum(1) == 1
    agree = (fy.argmax(1)[single] == lab.argmax(1)[single]).mean()
    assert agree > 0.8, agree  # the loaded foot is the ground truth's stance foot
    jrel = (out["joints"] - out["joints"][:, :1]) - (ref.joints - ref.joints[:, :1])
    assert float(jrel.norm(dim=-1).mean()) < 0.05  # tracks the reference pose within 5 cm
    err = (out["trans"] - ref.trans).norm(dim=-1)
    travelled = float((ref.trans[1:] - ref.trans[:-1]).norm(dim=-1).sum())
    assert float(err[-1]) < 0.1 * travelled
    assert torch.isfinite(out["torques"]).all()
