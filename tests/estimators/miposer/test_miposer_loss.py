"""MI-Poser's IK loss (issue 22): a spine twisted 180 deg about the bone and untwisted above it
leaves the joint positions right; the rotation loss has to see it."""

from __future__ import annotations

import pytest
import torch

from wearpose.body import BodyModel
from wearpose.estimators.miposer import MiposerConfig
from wearpose.estimators.miposer.model import SPINE, ik_loss, rotation_term, twist_prior
from wearpose.geometry import matrix_to_rot6d, rotation_x, rotation_y

OLD = MiposerConfig.preset("cpu").override(rot_loss="l1_6d", spine_rot_weight=1.0, lambda_twist=0.0)
NEW = MiposerConfig.preset("cpu")


@pytest.fixture(scope="module")
def bodies() -> dict[torch.dtype, BodyModel]:
    return {dt: BodyModel().to(dt) for dt in (torch.float32, torch.float64)}


def _poses(dtype: torch.dtype) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """``(gt, twisted, small)`` local rotations ``(4, 22, 3, 3)``: a random-ish ground truth (every
    joint 0.1-0.3 rad about X), the same with spine1 turned 180 deg about Y and spine2 turned back
    (the v1 weights' tear: the bones above land where they belong), and the ground truth with every
    joint 3 deg off about X (a small error that moves the joints)."""
    g = torch.Generator().manual_seed(0)
    a = 0.1 + 0.2 * torch.rand(4, 22, generator=g, dtype=dtype)
    gt = rotation_x(a)
    gt[:, 0] = torch.eye(3, dtype=dtype)
    gt[:, SPINE[0]] = gt[:, SPINE[1]] = torch.eye(3, dtype=dtype)
    twisted = gt.clone()
    half = rotation_y(torch.tensor(torch.pi, dtype=dtype))
    twisted[:, SPINE[0]] = half
    twisted[:, SPINE[1]] = half.transpose(-1, -2)
    small = gt @ rotation_x(torch.tensor(0.0524, dtype=dtype))
    small[:, 0] = gt[:, 0]
    return gt, twisted, small


def _loss(pred: torch.Tensor, gt: torch.Tensor, body: BodyModel, cfg: MiposerConfig):  # noqa: ANN202
    p6, g6 = matrix_to_rot6d(pred), matrix_to_rot6d(gt)
    C = torch.eye(3, dtype=pred.dtype).expand(pred.shape[0], 3, 3)
    return ik_loss((p6[:, 0].clone().requires_grad_(), p6[:, 1:].clone().requires_grad_()), C, g6, body, cfg)


@pytest.mark.budget(30)  # the first call imports roma (torch._dynamo): ~10 s at load 7
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_a_180_deg_spine_twist_costs_more_than_a_small_error(dtype: torch.dtype, bodies) -> None:  # noqa: ANN001
    body = bodies[dtype]
    gt, twisted, small = _poses(dtype)
    lt, pt, J, Jg = _loss(twisted, gt, body, NEW)
    ls, ps, _, _ = _loss(small, gt, body, NEW)
    # The twist leaves the joints (nearly) where they belong: the position terms barely see it ...
    assert pt["l_pos"] < ps["l_pos"] and pt["l_hand"] < 1e-4
    assert float((J[:, 12:] - Jg[:, 12:]).detach().norm(dim=-1).max()) < 0.01
    # ... the new rotation term does: ~pi per twisted joint, the spine weighted 5x, plus the hinge.
    lt, ls = float(lt.detach()), float(ls.detach())
    assert lt > 5 * ls, (lt, ls)
    assert pt["l_rot"] > 2 * 5 * 3.0 / 21 and pt["l_twist"] > 0.5 * (torch.pi - torch.deg2rad(torch.tensor(40.0)))
    # The v1 loss (L1 on the raw 6D numbers, 126 of them) ranks the tear as cheaper than the small error.
    lt_old, _, _, _ = _loss(twisted, gt, body, OLD)
    ls_old, _, _, _ = _loss(small, gt, body, OLD)
    assert float(lt_old.detach()) < float(ls_old.detach())


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_the_gradient_turns_a_twisted_spine_back(dtype: torch.dtype) -> None:
    """At 179 deg of twist the gradient of the geodesic + hinge points towards less twist (the L1 on
    Gram-Schmidt-normalised 6D has a local minimum at 180 deg); finite at 0 and exactly 180 deg."""
    gt6 = matrix_to_rot6d(torch.eye(3, dtype=dtype).expand(1, 21, 3, 3))
    for deg in (0.0, 90.0, 179.0, 180.0):
        R = torch.eye(3, dtype=dtype).repeat(1, 21, 1, 1)
        R[:, SPINE[0] - 1] = rotation_y(torch.tensor(deg, dtype=dtype).deg2rad())
        x6 = matrix_to_rot6d(R).requires_grad_()
        (rotation_term(x6, gt6, NEW) + twist_prior(x6, NEW)).backward()
        assert torch.isfinite(x6.grad).all(), deg
        if deg in (90.0, 179.0):
            step = x6.detach() - 1e-3 * x6.grad / x6.grad.norm()
            before = rotation_term(x6.detach(), gt6, NEW)
            assert float(rotation_term(step, gt6, NEW)) < float(before), deg


def test_old_configs_keep_the_old_loss() -> None:
    """A stored config without the new fields (the v1 weights') is the raw-6D L1, as trained."""
    d = OLD.to_dict()  # the v1 loss: the four loss fields are left out, as in a v1 checkpoint
    assert not {"rot_loss", "spine_rot_weight", "lambda_twist", "twist_limit_deg"} & set(d)
    old = MiposerConfig.from_dict(d)
    assert old.rot_loss == "l1_6d" and old.lambda_twist == 0.0
    g = torch.Generator().manual_seed(1)
    a, b = torch.randn(3, 21, 6, generator=g), torch.randn(3, 21, 6, generator=g)
    assert torch.equal(rotation_term(a, b, old), (a - b).abs().mean())
    assert NEW.rot_loss == "geodesic" and MiposerConfig.preset("paper").rot_loss == "l1_6d"
    # ... and writes back the dict it was read from (a v1 checkpoint re-saves identically).
    assert old.to_dict() == d and MiposerConfig.from_dict(NEW.to_dict()) == NEW
    assert NEW.to_dict()["rot_loss"] == "geodesic" and NEW.to_dict()["twist_limit_deg"] == 40.0  # all four kept
