"""Motion augmentation: mirror image and play speed (``wearpose.motion.augment``)."""

from __future__ import annotations

import math

import pytest
import torch

from tests.sensors.sensor_testutils import smooth_motion
from wearpose.body import BodyModel
from wearpose.body.skeleton import MIRROR
from wearpose.errors import ShapeError
from wearpose.geometry import axis_angle_to_matrix, mirror_points, mirror_rotation
from wearpose.motion import mirror, play_speed, resample


def test_mirror_rotation_against_axis_angle_reference() -> None:
    # Reflecting through x = 0 maps a rotation by theta about axis a to one by theta about -M a.
    g = torch.Generator().manual_seed(0)
    aa = torch.randn(50, 3, generator=g, dtype=torch.float64)
    ref = axis_angle_to_matrix(-mirror_points(aa))
    assert torch.allclose(mirror_rotation(axis_angle_to_matrix(aa)), ref, atol=1e-12)
    assert torch.allclose(mirror_points(torch.tensor([1.0, 2.0, 3.0])), torch.tensor([-1.0, 2.0, 3.0]))


def test_mirror_is_the_reflected_body_and_an_involution() -> None:
    body = BodyModel().to(torch.float64)  # the shipped asset: left/right symmetric to < 0.1 mm
    m = smooth_motion(T=40, fps=60.0, seed=3, amp=0.5).to(torch.float64)
    m.trans += torch.tensor([0.3, 0.0, -0.2], dtype=torch.float64)
    root = body.rest_joints(m.betas)[0]
    mm = mirror(m, root)
    J = body(m.pose, m.betas, m.trans, return_vertices=False).joints
    Jm = body(mm.pose, mm.betas, mm.trans, return_vertices=False).joints
    err = (Jm - mirror_points(J[:, list(MIRROR)])).norm(dim=-1)
    assert float(err.max()) < 1e-3, float(err.max())
    assert torch.allclose(torch.linalg.det(mm.pose), torch.ones(40, 24, dtype=torch.float64), atol=1e-9)
    back = mirror(mm, root)
    assert torch.allclose(back.pose, m.pose, atol=1e-12) and torch.allclose(back.trans, m.trans, atol=1e-12)
    assert mm.meta["augment"] == ["mirror"] and "augment" not in m.meta
    # A left-leaning clip becomes right-leaning: the pelvis path is reflected.
    assert torch.allclose(Jm[:, 0, 0], -J[:, 0, 0], atol=1e-9)


def test_play_speed_scales_time_and_validates() -> None:
    m = smooth_motion(T=121, fps=60.0, seed=1, amp=0.3)
    fast = play_speed(m, 1.25)
    assert fast.fps == pytest.approx(75.0) and torch.equal(fast.pose, m.pose)
    assert fast.meta["augment"] == ["speed=1.25"]
    r = resample(fast, 60.0)
    assert r.duration == pytest.approx(m.duration / 1.25, abs=1 / 60)
    for bad in (0.0, -1.0, math.nan, math.inf):
        with pytest.raises(ShapeError, match="play_speed"):
            play_speed(m, bad)
