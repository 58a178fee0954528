"""AMASS npz reader/writer: Z-up <-> Y-up with the pelvis-centred translation fix."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import torch

from wearpose.body.kinematics import forward_kinematics
from wearpose.errors import InputFileError
from wearpose.geometry import axis_angle_to_matrix
from wearpose.motion import MotionSequence, read_amass, save_amass, template_rest_joints

REST = template_rest_joints()


def joints(seq: MotionSequence, rest: torch.Tensor = REST) -> torch.Tensor:
    _, J = forward_kinematics(seq.pose.double(), rest)
    return J + seq.trans.double()[:, None]


def random_seq(T: int = 10, seed: int = 0) -> MotionSequence:
    g = torch.Generator().manual_seed(seed)
    aa = torch.randn(T, 24, 3, generator=g, dtype=torch.float64) * 0.4
    aa[:, 22:] = 0  # SMPL-H has no SMPL hand joints
    return MotionSequence(axis_angle_to_matrix(aa), torch.randn(10, generator=g) * 0.5,
                          torch.randn(T, 3, generator=g, dtype=torch.float64), 120.0, {"gender": "female"})


@pytest.mark.parametrize("layout", ["smplh", "smpl"])
def test_write_then_read_gives_the_same_joints(tmp_path: Path, layout: str) -> None:
    seq = random_seq()
    p = save_amass(seq, tmp_path / "a.npz", REST, layout=layout)
    with np.load(p) as d:
        assert d["poses"].shape == ((10, 156) if layout == "smplh" else (10, 72))
        assert d["betas"].shape == ((16,) if layout == "smplh" else (10,))
        assert float(d["mocap_framerate"]) == 120.0 and str(d["gender"]) == "female"
    back = read_amass(p, REST)
    assert back.fps == 120.0 and back.meta["gender"] == "female" and back.meta["source_format"] == "amass"
    assert float((joints(back) - joints(seq)).abs().max()) < 1e-5
    assert torch.allclose(back.betas, seq.betas.float())


def test_hand_built_z_up_file_reads_y_up(tmp_path: Path) -> None:
    """A standing body in AMASS's Z-up world: root rotation +90 deg about X stands SMPL's Y-up
    body up along Z; it must come out with the identity root rotation and joints equal to the
    Z-up joints rotated by Z_UP_TO_Y_UP, (x, y, z) -> (x, z, -y)."""
    T = 4
    poses = np.zeros((T, 156))
    poses[:, 0] = math.pi / 2  # root: +90 deg about X (SMPL's +Y -> world +Z)
    poses[:, 3 * 4] = 0.5  # left knee bend, so the body is not symmetric
    trans = np.stack([np.linspace(0, 1, T), np.full(T, 2.0), np.full(T, 0.9)], -1)  # walks along +X
    path = tmp_path / "raw.npz"
    np.savez(path, poses=poses, trans=trans, betas=np.zeros(16), mocap_frame_rate=np.array(60.0), gender=np.array("male"))
    seq = read_amass(path, REST)
    # Reference: the Z-up joints computed directly, then rotated into Y-up.
    R = axis_angle_to_matrix(torch.from_numpy(poses[:, :72]).reshape(T, 24, 3))
    _, Jz = forward_kinematics(R, REST)
    Jz = Jz + torch.from_numpy(trans)[:, None]
    C = torch.tensor([[1.0, 0, 0], [0, 0, 1], [0, -1, 0]], dtype=torch.float64)
    assert float((joints(seq) - Jz @ C.T).abs().max()) < 1e-5
    # Root rotation is the identity in Y-up: the body stands upright, facing +Z.
    assert torch.allclose(seq.pose[:, 0].double(), torch.eye(3, dtype=torch.float64).expand(T, 3, 3), atol=1e-6)
    J = joints(seq)
    assert bool((J[:, 15, 1] > J[:, 0, 1]).all())  # head above pelvis (Y up)
    # SMPL rotates about the pelvis joint, so the pelvis is at J0 + t in Z-up, C (J0 + t) in Y-up.
    assert torch.allclose(J[:, 0], (REST[0] + torch.from_numpy(trans)) @ C.T, atol=1e-6)
    assert torch.allclose(seq.trans.double(), (torch.from_numpy(trans) + REST[0]) @ C.T - REST[0], atol=1e-6)
    assert seq.fps == 60.0 and seq.meta["gender"] == "male"
    assert torch.allclose(seq.pose[:, 22:].double(), torch.eye(3, dtype=torch.float64).expand(T, 2, 3, 3))


def test_pelvis_correction_matters(tmp_path: Path) -> None:
    """Reading with a different rest pelvis changes trans exactly by the documented formula."""
    seq = random_seq(3)
    p = save_amass(seq, tmp_path / "b.npz", REST)
    other = REST.clone()
    other[0] += torch.tensor([0.0, 0.1, 0.0], dtype=torch.float64)
    a, b = read_amass(p, REST), read_amass(p, other)
    C = torch.tensor([[1.0, 0, 0], [0, 0, 1], [0, -1, 0]], dtype=torch.float64)
    d = torch.tensor([0.0, 0.1, 0.0], dtype=torch.float64)
    assert torch.allclose(b.trans.double() - a.trans.double(), (C @ d - d).expand(3, 3), atol=1e-6)
    # The pelvis alone as (3,) is accepted.
    assert torch.allclose(read_amass(p, REST[0]).trans, a.trans)


@pytest.mark.parametrize("drop, change, field", [
    ("poses", None, "poses"), ("trans", None, "trans"), ("betas", None, "betas"), ("mocap_framerate", None, "mocap_frame_rate"),
    (None, {"poses": np.zeros((5, 50))}, "poses"), (None, {"trans": np.zeros((4, 3))}, "trans"),
    (None, {"betas": np.zeros(5)}, "betas"), (None, {"mocap_framerate": np.array(0.0)}, "mocap_framerate"),
    (None, {"poses": np.full((5, 156), np.nan)}, "poses"),
])
def test_malformed_files_name_the_key(tmp_path: Path, drop: str | None, change: dict | None, field: str) -> None:
    arrays = {"poses": np.zeros((5, 156)), "trans": np.zeros((5, 3)), "betas": np.zeros(16),
              "mocap_framerate": np.array(30.0), "gender": np.array("neutral")}
    if drop:
        del arrays[drop]
    arrays.update(change or {})
    p = tmp_path / "bad.npz"
    np.savez(p, **arrays)
    with pytest.raises(InputFileError) as ei:
        read_amass(p, REST)
    assert ei.value.field == field and ei.value.path == p and ei.value.expected


def test_missing_and_pickled_files(tmp_path: Path) -> None:
    with pytest.raises(InputFileError, match="not found"):
        read_amass(tmp_path / "none.npz", REST)
    p = tmp_path / "obj.npz"
    np.savez(p, poses=np.array([object()], dtype=object))
    with pytest.raises(InputFileError, match="readable"):
        read_amass(p, REST)
