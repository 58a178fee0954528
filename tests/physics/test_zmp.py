"""ZMP distance (PIP's 4th metric): standing inside the support polygon, static lean outside it,
and the cart-table case with a known analytic ZMP."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from wearpose.body import JOINT_INDEX, NUM_JOINTS, BodyModel
from wearpose.errors import ShapeError
from wearpose.geometry import axis_angle_to_matrix
from wearpose.physics import PhysicsCharacter, convex_hull_2d, distance_to_polygon, zmp_distance

FPS = 60.0
G = 9.81


@pytest.fixture(scope="module")
def char() -> PhysicsCharacter:
    return PhysicsCharacter.from_body(BodyModel(), torch.zeros(10))


def _still(T: int, pose: torch.Tensor | None = None) -> tuple[torch.Tensor, torch.Tensor]:
    pose = torch.eye(3).expand(NUM_JOINTS, 3, 3) if pose is None else pose
    return pose.expand(T, NUM_JOINTS, 3, 3).clone(), torch.zeros(T, 3)


def test_hull_and_distance():
    sq = np.array([[0, 0], [1, 0], [1, 1], [0, 1], [0.5, 0.5]], dtype=float)
    hull = convex_hull_2d(sq)
    assert len(hull) == 4  # interior point dropped
    assert distance_to_polygon(np.array([0.5, 0.2]), hull) == 0.0
    assert np.isclose(distance_to_polygon(np.array([2.0, 0.5]), hull), 1.0)
    assert np.isclose(distance_to_polygon(np.array([2.0, 2.0]), hull), np.sqrt(2))  # nearest = corner
    seg = convex_hull_2d(np.array([[0, 0], [2, 0], [1, 0]], dtype=float))  # collinear: a segment
    assert np.isclose(distance_to_polygon(np.array([1.0, 3.0]), seg), 3.0)


def test_hull_matches_qhull_on_random_sets():
    from scipy.spatial import ConvexHull

    rng = np.random.default_rng(0)
    for n in (3, 5, 8, 40):
        for _ in range(25):
            pts = rng.normal(size=(n, 2))
            ours = convex_hull_2d(pts)
            ref = pts[ConvexHull(pts).vertices]  # counter-clockwise for 2-D input
            assert len(ours) == len(ref)
            k = int(np.argmin(np.linalg.norm(ref - ours[0], axis=1)))  # same cycle, any start vertex
            assert np.allclose(np.roll(ref, -k, axis=0), ours)


def test_standing_still_is_balanced(char):
    pose, trans = _still(20)
    res = zmp_distance(char, pose, trans, FPS)
    assert res.frames_defined == 18  # both ends lack a central difference
    assert res.contacts.all()
    assert res.mean_m == 0.0
    # static: the contact force is the body weight, the ZMP the COM's ground projection
    assert np.allclose(res.force[1:-1], [0.0, char.mass_kg * G, 0.0], atol=1e-6)
    com = char.center_of_mass(char.q_from_pose(pose[0], trans[0]))
    assert np.allclose(res.zmp[1:-1], com[[0, 2]], atol=1e-9)


def test_static_lean_outside_support(char):
    # whole body pitched 35 deg forward about the root, held still: the COM projects in front of
    # the feet; the ZMP distance is the distance of that projection to the feet's squares
    pose = torch.eye(3).expand(NUM_JOINTS, 3, 3).clone()
    pose[0] = axis_angle_to_matrix(torch.tensor([np.radians(35.0), 0.0, 0.0]))
    pose, trans = _still(10, pose)
    res = zmp_distance(char, pose, trans, FPS, ground_y=float(char.rest_joints[:, 1].min()) - 0.3,
                       contact_height=1.0)
    q = char.q_from_pose(pose[0], trans[0])
    com = char.center_of_mass(q)
    assert np.allclose(res.zmp[1:-1], com[[0, 2]], atol=1e-9)
    # expected: the COM projection's distance to the two feet squares (20 cm, centred half-way
    # from the foot joint to the ankle), from the body model's posed joints
    body = BodyModel()
    jp = body(pose[:1].float(), torch.zeros(1, 10), trans[:1].float(), return_vertices=False).joints[0].double().numpy()
    corners = []
    for f, ank in (("left_foot", "left_ankle"), ("right_foot", "right_ankle")):
        c = 0.5 * (jp[JOINT_INDEX[f]] + jp[JOINT_INDEX[ank]])[[0, 2]]
        corners += [c + [sx, sz] for sx in (-0.1, 0.1) for sz in (-0.1, 0.1)]
    corners = np.array(corners)
    front = corners[:, 1].max()
    assert com[2] > front + 0.1  # the lean puts the COM well in front of the toes
    inside_x = corners[:, 0].min() <= com[0] <= corners[:, 0].max()
    assert inside_x
    assert np.allclose(res.distance[1:-1], com[2] - front, atol=1e-4)
    # pitched backwards: the feet swing forward, the COM is now behind the heels
    pose_b = pose.clone()
    pose_b[:, 0] = axis_angle_to_matrix(torch.tensor([np.radians(-35.0), 0.0, 0.0]))
    res_b = zmp_distance(char, pose_b, trans, FPS, ground_y=res.ground_y, contact_height=1.0)
    assert np.all(res_b.distance[1:-1] > 0.05)


def test_cart_table_analytic(char):
    # rigid T-pose translated with constant horizontal acceleration a along +X and the feet held
    # "in contact" (speed rule off): no rotation, so the ZMP sits a * h / g behind the COM
    # (cart-table model: p = c - h a / g), h = COM height above the ground
    T, a = 30, 3.0
    pose, _ = _still(T)
    t = torch.arange(T, dtype=torch.float64) / FPS
    trans = torch.zeros(T, 3, dtype=torch.float64)
    trans[:, 0] = 0.5 * a * t ** 2
    res = zmp_distance(char, pose, trans, FPS, contact_speed=np.inf)
    com0 = char.center_of_mass(char.q_from_pose(pose[0], torch.zeros(3)))
    h = com0[1] - res.ground_y
    cx = com0[0] + trans[1:-1, 0].numpy()
    assert np.allclose(res.force[1:-1, 0], char.mass_kg * a, rtol=1e-6)
    assert np.allclose(res.zmp[1:-1, 0], cx - h * a / G, atol=1e-6)
    assert np.allclose(res.zmp[1:-1, 1], com0[2], atol=1e-6)
    # with a = 3 m/s^2 the ZMP is ~0.3 m behind the COM (-X: towards the right foot), outside the
    # 20 cm squares under the feet: the distance is to the right square's outer edge
    rest = char.rest_joints
    edge = 0.5 * (rest[JOINT_INDEX["right_foot"], 0] + rest[JOINT_INDEX["right_ankle"], 0]) - 0.1
    assert np.allclose(res.distance[1:-1], edge + trans[1:-1, 0].numpy() - res.zmp[1:-1, 0], atol=1e-6)
    assert np.all(res.distance[1:-1] > 0.03)
    # a wider stencil gives the same exact answer on this quadratic trajectory
    wide = zmp_distance(char, pose, trans, FPS, contact_speed=np.inf, stride=2)
    assert wide.frames_defined == T - 4
    assert np.allclose(wide.zmp[2:-2, 0], res.zmp[2:-2, 0], atol=1e-6)
    # the 2 m/s foot speed of the same motion at the end means no contact there with the speed rule
    assert not zmp_distance(char, pose, trans, FPS).contacts[-1].any()


def test_flight_and_shapes(char):
    pose, trans = _still(8)
    # 1 m above the ground: no foot in contact, no ZMP distance
    res = zmp_distance(char, pose, trans, FPS, ground_y=float(char.rest_joints[:, 1].min()) - 1.0)
    assert res.frames_defined == 0 and np.isnan(res.mean_m)
    with pytest.raises(ShapeError):
        zmp_distance(char, pose[:, :10], trans, FPS)
    with pytest.raises(ShapeError):
        zmp_distance(char, pose, trans[:3], FPS)
