"""The embedded free body asset (``wearpose_anny_v1.npz``): conventions and invariants.

numpy only (no torch BodyModel): joints come from ``J_regressor @ vertices``.
Frame: metres, Y up, T-pose facing +Z, subject's left towards +X.
"""

from __future__ import annotations

import numpy as np
import pytest

from wearpose.body.asset import load_default_asset
from wearpose.body.skeleton import JOINT_INDEX, NUM_JOINTS, PARENTS

J = JOINT_INDEX


@pytest.fixture(scope="module")
def asset():
    return load_default_asset()


@pytest.fixture(scope="module")
def joints(asset):
    """(24, 3) joints at beta = 0, metres."""
    return asset.J_regressor.astype(np.float64) @ asset.v_template.astype(np.float64)


def _height(v: np.ndarray) -> float:
    return float(v[:, 1].max() - v[:, 1].min())


def _elevation_deg(d: np.ndarray) -> float:
    return float(np.degrees(np.arcsin(abs(d[1]) / np.linalg.norm(d))))


def test_identity_and_shapes(asset):
    assert asset.asset_id == "wearpose-anny-v1"
    V = asset.num_vertices
    assert asset.num_betas == 10
    assert asset.posedirs is None
    assert tuple(asset.parents) == PARENTS
    assert asset.J_regressor.shape == (NUM_JOINTS, V) and asset.weights.shape == (V, NUM_JOINTS)
    for key in ("source", "licence", "generator", "anny_version", "phenotype_sampling"):
        assert key in asset.meta, key
    assert "tools/build_body_asset.py" in asset.meta["generator"]


@pytest.mark.parametrize("side", ["left", "right"])
def test_tpose_arms_horizontal(joints, side):
    for a, b in (("shoulder", "elbow"), ("elbow", "wrist")):
        d = joints[J[f"{side}_{b}"]] - joints[J[f"{side}_{a}"]]
        assert _elevation_deg(d) < 5.0, (a, b, d)
        # pointing outwards along +X (left) / -X (right)
        assert np.sign(d[0]) == (1 if side == "left" else -1) and abs(d[0]) / np.linalg.norm(d) > 0.99


def test_palms_down_thumb_forward(asset, joints):
    """Palm down in a T-pose puts the thumb in front (+Z) of the hand's long axis."""
    w = asset.weights
    for side in ("left", "right"):
        hand = np.flatnonzero(w[:, J[f"{side}_hand"]] > 0.5)
        v = asset.v_template[hand]
        axis_z = joints[J[f"{side}_hand"], 2]
        # the thumb is the part of the hand mesh furthest forward; the little finger furthest back
        assert v[:, 2].max() - axis_z > axis_z - v[:, 2].min()


def test_facing_plus_z_left_plus_x(joints):
    assert joints[J["left_hip"], 0] > 0.05 and joints[J["right_hip"], 0] < -0.05
    assert joints[J["left_shoulder"], 0] > 0.1 and joints[J["right_shoulder"], 0] < -0.1
    for side in ("left", "right"):
        assert joints[J[f"{side}_foot"], 2] - joints[J[f"{side}_ankle"], 2] > 0.08  # toes forward
    assert joints[J["head"], 1] > joints[J["neck"], 1] > joints[J["spine3"], 1] > joints[J["pelvis"], 1]
    assert joints[J["pelvis"], 1] > joints[J["left_knee"], 1] > joints[J["left_ankle"], 1]


def test_pelvis_at_smpl_neutral_pelvis(joints):
    assert np.allclose(joints[J["pelvis"]], [0.0, -0.223, 0.028], atol=0.015)


def test_joint_heights_plausible(asset, joints):
    floor = asset.v_template[:, 1].min()
    knee = joints[J["left_knee"], 1] - floor
    assert 0.40 < knee < 0.58
    assert 0.03 < joints[J["left_ankle"], 1] - floor < 0.12
    # shoulder joints below the neck, at the top of the torso
    assert 0.03 < joints[J["neck"], 1] - joints[J["left_shoulder"], 1] < 0.12


def test_height_beta0_and_beta0_monotone(asset):
    v0 = asset.v_template.astype(np.float64)
    sd = asset.shapedirs.astype(np.float64)
    assert 1.60 <= _height(v0) <= 1.80
    hs = [_height(v0 + b * sd[:, :, 0]) for b in np.linspace(-2, 2, 9)]
    assert np.all(np.diff(hs) > 0), hs
    assert hs[-1] - hs[0] >= 0.10


def test_weights_rows_sum_to_one(asset):
    w = asset.weights.astype(np.float64)
    assert w.min() >= 0
    assert np.allclose(w.sum(1), 1.0, atol=1e-5)


def test_regressor_rows_sum_to_one_sparse_nonnegative(asset):
    r = asset.J_regressor.astype(np.float64)
    assert r.min() >= 0
    assert np.allclose(r.sum(1), 1.0, atol=1e-5)
    assert (np.count_nonzero(r, axis=1) < 200).all()


def test_regressor_follows_shape(asset):
    """Joints move with the body: beta[0] = +2 (taller) lowers the ankles, raises the head."""
    v0 = asset.v_template.astype(np.float64)
    r = asset.J_regressor.astype(np.float64)
    tall = r @ (v0 + 2 * asset.shapedirs[:, :, 0])
    base = r @ v0
    assert tall[J["left_ankle"], 1] < base[J["left_ankle"], 1]
    assert tall[J["head"], 1] > base[J["head"], 1]


def test_sites(asset):
    names = asset.site_names
    expected = {"head", "sternum", "back_upper", "pelvis", "left_upper_arm", "right_upper_arm", "left_forearm",
                "right_forearm", "left_wrist", "right_wrist", "left_thigh", "right_thigh", "left_shin",
                "right_shin", "left_foot", "right_foot", "left_shoulder", "right_shoulder"}
    assert set(names) == expected and len(names) == len(expected)
    # Sites added later are appended: the index of every earlier site never changes.
    assert names[:16] == ("head", "sternum", "back_upper", "pelvis", "left_upper_arm", "right_upper_arm",
                          "left_forearm", "right_forearm", "left_wrist", "right_wrist", "left_thigh", "right_thigh",
                          "left_shin", "right_shin", "left_foot", "right_foot")
    V = asset.num_vertices
    f = asset.faces
    assert len(asset.site_vertices) == len(names) == len(asset.site_tangent)
    for n, v, t in zip(names, asset.site_vertices, asset.site_tangent):
        assert 0 <= v < V and 0 <= t < V and v != t, n
        # the tangent vertex shares a triangle edge with the site vertex
        tri = f[(f == v).any(axis=1)]
        assert (tri == t).any(), n
    x = {n: asset.v_template[v] for n, v in zip(names, asset.site_vertices)}
    assert x["sternum"][2] > x["back_upper"][2]  # sternum in front
    assert x["left_thigh"][0] > 0 > x["right_thigh"][0]


def test_faces_wind_outwards(asset):
    v = asset.v_template.astype(np.float64)
    t = v[asset.faces]
    vol = np.einsum("fi,fi->f", t[:, 0], np.cross(t[:, 1], t[:, 2])).sum() / 6.0
    assert 0.03 < vol < 0.15  # m^3, positive: counter-clockwise seen from outside


def test_site_normals_point_outwards(asset):
    """Each site's area-weighted vertex normal faces the side the site is defined on."""
    v = asset.v_template.astype(np.float64)
    f = asset.faces
    expected = {"head": (0, 0, 1), "sternum": (0, 0, 1), "back_upper": (0, 0, -1), "pelvis": (0, 0, -1),
                "left_upper_arm": (0, 1, 0), "right_upper_arm": (0, 1, 0), "left_forearm": (0, 1, 0),
                "right_forearm": (0, 1, 0), "left_wrist": (0, 1, 0), "right_wrist": (0, 1, 0),
                "left_thigh": (1, 0, 0), "right_thigh": (-1, 0, 0), "left_shin": (0, 0, 1), "right_shin": (0, 0, 1),
                "left_foot": (0, 1, 0), "right_foot": (0, 1, 0), "left_shoulder": (0, 1, 0), "right_shoulder": (0, 1, 0)}
    for n, vid in zip(asset.site_names, asset.site_vertices):
        tri = v[f[(f == vid).any(axis=1)]]
        nrm = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]).sum(0)
        nrm /= np.linalg.norm(nrm)
        assert nrm @ np.array(expected[n]) > 0.5, (n, nrm)


@pytest.mark.parametrize("side", ["left", "right"])
def test_shoulder_sites_on_top_of_the_shoulder(asset, joints, side):
    """EM-POSE's shoulder sensors: on top of the shoulder over the acromion (above and just
    medial of the glenohumeral joint), on skin that moves with the shoulder girdle (collar) as
    well as the arm -- not a second upper-arm site."""
    x = {n: asset.v_template[v].astype(np.float64) for n, v in zip(asset.site_names, asset.site_vertices)}
    vid = dict(zip(asset.site_names, asset.site_vertices))[f"{side}_shoulder"]
    p = x[f"{side}_shoulder"]
    sh, cl = joints[J[f"{side}_shoulder"]], joints[J[f"{side}_collar"]]
    sx = 1.0 if side == "left" else -1.0
    assert 0.02 < p[1] - sh[1] < 0.08  # on top: skin above the joint centre
    assert 0.0 < sx * (sh[0] - p[0]) < 0.06  # medial of the shoulder joint ...
    assert sx * (p[0] - cl[0]) > 0.08  # ... but well lateral of the collar joint (not the neck)
    assert abs(p[2] - sh[2]) < 0.03  # neither on the chest nor on the scapula
    assert np.linalg.norm(p - x[f"{side}_upper_arm"]) > 0.10
    w = asset.weights[vid]
    assert w[J[f"{side}_collar"]] > 0.2 and w[J[f"{side}_collar"]] + w[J[f"{side}_shoulder"]] > 0.99
    # mirror images of each other
    other = x["right_shoulder" if side == "left" else "left_shoulder"]
    assert np.allclose(p * [-1, 1, 1], other, atol=0.005)
