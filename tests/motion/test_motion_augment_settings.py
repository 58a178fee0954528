"""One place for augmentation (wearpose.motion.augment): heading, part mixing, site jitter and the
recordable settings."""

from __future__ import annotations

import json
import math

import pytest
import torch

from tests.sensors.sensor_testutils import smooth_motion
from wearpose.body import BodyModel
from wearpose.body.skeleton import JOINT_INDEX
from wearpose.errors import ConfigError, ShapeError
from wearpose.motion.augment import (
    LOWER_BODY, AugmentSettings, augment_clip, augmented_ids, jitter_sites, joint_frame_offsets, mix_parts,
    offset_rest, random_rest_offsets, rotate_heading,
)


@pytest.fixture(scope="module")
def body() -> BodyModel:
    return BodyModel()


def test_heading_turns_every_joint_about_the_vertical(body: BodyModel) -> None:
    seq = smooth_motion(T=30, seed=1).to(torch.float64)
    r = body.rest_joints(seq.betas.to(body.dtype))[0].double()
    out = rotate_heading(seq, math.radians(70.0), r)
    J0 = body(seq.pose, seq.betas, seq.trans, return_vertices=False).joints.double()
    J1 = body(out.pose, out.betas, out.trans, return_vertices=False).joints.double()
    from wearpose.geometry import rotation_y

    Ry = rotation_y(torch.tensor(math.radians(70.0), dtype=torch.float64))
    assert torch.allclose(J1, J0 @ Ry.T, atol=1e-5)
    assert out.meta["augment"] == ["heading=70"]


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_rest_offset_turns_every_joint_frame_by_its_constant(body: BodyModel, dtype: torch.dtype) -> None:
    """G'_j = G_j C_j for every joint and frame (the global frames from the body's own FK)."""
    seq = smooth_motion(T=12, seed=4).to(dtype)
    C = random_rest_offsets(30.0, torch.Generator().manual_seed(3))
    out = offset_rest(seq, C)
    assert out.pose.dtype == dtype and out.meta["augment"] == ["rest_offset"]
    G0 = body(seq.pose, seq.betas, seq.trans, return_vertices=False).global_rot.double()
    G1 = body(out.pose, out.betas, out.trans, return_vertices=False).global_rot.double()
    assert torch.allclose(G1, G0 @ C, atol=1e-5)
    assert torch.equal(out.trans, seq.trans)
    # rotations stay rotations (float32 included)
    eye = torch.eye(3, dtype=dtype)
    assert torch.allclose(out.pose @ out.pose.transpose(-1, -2), eye.expand_as(out.pose), atol=1e-5)


def test_random_rest_offsets_stay_within_the_angle_and_follow_the_generator() -> None:
    from wearpose.geometry import geodesic_angle

    a = random_rest_offsets(20.0, torch.Generator().manual_seed(1))
    b = random_rest_offsets(20.0, torch.Generator().manual_seed(1))
    c = random_rest_offsets(20.0, torch.Generator().manual_seed(2))
    ang = torch.rad2deg(geodesic_angle(a, torch.eye(3, dtype=a.dtype).expand_as(a)))
    assert a.shape == (24, 3, 3) and torch.equal(a, b) and not torch.equal(a, c)
    assert float(ang.max()) <= 20.0 + 1e-9 and float(ang.max()) > 10.0  # 24 uniform draws: one above half
    assert torch.allclose(random_rest_offsets(0.0, torch.Generator()), torch.eye(3, dtype=torch.float64).expand(24, 3, 3))


def test_joint_frame_offsets_recover_the_offsets_of_offset_rest() -> None:
    from wearpose.geometry import geodesic_angle

    seq = smooth_motion(T=20, seed=5).to(torch.float64)
    C = random_rest_offsets(30.0, torch.Generator().manual_seed(8))
    got = joint_frame_offsets(seq.pose, offset_rest(seq, C).pose)
    assert torch.allclose(got.mean, C, atol=1e-9) and float(got.spread_deg.max()) < 1e-5
    assert torch.allclose(got.angle_deg, torch.rad2deg(geodesic_angle(C, torch.eye(3, dtype=C.dtype).expand_as(C))),
                          atol=1e-5)
    same = joint_frame_offsets(seq.pose, seq.pose)
    assert float(same.angle_deg.max()) < 1e-5 and float(same.local_deg.max()) < 1e-5
    with pytest.raises(ShapeError, match="expected both"):
        joint_frame_offsets(seq.pose, seq.pose[:-1])


def test_rest_offsets_on_named_joints_only_keep_the_full_draw_there() -> None:
    full = random_rest_offsets(30.0, torch.Generator().manual_seed(4))
    some = random_rest_offsets(30.0, torch.Generator().manual_seed(4), joints=(13, 14, 12))
    eye = torch.eye(3, dtype=torch.float64)
    assert torch.equal(some[[12, 13, 14]], full[[12, 13, 14]])
    others = [j for j in range(24) if j not in (12, 13, 14)]
    assert torch.allclose(some[others], eye.expand(len(others), 3, 3))
    st = AugmentSettings(rest_offset_deg=20.0, rest_offset_joints=("neck", "left_collar"))
    assert st.to_dict()["rest_offset_joints"] == ["neck", "left_collar"]
    assert AugmentSettings.from_dict(json.loads(json.dumps(st.to_dict()))) == st
    assert "rest_offset_joints" not in AugmentSettings(rest_offset_deg=20.0).to_dict()
    with pytest.raises(ConfigError, match="unknown joints.*'elbow'"):
        AugmentSettings(rest_offset_deg=20.0, rest_offset_joints=("elbow",))


def test_rest_offset_refuses_a_wrong_shape() -> None:
    with pytest.raises(ShapeError, match=r"expected \(24, 3, 3\)"):
        offset_rest(smooth_motion(T=4, seed=1), torch.eye(3).expand(22, 3, 3))


def test_mix_parts_takes_legs_and_path_from_lower(body: BodyModel) -> None:
    a, b = smooth_motion(T=40, seed=2), smooth_motion(T=30, seed=3)
    out = mix_parts(a, b)
    assert out.num_frames == 30
    assert torch.equal(out.pose[:, list(LOWER_BODY)], b.pose[:30, list(LOWER_BODY)])
    upper = [j for j in range(24) if j not in LOWER_BODY]
    assert torch.equal(out.pose[:, upper], a.pose[:30, upper]) and torch.equal(out.trans, b.trans)
    with pytest.raises(ShapeError, match="resample one first"):
        mix_parts(a, b.slice(0, None, 2))


def test_site_jitter_moves_sites_within_radius_on_the_same_part(body: BodyModel) -> None:
    names = ("left_forearm", "head", "pelvis")
    g = torch.Generator().manual_seed(0)
    jb = jitter_sites(body, 0.03, g, names)
    before, after = body.sites(names=names), jb.sites(names=names)
    d = (before.positions - after.positions).norm(dim=-1)
    assert float(d.max()) <= 0.03 + 1e-6 and float(d.max()) > 0.0
    assert torch.equal(body.sites(names=names).positions, before.positions)  # the original is unchanged
    part = body.weights.argmax(1)
    assert all(int(part[int(v)]) == int(part[int(w)]) for v, w in zip(body.site_ids(names)[1], jb.site_ids(names)[1]))
    again = jitter_sites(body, 0.03, torch.Generator().manual_seed(0), names)
    assert (again.site_ids(names)[1] == jb.site_ids(names)[1]).all()


def test_settings_round_trip_json_and_refuse_bad_values() -> None:
    s = AugmentSettings(mirror=True, speed_copies=2, speed_range=(0.7, 1.3), heading_copies=1, mix_copies=1,
                        site_jitter_m=0.02)
    assert AugmentSettings.from_dict(json.loads(json.dumps(s.to_dict()))) == s
    assert augmented_ids(["a"], s) == ["a#mirror", "a#speed0", "a#speed1", "a#heading0", "a#mix0"]
    for bad in ({"speed_range": (1.2, 0.9)}, {"speed_copies": -1}, {"site_jitter_m": 0.5}):
        with pytest.raises(ConfigError):
            AugmentSettings(**bad)
    with pytest.raises(ConfigError, match="unknown key"):
        AugmentSettings.from_dict({"mirorr": True})


def test_augment_clip_by_tag(body: BodyModel) -> None:
    seq, other = smooth_motion(T=30, seed=4), smooth_motion(T=30, seed=5)
    s = AugmentSettings(heading_copies=1, mix_copies=1)
    h = augment_clip("c#heading0", seq, s, torch.Generator().manual_seed(1))
    assert h.meta["augment"][0].startswith("heading=")
    assert torch.equal(h.pose[:, JOINT_INDEX["left_knee"]], seq.pose[:, JOINT_INDEX["left_knee"]])
    m = augment_clip("c#mix0", seq, s, torch.Generator(), partner=other)
    assert torch.equal(m.trans, seq.trans)
    with pytest.raises(ShapeError, match="needs the partner"):
        augment_clip("c#mix0", seq, s, torch.Generator())
    with pytest.raises(ShapeError, match="unknown augmentation tag"):
        augment_clip("c#twirl", seq, s, torch.Generator())
