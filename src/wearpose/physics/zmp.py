"""Zero-moment-point (ZMP) distance of a motion: PIP's 4th metric (Sec. 4, "Metrics", and the
supplement's "Zero Moment Point vs. Center of Pressure").

For every frame the *fictitious* ZMP is the point of the ground plane about which the ground
contact wrench that the motion needs has no horizontal moment. That wrench follows from the
motion alone (Newton-Euler on the whole body): ``F = dP/dt - m g`` and, about the centre of mass
``c``, ``N_c = dL_c/dt`` with ``(dP/dt, dL_c/dt)`` the rate of the centroidal momentum,
computed with Pinocchio (:func:`pinocchio.computeCentroidalMomentumTimeVariation`) from the
configuration, velocity and acceleration of the character (finite differences of the motion on
the Lie group). With ``d = c - p`` and the ground at height ``y0`` (Y up), the horizontal
moment about ``p`` vanishes for::

    p_x = c_x - ((c_y - y0) F_x - N_z) / F_y,    p_z = c_z - ((c_y - y0) F_z + N_x) / F_y.

The ZMP distance is its distance to the base of support, the convex hull of the ground-contact
points of the feet in contact (0 inside). A body in dynamic equilibrium on its feet has its ZMP
inside the support polygon; the distance measures the unbalanced moment that would tip the body
over a foot edge (PIP: "should be zero for a real human in dynamic equilibrium").

Contact geometry (as the physics module's, so that the metric sees the character's own feet): a
foot joint (SMPL ``left_foot`` / ``right_foot``) is in contact when it is within
``contact_height`` of the ground and slower than ``contact_speed``; its contact points are the
corners of a world-aligned ``square_size`` square centred ``foot_square_shift`` of the way from
the foot joint to its ankle (:class:`~wearpose.physics.PhysicsConfig`'s defaults). Frames without
a foot in contact (flight) or whose required vertical contact force is below ``min_support`` of
the body weight (falling) have no ZMP distance (NaN) and are left out of the mean.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin
import torch

from wearpose.body import NUM_JOINTS
from wearpose.errors import ShapeError
from wearpose.physics.character import PhysicsCharacter
from wearpose.physics.optimizer import PhysicsConfig, contact_offsets, contact_square

#: Foot joints (left, right) whose contact squares form the base of support.
ZMP_FEET = PhysicsConfig.foot_joints


@dataclass
class ZmpResult:
    """Per-frame ZMP of a motion (see module doc).

    Attributes:
        distance: ``(T,)`` m, distance of the ZMP to the base of support (0 inside), NaN where
            undefined (first/last ``stride`` frames, no foot in contact, vertical force below ``min_support``).
        zmp: ``(T, 2)`` fictitious ZMP ``(x, z)`` on the ground plane, world, m (NaN where undefined).
        contacts: ``(T, 2)`` bool, left/right foot in contact.
        force: ``(T, 3)`` N, total ground contact force the motion needs, world.
        ground_y: ground height, m.
        mean_m: mean of ``distance`` over the frames where it is defined (NaN if none).
        frames_defined: number of such frames.
    """

    distance: np.ndarray
    zmp: np.ndarray
    contacts: np.ndarray
    force: np.ndarray
    ground_y: float
    mean_m: float
    frames_defined: int


def convex_hull_2d(points: np.ndarray) -> np.ndarray:
    """Convex hull ``(K, 2)`` (counter-clockwise, Andrew's monotone chain) of ``points`` ``(N, 2)``;
    degenerate inputs give 1 or 2 vertices."""
    # Not scipy.spatial.ConvexHull: Qhull raises on the degenerate supports that occur every few
    # frames here (one contact point; the points of a foot on its edge, collinear seen from
    # above), and the base of support is then a point or a segment, not an error. Tested
    # against Qhull on non-degenerate sets (tests/physics/test_zmp.py).
    pts = np.unique(np.asarray(points, dtype=np.float64).reshape(-1, 2), axis=0)
    if len(pts) <= 2:
        return pts

    def cross(o: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
        return float((a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0]))

    lower: list[np.ndarray] = []
    for p in pts:
        while len(lower) >= 2 and cross(lower[-2], lower[-1], p) <= 0:
            lower.pop()
        lower.append(p)
    upper: list[np.ndarray] = []
    for p in pts[::-1]:
        while len(upper) >= 2 and cross(upper[-2], upper[-1], p) <= 0:
            upper.pop()
        upper.append(p)
    return np.array(lower[:-1] + upper[:-1])


def distance_to_polygon(point: np.ndarray, hull: np.ndarray) -> float:
    """Distance (same unit) from ``point`` ``(2,)`` to the convex polygon ``hull`` ``(K, 2)``
    (counter-clockwise, :func:`convex_hull_2d`); 0 inside or on the boundary."""
    p = np.asarray(point, dtype=np.float64)
    K = len(hull)
    if K == 0:
        return float("nan")
    if K >= 3:
        e = np.roll(hull, -1, axis=0) - hull
        w = p - hull
        if np.all(e[:, 0] * w[:, 1] - e[:, 1] * w[:, 0] >= -1e-12):
            return 0.0
    if K == 1:
        return float(np.linalg.norm(p - hull[0]))
    a = hull
    b = np.roll(hull, -1, axis=0) if K > 2 else hull[::-1]
    ab = b - a
    t = np.clip(((p - a) * ab).sum(1) / np.maximum((ab * ab).sum(1), 1e-18), 0.0, 1.0)
    return float(np.min(np.linalg.norm(a + t[:, None] * ab - p, axis=1)))


def zmp_distance(character: PhysicsCharacter, pose_local: torch.Tensor, trans: torch.Tensor, fps: float, *,
                 ground_y: float | None = None, contact_height: float = 0.05, contact_speed: float = 0.48,
                 square_size: float = PhysicsConfig.square_size,
                 foot_square_shift: float = PhysicsConfig.foot_square_shift, min_support: float = 0.1,
                 stride: int = 1) -> ZmpResult:
    """ZMP distance to the base of support of a motion (module doc).

    Args:
        character: the subject's :class:`PhysicsCharacter` (masses, inertias).
        pose_local: ``(T, 24, 3, 3)`` local joint rotations.
        trans: ``(T, 3)`` root translation, m, world (Y up).
        fps: frame rate, Hz (velocities and accelerations by central differences).
        ground_y: ground height, m; None = the lowest foot joint of the motion.
        contact_height: a foot joint within this height of the ground (m) ...
        contact_speed: ... and slower than this (m/s) is in contact.
        square_size, foot_square_shift: each contact foot's square (see
            :class:`~wearpose.physics.PhysicsConfig`).
        min_support: frames whose required vertical contact force is below this fraction of the
            body weight (falling, flight) have no ZMP.
        stride: velocities and accelerations by central differences over ``stride`` frames on each
            side (the first and last ``stride`` frames have none). 2 at 60 fps removes the
            artefacts of a motion upsampled from 30 fps (piecewise-constant velocities make the
            1-frame second difference alternate between 0 and twice the true value).

    Returns:
        :class:`ZmpResult`; ``mean_m`` is PIP's "ZMP distance" of the motion.
    """
    model = character.model
    data = model.createData()
    q = character.q_from_motion(pose_local, trans)
    T, dt = len(q), 1.0 / float(fps)
    if int(stride) < 1:
        raise ShapeError(f"stride: expected a positive number of frames, got {stride}")
    s = int(stride)
    pin_ids = [int(i) for i in character.pin_id]
    joints = np.empty((T, NUM_JOINTS, 3))
    for t in range(T):
        pin.forwardKinematics(model, data, q[t])
        joints[t] = [data.oMi[i].translation for i in pin_ids]
    feet = list(ZMP_FEET)
    y0 = float(joints[:, feet, 1].min()) if ground_y is None else float(ground_y)
    speed = np.zeros((T, 2))
    if T > 1:
        speed = np.linalg.norm(np.gradient(joints[:, feet], dt, axis=0), axis=-1)
    contacts = (joints[:, feet, 1] - y0 < contact_height) & (speed < contact_speed)
    square = contact_square(square_size)

    dist = np.full(T, np.nan)
    zmp = np.full((T, 2), np.nan)
    force = np.full((T, 3), np.nan)
    mg = float(character.mass_kg) * float(np.linalg.norm(model.gravity.linear))
    g = np.asarray(model.gravity.linear, dtype=np.float64)
    for t in range(s, T - s):
        d_prev = pin.difference(model, q[t - s], q[t]) / (s * dt)
        d_next = pin.difference(model, q[t], q[t + s]) / (s * dt)
        v, a = 0.5 * (d_prev + d_next), (d_next - d_prev) / (s * dt)
        pin.computeCentroidalMomentumTimeVariation(model, data, q[t], v, a)
        dh = data.dhg
        F = dh.linear - character.mass_kg * g  # ground contact force the motion needs (world)
        N = dh.angular  # its moment about the centre of mass
        c = data.com[0]
        force[t] = F
        if F[1] < min_support * mg or not contacts[t].any():
            continue
        h = c[1] - y0
        p = np.array([c[0] - (h * F[0] - N[2]) / F[1], c[2] - (h * F[2] + N[0]) / F[1]])
        zmp[t] = p
        cj = [f for k, f in enumerate(feet) if contacts[t, k]]
        pts = joints[t, cj][:, None] + contact_offsets(joints[t], cj, square, feet, foot_square_shift)  # (nj, 4, 3)
        dist[t] = distance_to_polygon(p, convex_hull_2d(pts[..., [0, 2]]))
    ok = np.isfinite(dist)
    return ZmpResult(distance=dist, zmp=zmp, contacts=contacts, force=force, ground_y=y0,
                     mean_m=float(dist[ok].mean()) if ok.any() else float("nan"), frames_defined=int(ok.sum()))
