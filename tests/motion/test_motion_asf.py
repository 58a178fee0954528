"""ASF/AMC reader: a hand-worked case, known rotations read back exactly, malformed files."""

from __future__ import annotations

import pytest
import torch

from wearpose.errors import InputFileError
from wearpose.motion import bvh_forward_kinematics, end_site_positions, template_rest_joints
from wearpose.motion.asf import find_asf_for, parse_amc_text, parse_asf_text, read_asf_amc, asf_amc_to_motion
from import_testutils import custom_skeleton_motion, joint_tree_to_asf_amc
from motion_testutils import synthetic_smpl_motion

REST = template_rest_joints()

HAND_ASF = """# two bones
:version 1.10
:name hand
:units
  mass 1.0
  length 1.0
  angle deg
:root
  order TX TY TZ RX RY RZ
  axis XYZ
  position 0 0 0
  orientation 0 0 0
:bonedata
  begin
    id 1
    name a
    direction 1 0 0
    length 2
    axis 0 0 90 XYZ
    dof rx
    limits (-180.0 180.0)
  end
  begin
    id 2
    name b
    direction 0 1 0
    length 1
    axis 0 0 0 XYZ
    dof rz ry
    limits (-180 180)
           (-180 180)
  end
:hierarchy
  begin
    root a
    a b
  end
"""
HAND_AMC = """:FULLY-SPECIFIED
:DEGREES
1
root 1 2 3 0 0 0
a 90
b 90 0
2
root 1 2 3 0 0 0
a 0
b 0 90
"""


def test_hand_worked_case() -> None:
    """a: C = Rz(90), M = Rx(90) -> L = C M C^-1 = Ry(90): the bone (2,0,0) turns to (0,0,-2).
    b then turns its (0,1,0) by Rz(90) -> (-1,0,0) in a's frame -> Ry(90) -> (0,0,1) in the world."""
    asf = parse_asf_text(HAND_ASF, "hand.asf")
    m = asf_amc_to_motion(asf, parse_amc_text(HAND_AMC, asf, "hand.amc"), fps=30)
    G, P = bvh_forward_kinematics(m)
    ends = end_site_positions(m, G, P)
    b = m.skeleton.index("b")
    assert torch.allclose(P[0, 0], torch.tensor([1.0, 2, 3], dtype=torch.float64))
    assert torch.allclose(P[0, b], torch.tensor([1.0, 2, 1], dtype=torch.float64), atol=1e-12)
    assert torch.allclose(ends[b][0, 0], torch.tensor([1.0, 2, 2], dtype=torch.float64), atol=1e-12)
    # Frame 2: a straight; b: ry 90 about world y turns (0,1,0)... ry leaves y fixed.
    assert torch.allclose(P[1, b], torch.tensor([3.0, 2, 3], dtype=torch.float64), atol=1e-12)
    assert torch.allclose(ends[b][1, 0], torch.tensor([3.0, 3, 3], dtype=torch.float64), atol=1e-12)
    assert asf.units_to_m == pytest.approx(0.0254) and m.fps == 30 and m.meta["fps_assumed"] is False


def test_dof_order_matters() -> None:
    """'dof rz ry' composes as Ry @ Rz (fixed axes, applied in the listed order)."""
    asf = parse_asf_text(HAND_ASF)
    amc = ":FULLY-SPECIFIED\n:DEGREES\n1\nroot 0 0 0 0 0 0\na 0\nb 90 90\n"
    m = asf_amc_to_motion(asf, parse_amc_text(amc, asf))
    G, P = bvh_forward_kinematics(m)
    ends = end_site_positions(m, G, P)
    # (0,1,0) -Rz(90)-> (-1,0,0) -Ry(90)-> (0,0,1); the other order would give (-1,0,0).
    assert torch.allclose(ends[m.skeleton.index("b")][0, 0] - P[0, m.skeleton.index("b")],
                          torch.tensor([0.0, 0, 1], dtype=torch.float64), atol=1e-12)


@pytest.mark.parametrize("angle,length_mult", [("deg", 0.45), ("rad", 1.0)])
def test_known_rotations_read_back_exactly(tmp_path, angle: str, length_mult: float) -> None:
    """ASF/AMC written from known SMPL-tree rotations (random bone axes and dof orders, link
    bones) reads back to the same global joint positions within 1e-4 m."""
    local, pelvis = synthetic_smpl_motion(REST, T=12, seed=3)
    sk = custom_skeleton_motion(local, pelvis, REST, scale=1.0 / 0.0254, z_up=False)  # inches
    asf_text, amc_text, bones = joint_tree_to_asf_amc(sk, length_mult=length_mult, angle=angle, seed=2,
                                                       root_order="RZ TX RX TY RY TZ")
    (tmp_path / "s.asf").write_text(asf_text)
    (tmp_path / "s_01.amc").write_text(amc_text)
    m = read_asf_amc(tmp_path / "s_01.amc", fps=60)
    assert find_asf_for(tmp_path / "s_01.amc") == tmp_path / "s.asf"
    _, P = bvh_forward_kinematics(m)
    P = P * m.meta["units_to_m"]
    want = sk["pos"] * 0.0254
    for k, name in enumerate(sk["names"]):
        j = 0 if k == 0 else m.skeleton.index(bones[name])
        err = float((P[:, j] - want[:, k]).norm(dim=-1).max())
        assert err < 1e-4, (name, err)
    assert m.num_frames == 12 and m.fps == 60
    # The column-wise fast path (regular files) and the line-by-line parser read the same values.
    asf = parse_asf_text(asf_text)
    fast, slow = parse_amc_text(amc_text, asf), parse_amc_text(amc_text, asf, strict=True)
    assert fast.keys() == slow.keys() and all((fast[k] == slow[k]).all() for k in slow)


def _bad(text_asf: str = HAND_ASF, text_amc: str = HAND_AMC) -> InputFileError:
    with pytest.raises(InputFileError) as ei:
        asf = parse_asf_text(text_asf, "bad.asf")
        parse_amc_text(text_amc, asf, "bad.amc")
    return ei.value


def test_malformed_files_name_file_line_and_problem() -> None:
    e = _bad(HAND_ASF.replace("angle deg", "angle grad"))
    assert "bad.asf" in str(e) and "line 7" in str(e) and "grad" in str(e) and "deg" in e.expected
    e = _bad(HAND_ASF.replace("length 1.0", "length inches"))
    assert "line 6" in str(e)
    e = _bad(text_amc=HAND_AMC.rsplit("b 0 90", 1)[0])  # truncated: last frame lacks bone b
    assert "bad.amc" in str(e) and "frame 1" in str(e) and "bone b" in str(e)
    e = _bad(text_amc=HAND_AMC.replace("b 90 0", "b 90"))  # value count mismatch
    assert "line 6" in str(e) and "bone b" in str(e) and "2 values" in e.expected
    e = _bad(text_amc=HAND_AMC.replace("a 0", "c 0"))
    assert "unknown bone 'c'" in str(e)
    e = _bad(HAND_ASF.replace("    a b\n", "    a b zz\n"))
    assert "unknown bone 'zz'" in str(e) and "bad.asf" in str(e)
    e = _bad(HAND_ASF.replace("    dof rz ry\n", "    dof rz rq\n"))
    assert "rq" in str(e) and "line 29" in str(e)
    e = _bad(text_amc=HAND_AMC.replace("a 0\n", "a nan\n"))  # read fast, then found and named
    assert "line 9" in str(e) and "'nan'" in str(e)
    e = _bad(text_amc=HAND_AMC.replace(":DEGREES", ":RADIANS"))
    assert "angle" in str(e).lower() or "rad" in str(e)


def test_missing_asf_is_named(tmp_path) -> None:
    (tmp_path / "x_01.amc").write_text(HAND_AMC)
    with pytest.raises(InputFileError, match="no .asf skeleton"):
        read_asf_amc(tmp_path / "x_01.amc")
