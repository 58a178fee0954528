"""Helpers for sensor tests: a smooth synthetic motion and a tiny body with every anny site name."""

from __future__ import annotations

import math

import pytest
import torch

from tests.conftest import make_tiny_asset
from wearpose.body import BodyModel
from wearpose.body.asset import BodyAsset
from wearpose.geometry import axis_angle_to_matrix
from wearpose.motion.sequence import MotionSequence


def smooth_motion(T: int = 240, fps: float = 60.0, seed: int = 0, amp: float = 0.5, dtype=torch.float64) -> MotionSequence:
    """Sum-of-sinusoids joint angles and a walking root: smooth, deterministic."""
    g = torch.Generator().manual_seed(seed)
    t = torch.arange(T, dtype=torch.float64) / fps
    a = amp * torch.rand(24, 3, generator=g, dtype=torch.float64)
    f = 0.2 + 1.3 * torch.rand(24, 3, generator=g, dtype=torch.float64)
    ph = 2 * math.pi * torch.rand(24, 3, generator=g, dtype=torch.float64)
    aa = a * torch.sin(2 * math.pi * f * t[:, None, None] + ph)
    trans = torch.stack([0.4 * t, 0.02 * torch.sin(2 * math.pi * t), 0.2 * torch.sin(0.5 * t)], -1)
    return MotionSequence(axis_angle_to_matrix(aa).to(dtype), torch.zeros(10, dtype=dtype), trans.to(dtype), fps)


def tiny_full_sites_asset() -> BodyAsset:
    """The tiny test asset with every site name of wearpose_anny_v1 (sites on the joint tetrahedra)."""
    a = make_tiny_asset()
    names = ["head", "sternum", "back_upper", "pelvis"] + [
        lr + p for p in ("upper_arm", "forearm", "wrist", "thigh", "shin", "foot") for lr in ("left_", "right_")] + [
        "left_shoulder", "right_shoulder"]
    # joint of each site (SMPL order): head 15, spine3 9, spine2 6, pelvis 0, shoulders 16/17,
    # elbows 18/19, wrists 20/21, hips 1/2, knees 4/5, ankles 7/8; shoulder sites on the collars 13/14.
    joints = [15, 9, 6, 0, 16, 17, 18, 19, 20, 21, 1, 2, 4, 5, 7, 8, 13, 14]
    vids = [4 * j for j in joints]
    tids = [4 * j + 1 for j in joints]
    return BodyAsset(v_template=a.v_template, faces=a.faces, shapedirs=a.shapedirs, J_regressor=a.J_regressor,
                     weights=a.weights, parents=a.parents, posedirs=None, site_names=tuple(names),
                     site_vertices=torch.tensor(vids).numpy(), site_tangent=torch.tensor(tids).numpy(),
                     meta={"asset_id": "tiny-all-sites"})




def rand_R(*shape: int, seed: int = 0) -> torch.Tensor:
    """Random rotations ``(*shape, 3, 3)``, float64, seeded."""
    g = torch.Generator().manual_seed(seed)
    return axis_angle_to_matrix(torch.randn(*shape, 3, generator=g, dtype=torch.float64))
