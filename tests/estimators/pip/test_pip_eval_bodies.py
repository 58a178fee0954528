"""PIP evaluation on held-out wearers of every size (issue 23.6): ``bodies="heldout"``, the
wearers of :mod:`wearpose.estimators.bodies` (every method's)."""

from __future__ import annotations

import pytest
import torch

from wearpose.estimators.bodies import heldout_betas
from wearpose.estimators.seeding import clip_seed
from wearpose.estimators.pip import PipConfig, PipEstimator
from wearpose.estimators.pip.evaluate import evaluate_variants
from wearpose.motion import MotionSequence
from wearpose.sensors import random_body_shape

T = 40


class _Store:
    """Two synthetic clips of a person standing still."""

    still = MotionSequence(torch.eye(3).repeat(T, 24, 1, 1), torch.zeros(10), torch.zeros(T, 3) + torch.tensor([0, 0.9, 0]),
                           60.0)

    def clips(self, split: str) -> list[str]:
        return ["synthetic/a", "synthetic/b"]

    def load(self, cid: str) -> MotionSequence:
        return self.still


def test_heldout_bodies_are_the_evaluation_streams_wearers(body) -> None:
    torch.manual_seed(0)
    v = {"kin": PipEstimator(PipConfig.preset("tiny"), body=body, physics=False)}
    res = evaluate_variants(v, "test", store=_Store(), noise="none", seed=2, bodies="heldout")
    assert res["bodies"] == "heldout"
    rows = res["rows"]["kin"]["per_clip"]
    for row in rows:
        assert row["betas"] == pytest.approx(heldout_betas(row["clip"], 2).tolist(), abs=1e-4)
        # never the wearer a training simulation of that clip draws (training namespace "pip", draw "random")
        assert row["betas"] != pytest.approx(random_body_shape(clip_seed(row["clip"], 2, "pip")).tolist(), abs=1e-3)
    assert rows[0]["betas"] != rows[1]["betas"]  # one wearer per clip
    plain = evaluate_variants(v, "test", store=_Store(), noise="none", seed=2)
    assert "bodies" not in plain and "betas" not in plain["rows"]["kin"]["per_clip"][0]
    with pytest.raises(Exception, match="bodies"):
        evaluate_variants(v, "test", store=_Store(), bodies="tall")
