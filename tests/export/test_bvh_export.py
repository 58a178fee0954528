"""SMPL-skeleton BVH export: readable by our BVH parser and back to the same motion."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from tests.conftest import SMPL_LIKE_REST, make_tiny_asset
from wearpose.body import JOINT_NAMES, BodyModel, forward_kinematics
from wearpose.errors import InputFileError, WearposeError
from wearpose.export import export_motion, write_smpl_bvh
from wearpose.geometry import axis_angle_to_matrix, geodesic_angle
from wearpose.motion import MotionSequence, bvh_forward_kinematics, load_motion, read_bvh, read_smpl_bvh

REST = torch.tensor(SMPL_LIKE_REST, dtype=torch.float64)


def _motion(T: int = 12) -> MotionSequence:
    g = torch.Generator().manual_seed(1)
    pose = axis_angle_to_matrix(torch.randn(T, 24, 3, generator=g, dtype=torch.float64) * 0.6)
    trans = torch.cumsum(torch.randn(T, 3, generator=g, dtype=torch.float64) * 0.02, 0)
    return MotionSequence(pose, torch.zeros(10, dtype=torch.float64), trans, 60.0)


def test_round_trip_is_exact_to_print_precision(tmp_path: Path) -> None:
    seq = _motion()
    path = write_smpl_bvh(seq, tmp_path / "m.bvh", REST)
    back = read_smpl_bvh(path, REST)
    assert back.fps == 60.0 and back.num_frames == seq.num_frames
    ang = geodesic_angle(back.pose.double(), seq.pose).max()
    assert ang < 1e-6, ang
    np.testing.assert_allclose(back.trans.numpy(), seq.trans.numpy(), atol=1e-6)
    # load_motion recognises our own export and skips retargeting
    again = load_motion(path, rest_joints=REST)
    assert geodesic_angle(again.pose.double(), seq.pose).max() < 1e-6


def test_bvh_world_joints_equal_smpl_joints(tmp_path: Path) -> None:
    """Any BVH tool sees the same skeleton motion: our generic BVH FK gives SMPL's joints (cm)."""
    seq = _motion()
    path = write_smpl_bvh(seq, tmp_path / "m.bvh", REST)
    motion = read_bvh(path)
    _, world = bvh_forward_kinematics(motion)  # (T, J, 3) cm, BVH joint order
    idx = [motion.skeleton.names.index(n) for n in JOINT_NAMES]
    _, joints = forward_kinematics(seq.pose, REST)
    joints = joints + seq.trans[:, None]
    np.testing.assert_allclose(world[:, idx].numpy() / 100.0, joints.numpy(), atol=1e-6)


def test_other_skeletons_are_refused_by_the_exact_reader(tmp_path: Path) -> None:
    p = tmp_path / "other.bvh"
    p.write_text("HIERARCHY\nROOT hip\n{\n OFFSET 0 0 0\n CHANNELS 3 Zrotation Xrotation Yrotation\n End Site\n {\n OFFSET 0 1 0\n }\n}\n"
                 "MOTION\nFrames: 1\nFrame Time: 0.1\n0 0 0\n")
    with pytest.raises(InputFileError, match="not SMPL's 24-joint tree"):
        read_smpl_bvh(p, REST)


def test_export_by_extension(tmp_path: Path) -> None:
    seq = _motion(4)
    body = BodyModel(make_tiny_asset(), dtype=torch.float64)
    for ext in (".bvh", ".npz", ".glb"):
        assert export_motion(seq, tmp_path / f"a{ext}", body).stat().st_size > 1000
    with pytest.raises(WearposeError, match="unknown export format"):
        export_motion(seq, tmp_path / "a.fbx", body)
