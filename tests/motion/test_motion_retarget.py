"""Retargeting on a synthetic BVH made from known SMPL motion with random joint orients."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from wearpose.body.kinematics import forward_kinematics
from wearpose.body.skeleton import JOINT_INDEX
from wearpose.geometry import geodesic_angle, rotation_y
from wearpose.motion import (
    BANDAI, CMU_DAZ, RetargetError, bone_direction_errors, detect_skeleton_map, estimate_hinge_axes,
    parse_bvh_text, retarget_bvh, template_rest_joints,
)
from wearpose.motion.bvh import BvhSkeleton
from motion_testutils import SYN_JOINTS, SYN_MAP, synthetic_bvh_from_smpl, synthetic_smpl_motion

REST = template_rest_joints()


@pytest.fixture(scope="module")
def synthetic() -> tuple:
    local, pelvis = synthetic_smpl_motion(REST, T=60, seed=0)
    text, O = synthetic_bvh_from_smpl(REST, local, pelvis, seed=1)
    motion = parse_bvh_text(text, "synthetic.bvh")
    return local, pelvis, motion, O


@pytest.mark.parametrize("hinge", ["clip", "auto"])
def test_recovers_the_source_motion(synthetic: tuple, hinge: str) -> None:
    """The BVH frames carry arbitrary constant orients (like Bandai's), so only a correct rest
    correction (bone directions + lateral vectors + hinge axes + minimal twist along straight
    chains) gives back SMPL's global rotations, twist included."""
    local, pelvis, motion, _ = synthetic
    res = retarget_bvh(motion, REST, SYN_MAP, hinge=hinge)
    G_true, _ = forward_kinematics(local, REST)
    G_out, _ = forward_kinematics(res.sequence.pose.double(), REST)
    for name in SYN_JOINTS:
        j = JOINT_INDEX[name]
        err = geodesic_angle(G_out[:, j], G_true[:, j]).max()
        assert float(err) < 1e-4, (name, float(err))
    assert res.tpose.hinge_source == {h: "clip" for h in ("left_knee", "right_knee", "left_elbow", "right_elbow")}
    # Same legs -> scale 1; the SMPL pelvis joint lands on the BVH pelvis.
    assert res.tpose.scale == pytest.approx(1.0, abs=1e-6)
    assert torch.allclose(res.sequence.trans.double() + REST[0], pelvis, atol=1e-5)
    errs = bone_direction_errors(res, REST)
    assert len(errs) == 11 and max(float(v.max()) for v in errs.values()) < 1e-3


def test_mean_twist_rule_recovers_twisted_rig_joints() -> None:
    """Spine1 and collars with random orients (a twisted zero pose, like Bandai's): the
    mean-twist rule recovers them exactly when the true motion has zero mean twist."""
    from dataclasses import replace

    from motion_testutils import RANDOM_ORIENT, SWING_BONES
    local, pelvis = synthetic_smpl_motion(REST, T=60, seed=4, swing_only=tuple(SWING_BONES))
    text, _ = synthetic_bvh_from_smpl(REST, local, pelvis, seed=6, random_orient=RANDOM_ORIENT + tuple(SWING_BONES))
    motion = parse_bvh_text(text)
    smap = replace(SYN_MAP, mean_twist=tuple(SWING_BONES))
    res = retarget_bvh(motion, REST, smap, hinge="clip")
    G_true, _ = forward_kinematics(local, REST)
    G_out, _ = forward_kinematics(res.sequence.pose.double(), REST)
    for name in SYN_JOINTS:
        j = JOINT_INDEX[name]
        assert float(geodesic_angle(G_out[:, j], G_true[:, j]).max()) < 1e-4, name
    assert set(res.tpose.twist_offsets) == set(SWING_BONES)
    # Without the rule the twisted zero pose leaves a large constant twist error.
    bad = retarget_bvh(motion, REST, SYN_MAP, hinge="clip")
    G_bad, _ = forward_kinematics(bad.sequence.pose.double(), REST)
    assert float(geodesic_angle(G_bad[:, 3], G_true[:, 3]).mean()) > 0.05


def test_spine2_splits_and_hands_follow(synthetic: tuple) -> None:
    _, _, motion, _ = synthetic
    seq = retarget_bvh(motion, REST, SYN_MAP, hinge="clip").sequence
    pose = seq.pose.double()
    # spine2 and spine3 local rotations are equal halves of spine1 -> spine3.
    G, _ = forward_kinematics(pose, REST)
    rel = G[:, 3].transpose(-1, -2) @ G[:, 9]
    half = G[:, 3].transpose(-1, -2) @ G[:, 6]
    assert torch.allclose(half @ half, rel, atol=1e-5)
    eye = torch.eye(3, dtype=torch.float64)
    assert torch.allclose(pose[:, 22], eye.expand_as(pose[:, 22]), atol=1e-6)
    assert torch.allclose(pose[:, 23], eye.expand_as(pose[:, 23]), atol=1e-6)


def test_hinge_axes_estimated_exactly(synthetic: tuple) -> None:
    local, _, motion, O = synthetic
    axes = estimate_hinge_axes(motion, SYN_MAP)
    from motion_testutils import smpl_hinge_axis
    for hinge, seg in (("left_knee", "left_hip"), ("right_elbow", "right_shoulder")):
        a_par, a_child, rms = axes[hinge]
        s = smpl_hinge_axis(REST, hinge)
        assert torch.allclose(a_par, O[seg].T @ s, atol=1e-6)
        assert torch.allclose(a_child, O[hinge].T @ s, atol=1e-6)
        assert rms > math.radians(10)


def test_leg_scale_and_translation_scale(synthetic: tuple) -> None:
    """A SMPL body with longer legs than the BVH scales the root trajectory by the ratio."""
    _, pelvis, motion, _ = synthetic
    rest = REST * 1.2
    res = retarget_bvh(motion, rest, SYN_MAP, hinge="clip")
    assert res.tpose.scale == pytest.approx(1.2, rel=1e-6)
    assert torch.allclose(res.sequence.trans.double() + rest[0], 1.2 * pelvis, atol=1e-5)
    assert math.isfinite(res.lowest_foot_y) and math.isfinite(res.lowest_bvh_foot_y)


def test_meta_and_types(synthetic: tuple) -> None:
    _, _, motion, _ = synthetic
    res = retarget_bvh(motion, REST, SYN_MAP, betas=torch.ones(10), meta={"clip": "c1"})
    s = res.sequence
    assert s.pose.dtype == torch.float32 and s.fps == 30.0 and torch.equal(s.betas, torch.ones(10))
    assert s.meta["skeleton"] == "synthetic" and s.meta["clip"] == "c1" and s.meta["source_format"] == "bvh"
    assert "lowest_foot_y" in s.meta["retarget"]
    with pytest.raises(Exception, match="rest_joints"):
        retarget_bvh(motion, REST[:20], SYN_MAP)


def _skeleton(names: list[str]) -> BvhSkeleton:
    return BvhSkeleton(tuple(names), tuple([-1] + [0] * (len(names) - 1)), np.zeros((len(names), 3)),
                       tuple(() for _ in names))


def test_detect_skeleton_map() -> None:
    assert detect_skeleton_map(_skeleton(["joint_Root", *BANDAI.joints.values()])) is BANDAI
    assert detect_skeleton_map(_skeleton(list(CMU_DAZ.joints.values()) + ["lButtock"])) is CMU_DAZ
    with pytest.raises(RetargetError, match="no built-in SMPL joint map"):
        detect_skeleton_map(_skeleton(["Hips", "Spine"]))


def test_facing_is_preserved_for_a_turned_body(synthetic: tuple) -> None:
    """A BVH body yawed by 90 deg gives a SMPL root yawed by 90 deg (world frames agree)."""
    local, pelvis, _, _ = synthetic
    turned = local.clone()
    turned[:, 0] = rotation_y(torch.tensor(math.pi / 2, dtype=torch.float64)) @ local[:, 0]
    text, _ = synthetic_bvh_from_smpl(REST, turned, pelvis, seed=5)
    res = retarget_bvh(parse_bvh_text(text), REST, SYN_MAP, hinge="clip")
    fwd = res.sequence.pose[:, 0, :, 2].double()  # pelvis +Z (forward) in the world
    want = (rotation_y(torch.tensor(math.pi / 2, dtype=torch.float64)) @ local[:, 0])[:, :, 2]
    assert torch.allclose(fwd, want, atol=1e-4)


def test_root_travel_follows_the_limbs_and_height_the_pelvis_drop(synthetic: tuple) -> None:
    """An SMPL body whose hips sit 6 cm lower under the pelvis but whose limbs match the BVH's:
    the root travels exactly as the source's (the legs reach as far), while the height is scaled by
    the pelvis-to-ankle ratio (feet on the floor where the source's are)."""
    from wearpose.motion import leg_measures

    _, pelvis, motion, _ = synthetic
    rest = REST.clone().double()
    below = [JOINT_INDEX[n] for n in ("left_hip", "right_hip", "left_knee", "right_knee", "left_ankle",
                                      "right_ankle", "left_foot", "right_foot")]
    rest[below, 1] -= 0.06
    res = retarget_bvh(motion, rest, SYN_MAP, hinge="clip")
    lm0, lm1 = leg_measures(REST), leg_measures(rest)
    assert lm1.limb == pytest.approx(lm0.limb, abs=1e-9) and lm1.height == pytest.approx(lm0.height + 0.06, abs=1e-9)
    assert res.tpose.travel_scale == pytest.approx(1.0, abs=1e-6)
    assert res.tpose.scale == pytest.approx(lm1.height / lm0.height, rel=1e-6)
    p = res.sequence.trans.double() + rest[0]
    assert torch.allclose(p[:, [0, 2]], pelvis[:, [0, 2]], atol=1e-5)
    assert torch.allclose(p[:, 1], res.tpose.scale * pelvis[:, 1], atol=1e-5)
    assert res.sequence.meta["retarget"]["travel_scale"] == pytest.approx(1.0, abs=1e-6)


def test_legs_travel_keeps_a_planted_foot_still_where_wider_hips_would_slide_it() -> None:
    """The pelvis yaws +-10 deg over a planted left foot (the right one swings 20 cm up). SMPL's
    hips sit wider apart than the source's, so a root path scaled from the source pelvis (any
    scale) slides SMPL's planted foot; the "legs" path keeps it where the source's is."""
    from wearpose.motion import SkeletonMap, TPose
    from wearpose.motion.retarget import root_path

    T, fps = 90, 30.0
    yaw = torch.deg2rad(10.0 * torch.sin(torch.arange(T, dtype=torch.float64) / fps * 2 * math.pi))
    R = rotation_y(yaw).double()  # (T, 3, 3)
    pose = torch.eye(3, dtype=torch.float64).repeat(T, 24, 1, 1)
    pose[:, 0] = R
    rest = REST.double()
    la, ra = JOINT_INDEX["left_ankle"], JOINT_INDEX["right_ankle"]
    src_rel = torch.tensor([[0.05, -0.85, 0.0], [-0.05, -0.85, 0.0]], dtype=torch.float64)  # narrow hips
    assert float((rest[la] - rest[0])[0]) > 0.08  # SMPL's are wider
    foot_l = torch.tensor([0.3, 0.05, 1.0], dtype=torch.float64)
    pelvis = foot_l - (R @ src_rel[0])
    foot_r = pelvis + R @ src_rel[1] + torch.tensor([0.0, 0.2, 0.0], dtype=torch.float64)
    src = torch.stack([pelvis, foot_l.expand(T, 3), foot_r], dim=1)  # (T, 3, 3)
    smap = SkeletonMap("toy", {"pelvis": "P", "left_ankle": "LA", "right_ankle": "RA"}, units_to_m=1.0)
    tpose = TPose({}, 1.0, {}, travel_scale=1.0)
    _, J = forward_kinematics(pose, rest)
    speeds = {}
    for mode in ("limb", "legs"):
        trans = root_path(pose, src, ("P", "LA", "RA"), smap, tpose, rest, fps, mode)
        foot = J[:, la] + trans
        speeds[mode] = float(torch.diff(foot[:, [0, 2]], dim=0).norm(dim=-1).max() * fps)
        assert torch.allclose(trans[:, 1], pelvis[:, 1] - rest[0, 1])  # height: the source pelvis's
    assert speeds["limb"] > 0.05 and speeds["legs"] < 1e-9, speeds
