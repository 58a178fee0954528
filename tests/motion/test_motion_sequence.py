"""MotionSequence: validation, basic operations, npz round trip and the validating reader."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch

from wearpose.errors import InputFileError, ShapeError
from wearpose.motion import MotionSequence
from motion_testutils import random_rotations


def make_seq(T: int = 12, fps: float = 30.0, seed: int = 0) -> MotionSequence:
    g = torch.Generator().manual_seed(seed)
    pose = random_rotations(T * 24, g).reshape(T, 24, 3, 3).float()
    return MotionSequence(pose, torch.randn(10, generator=g), torch.randn(T, 3, generator=g), fps,
                          {"clip": "x", "subject": "s", "nested": {"a": [1, 2]}})


def test_basic_facts_and_slice() -> None:
    s = make_seq(12, 30.0)
    assert s.num_frames == 12 and len(s) == 12
    assert s.duration == pytest.approx(12 / 30)
    sub = s.slice(2, 10, 2)
    assert sub.num_frames == 4 and sub.fps == 15.0
    assert torch.equal(sub.pose[1], s.pose[4]) and torch.equal(sub.trans[1], s.trans[4])
    sub.meta["clip"] = "changed"
    assert s.meta["clip"] == "x"  # meta is copied, not shared
    d = s.to(torch.float64)
    assert d.pose.dtype == d.betas.dtype == d.trans.dtype == torch.float64
    with pytest.raises(ShapeError):
        s.slice(20, 30)


def test_numpy_input_and_dtype_unification() -> None:
    s = MotionSequence(np.tile(np.eye(3), (5, 24, 1, 1)), np.zeros(10), np.zeros((5, 3)), 60, {})
    assert s.pose.dtype == torch.float64 and s.trans.dtype == torch.float64 and s.num_frames == 5


@pytest.mark.parametrize("kwargs, msg", [
    ({"pose": torch.zeros(5, 23, 3, 3)}, "pose"),
    ({"pose": torch.zeros(24, 3, 3)}, "pose"),
    ({"betas": torch.zeros(16)}, "betas"),
    ({"trans": torch.zeros(4, 3)}, "frames"),
    ({"trans": torch.zeros(5, 2)}, "trans"),
    ({"fps": 0}, "fps"),
    ({"fps": "abc"}, "fps"),
    ({"meta": []}, "meta"),
])
def test_validation(kwargs: dict, msg: str) -> None:
    args = {"pose": torch.eye(3).repeat(5, 24, 1, 1), "betas": torch.zeros(10), "trans": torch.zeros(5, 3), "fps": 30.0, "meta": {}}
    args.update(kwargs)
    with pytest.raises(ShapeError, match=msg):
        MotionSequence(**args)


def test_save_load_round_trip(tmp_path: Path) -> None:
    s = make_seq(20, 60.0)
    p = s.save(tmp_path / "sub" / "clip.npz")
    r = MotionSequence.load(p)
    assert r.num_frames == 20 and r.fps == 60.0 and r.meta == s.meta
    assert torch.allclose(r.pose, s.pose, atol=2e-6)
    assert torch.allclose(r.trans, s.trans) and torch.allclose(r.betas, s.betas)
    assert MotionSequence.load(p, dtype=torch.float64).pose.dtype == torch.float64


def _write_npz(path: Path, **arrays: np.ndarray) -> Path:
    np.savez(path, **arrays)
    return path


def _good_arrays(T: int = 3) -> dict:
    return {"format": np.array("wearpose.motion"), "version": np.array(1), "pose_aa": np.zeros((T, 24, 3), np.float32),
            "betas": np.zeros(10, np.float32), "trans": np.zeros((T, 3), np.float32), "fps": np.array(30.0),
            "meta": np.array(json.dumps({"a": 1}))}


@pytest.mark.parametrize("change, field", [
    ({"pose_aa": None}, "pose_aa"),
    ({"pose_aa": np.zeros((3, 22, 3))}, "pose_aa"),
    ({"betas": np.zeros(16)}, "betas"),
    ({"trans": np.zeros((4, 3))}, "trans"),
    ({"fps": np.array(-1.0)}, "fps"),
    ({"format": np.array("something.else")}, "format"),
    ({"version": np.array(99)}, "version"),
    ({"meta": np.array("[1, 2")}, "meta"),
    ({"trans": np.full((3, 3), np.nan)}, "trans"),
])
def test_reader_errors_name_the_key(tmp_path: Path, change: dict, field: str) -> None:
    arrays = _good_arrays()
    for k, v in change.items():
        if v is None:
            del arrays[k]
        else:
            arrays[k] = v
    p = _write_npz(tmp_path / "bad.npz", **arrays)
    with pytest.raises(InputFileError) as ei:
        MotionSequence.load(p)
    assert ei.value.field == field and ei.value.path == p and "Expected" in str(ei.value)


def test_reader_missing_and_garbage_file(tmp_path: Path) -> None:
    with pytest.raises(InputFileError, match="not found"):
        MotionSequence.load(tmp_path / "nope.npz")
    bad = tmp_path / "garbage.npz"
    bad.write_bytes(b"not a zip")
    with pytest.raises(InputFileError, match=r"not an npz \(zip\) archive"):
        MotionSequence.load(bad)
    assert MotionSequence.load(_write_npz(tmp_path / "ok.npz", **_good_arrays())).num_frames == 3
