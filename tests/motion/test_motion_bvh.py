"""BVH reader on small hand-written files, including every error case."""

from __future__ import annotations

import gzip
import math
from pathlib import Path

import numpy as np
import pytest
import torch

from wearpose.errors import InputFileError
from wearpose.geometry import euler_to_matrix
from wearpose.motion import bvh_forward_kinematics, end_site_positions, parse_bvh_text, read_bvh

# Root: 6 channels (position, then Z Y X like CMU's root); spine: 3 channels ZXY; arm: 6
# channels whose position replaces the OFFSET (Bandai style); hand: a single Yrotation channel;
# tip: no channels at all.
SAMPLE = """HIERARCHY
ROOT hip
{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Yposition Zposition Zrotation Yrotation Xrotation
  JOINT spine
  {
    OFFSET 0 10 0
    CHANNELS 3 Zrotation Xrotation Yrotation
    End Site
    {
      OFFSET 0 5 0
    }
  }
  JOINT arm
  {
    OFFSET 99 99 99
    CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
    JOINT hand
    {
      OFFSET 20 0 0
      CHANNELS 1 Yrotation
      JOINT tip
      {
        OFFSET 3 0 0
        CHANNELS 0
        End Site
        {
          OFFSET 1 0 0
        }
      }
    }
  }
}
MOTION
Frames: 2
Frame Time: 0.0333333
1 2 3 0 0 0 0 0 0 10 0 0 0 0 0 0
0 100 0 90 0 0 30 45 60 10 0 0 0 0 90 -90
"""


def test_hierarchy_and_channels() -> None:
    m = parse_bvh_text(SAMPLE, "sample.bvh")
    s = m.skeleton
    assert s.names == ("hip", "spine", "arm", "hand", "tip")
    assert s.parents == (-1, 0, 0, 2, 3)
    assert s.num_channels == 16
    assert s.channels[3] == ("Yrotation",) and s.channels[4] == ()
    assert np.allclose(s.offsets[2], [99, 99, 99])
    assert np.allclose(s.end_sites[1], [[0, 5, 0]]) and np.allclose(s.end_sites[4], [[1, 0, 0]])
    assert m.num_frames == 2 and m.fps == 30.0  # 0.0333333 snaps to 30 Hz


def test_rotation_order_and_position_channels() -> None:
    m = parse_bvh_text(SAMPLE)
    d = math.radians
    # Root channels listed Z Y X -> R = Rz @ Ry @ Rx.
    want_root = euler_to_matrix(torch.tensor([d(90), d(0), d(0)], dtype=torch.float64), "ZYX")
    assert torch.allclose(m.rotations[1, 0], want_root)
    want_spine = euler_to_matrix(torch.tensor([d(30), d(45), d(60)], dtype=torch.float64), "ZXY")
    assert torch.allclose(m.rotations[1, 1], want_spine)
    # Position channels replace the OFFSET (99 99 99), not add to it.
    assert torch.allclose(m.translations[:, 2], torch.tensor([[10.0, 0, 0]] * 2, dtype=torch.float64))
    assert torch.allclose(m.translations[0, 0], torch.tensor([1.0, 2, 3], dtype=torch.float64))
    assert torch.allclose(m.rotations[1, 3], euler_to_matrix(torch.tensor([d(-90)], dtype=torch.float64), "Y"))
    assert torch.allclose(m.translations[:, 4], torch.tensor([3.0, 0, 0], dtype=torch.float64))


def test_forward_kinematics_by_hand() -> None:
    m = parse_bvh_text(SAMPLE)
    R, P = bvh_forward_kinematics(m)
    # Frame 0: no rotation; arm at root + (10,0,0), hand +20 in x, tip +3.
    assert torch.allclose(P[0], torch.tensor([[1, 2, 3], [1, 12, 3], [11, 2, 3], [31, 2, 3], [34, 2, 3]], dtype=torch.float64))
    # Frame 1: root yawed 90 deg about Z at (0, 100, 0): x -> y. Arm local (10,0,0) -> (0,10,0);
    # arm rotated 90 about Y (last channel... Zrot 0, Xrot 0, Yrot 90): x -> -z, then root z-rot.
    assert torch.allclose(P[1, 2], torch.tensor([0.0, 110.0, 0.0], dtype=torch.float64), atol=1e-9)
    hand_world = P[1, 2] + R[1, 2] @ torch.tensor([20.0, 0, 0], dtype=torch.float64)
    assert torch.allclose(P[1, 3], hand_world)
    assert torch.allclose(P[1, 3], torch.tensor([0.0, 110.0, -20.0], dtype=torch.float64), atol=1e-9)
    # Hand Yrotation -90 undoes the arm's +90: the tip points along the root's x again (world +y).
    assert torch.allclose(P[1, 4], torch.tensor([0.0, 113.0, -20.0], dtype=torch.float64), atol=1e-9)
    ends = end_site_positions(m, R, P)
    assert torch.allclose(ends[4][1, 0], torch.tensor([0.0, 114.0, -20.0], dtype=torch.float64), atol=1e-9)


def test_gzip_and_plain_files(tmp_path: Path) -> None:
    plain = tmp_path / "a.bvh"
    plain.write_text(SAMPLE)
    gz = tmp_path / "a.bvh.gz"
    with gzip.open(gz, "wt") as f:
        f.write(SAMPLE.replace("\n", "\r\n"))  # CRLF files are read too
    a, b = read_bvh(plain), read_bvh(gz)
    assert torch.equal(a.rotations, b.rotations) and a.path == plain


def _err(text: str, tmp_path: Path) -> InputFileError:
    p = tmp_path / "bad.bvh"
    p.write_text(text)
    with pytest.raises(InputFileError) as ei:
        read_bvh(p)
    e = ei.value
    assert e.path == p and str(p) in str(e) and e.expected
    return e


def test_missing_file(tmp_path: Path) -> None:
    with pytest.raises(InputFileError, match="not found"):
        read_bvh(tmp_path / "none.bvh")


def test_truncated_motion(tmp_path: Path) -> None:
    e = _err(SAMPLE.replace("Frames: 2", "Frames: 3"), tmp_path)
    assert "truncated" in e.problem and "3" in e.expected and e.field.startswith("line")


def test_wrong_channel_count_on_a_line(tmp_path: Path) -> None:
    lines = SAMPLE.splitlines()
    lines[-1] = lines[-1] + " 7"
    e = _err("\n".join(lines) + "\n", tmp_path)
    assert e.field == f"line {len(lines)}" and "17 values" in e.problem and "16 numbers" in e.expected


def test_non_numeric_value(tmp_path: Path) -> None:
    lines = SAMPLE.splitlines()
    lines[-2] = lines[-2].replace("1 2 3", "1 x2 3", 1)
    e = _err("\n".join(lines), tmp_path)
    assert "x2" in e.problem and e.field == f"line {len(lines) - 1}, value 2 (hip Yposition)"


def test_nan_value(tmp_path: Path) -> None:
    lines = SAMPLE.splitlines()
    lines[-1] = lines[-1].replace("-90", "nan")
    e = _err("\n".join(lines), tmp_path)
    assert "nan" in e.problem and "tip" not in e.field and "hand Yrotation" in e.field


def test_unknown_channel_name(tmp_path: Path) -> None:
    e = _err(SAMPLE.replace("CHANNELS 1 Yrotation", "CHANNELS 1 Yrot"), tmp_path)
    assert "Yrot" in e.problem and "hand" in e.problem and e.field == "line 22" and "Xposition" in e.expected


def test_missing_motion_and_bad_headers(tmp_path: Path) -> None:
    assert _err(SAMPLE.split("MOTION")[0], tmp_path).field == "MOTION"
    assert "Frames" in _err(SAMPLE.replace("Frames: 2", "Frames: two"), tmp_path).expected
    assert "Frame Time" in _err(SAMPLE.replace("Frame Time: 0.0333333", "Frame Time: -1"), tmp_path).expected
    assert "more motion lines" in _err(SAMPLE.replace("Frames: 2", "Frames: 1"), tmp_path).problem


def test_malformed_hierarchy(tmp_path: Path) -> None:
    e = _err(SAMPLE.replace("OFFSET 20 0 0", "OFFSET 20 zero 0"), tmp_path)
    assert "zero" in e.problem and e.field == "line 21"
    e = _err(SAMPLE.replace("CHANNELS 3 Zrotation", "CHANNELS three Zrotation"), tmp_path)
    assert "channel count" in e.problem
    e = _err(SAMPLE.replace("  JOINT spine", "  JOYNT spine"), tmp_path)
    assert "JOYNT" in e.problem and e.field == "line 6"
    e = _err(SAMPLE.replace("HIERARCHY", "HIERARCH"), tmp_path)
    assert e.field == "line 1"
    e = _err(SAMPLE.replace("JOINT tip", "JOINT spine"), tmp_path)
    assert "duplicate" in e.problem
