"""Retarget a BVH clip onto SMPL's 24-joint tree.

Method: global orientation transfer with a per-joint rest-pose correction.

For every SMPL joint ``j`` mapped to a BVH joint ``b`` the SMPL global rotation is

    ``G_j(t) = G_b(t) @ C_j``,   ``C_j = T_b^T``,

where ``G_b(t)`` is the BVH joint's world rotation (BVH FK) and ``T_b`` is the rotation of BVH
joint frame ``b`` **in a T-pose that matches SMPL's zero pose** (so at that T-pose ``G_j = I``,
SMPL's zero pose). ``T_b`` is built from the skeleton's geometry, parents first, as
``T_b = F(p_s, s_s) @ F(p_b, s_b)^T`` with ``F(p, s)`` the orthonormal frame whose first axis is
``p`` and whose second lies in the ``(p, s)`` plane:

- primary direction ``p``: the bone from the joint to its next mapped joint down the chain
  (:func:`next_joint`: spine1 -> spine2 when spine2 is mapped, else spine1 -> spine3), in
  SMPL's rest skeleton (``p_s``) and in the BVH joint's own frame (``p_b``, from the clip's local
  translations). So every mapped bone of the retargeted skeleton points exactly where the BVH
  bone points, in every frame. A next joint at the same place as the joint (a zero-length
  source bone: CMU's ``lowerback`` starts at the root) is passed over for the joint after it;
  that SMPL bone then has no source bone (:attr:`TPose.bone_ends`).
- secondary direction ``s`` (twist about the bone), chosen per joint:

  * pelvis and spine3 (two+ children): the right-to-left vector between the hips / the collars,
    or, where the collars start at one point (CMU's ASF layout: both clavicles at the thorax
    end), between the shoulders (:data:`_LATERAL`).
  * thighs, shins, upper arms and forearms: the **hinge axis of the knee / elbow**. In SMPL's
    zero pose the knee flexes about ``+X`` and the elbow about ``-Y`` (left) / ``+Y`` (right),
    written generally as ``normalize(cross(parent_bone, flexion_direction))`` with flexion moving
    the shin backwards (``-Z``) and the forearm forwards (``+Z``). In the BVH the axis is the
    normal of the cone the child bone sweeps in the parent frame (:func:`estimate_hinge_axis`),
    signed so that flexion bends the limb; built-in
    skeletons carry constants estimated this way over the corpus, any other skeleton (or
    ``hinge="clip"``) estimates them from the clip itself. This anchors forearm/shin twist, which
    body-worn sensors measure, to anatomy instead of to each rig's joint orients.
  * every other mapped joint: **minimal twist relative to the parent's corrected frame** at the
    BVH's zero pose: ``T_b = rotation_between(K p_b, p_s) @ K`` with ``K = T_parent`` (the
    joint's own zero rotation relative to its parent). Leaves (no bone to a mapped child) take
    ``T_b = K``. This is meaningful for the two corpus skeletons: CMU-Daz's zero pose is a
    T-pose with world-aligned frames, and Bandai's zero pose is a straight chain along each
    bone's local X (neck > head, forearm > hand, shin > foot).
  * joints listed in the map's ``mean_twist`` (Bandai: spine1 and the collars, whose zero pose
    is twisted by about 90 deg): as above, then turned about the bone so that their local twist
    relative to the corrected parent averages zero over the clip (swing-twist decomposition,
    circular mean). These joints barely twist in practice (Bandai: 3 deg RMS).

Source joints between two mapped joints that the map leaves out (CMU's ``upperneck`` between
``lowerneck`` and ``head``) would bend the source bone away from the SMPL one; for every joint
but the pelvis and the chest, the SMPL joint is then swung per frame onto the source bone
(:class:`BoneFix`), keeping its twist.

Joints SMPL has but the BVH does not (per map): ``spine2`` takes half of the spine1 -> spine3
relative rotation (slerp at 0.5), the other half goes to spine3; hands (and CMU's SMPL ``foot``
joints) get the identity local rotation (they follow their parent).

Root translation: the SMPL pelvis joint is put on the BVH pelvis joint's world position, scaled
about the world origin, with one scale for height and one for travel (:func:`leg_measures`):

- height (``y``): ``scale = height_smpl / height_bvh``, *height* the vertical distance from the
  pelvis joint down to the ankle joints in the T-pose (SMPL rest skeleton / BVH skeleton posed
  by ``T``). This puts the feet on the floor ``y = 0`` where the source's are.
- travel (``x``, ``z``): ``travel_scale = limb_smpl / limb_bvh``, *limb* the hip-to-ankle
  distance in the T-pose. A stance foot is still when the root moves as far as the legs reach,
  and the legs are the limbs: the pelvis-to-ankle height also counts the pelvis-to-hip drop
  (9.6 cm on SMPL, a few cm on the sources), so scaling travel by it made the root travel
  10-14 % further than the legs on the corpus and the stance feet slide (``docs/pip.md``,
  "Ground truth that skates"; ``benchmarks/foot_skate.py``).

``trans(t) = diag(travel_scale, scale, travel_scale) @ units * pelvis_bvh(t) - rest_joints[0]`` is
the ``travel="limb"`` path. The default, ``travel="legs"`` (:func:`root_path`), keeps that height
but takes the horizontal travel from the legs: while a source foot is planted, the root moves so
that SMPL's foot moves as the source's does (a scale alone leaves 0.06 m/s of slide on Bandai
walks, from SMPL's wider hips and other thigh/shin proportions).

The two corpus BVH worlds are Y up, facing +Z with left at +X (the wearpose world), so only the
unit scale (cm -> m) is applied to positions.

Consequences worth knowing: matching bones exactly means that where the source skeleton's rest
shape differs from SMPL's, the difference shows up as joint rotations. The CMU-Daz converter's
T-pose (frame 0; its zero pose, world-aligned frames) has elbows bent about 17 deg forward and
collars about 14 deg low, so it retargets to an SMPL pose with 3-19 deg per joint rather than to
exactly zero; and the pelvis tilts forward by the angle between the source's pelvis->spine bone
and SMPL's (about 10-16 deg with the default body), compensated by spine1.
"""

from __future__ import annotations

import math
from collections.abc import Collection, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
import torch

from wearpose.body.kinematics import forward_kinematics, global_to_local
from wearpose.body.skeleton import JOINT_INDEX, JOINT_NAMES, NUM_JOINTS, PARENTS
from wearpose.errors import ShapeError, WearposeError
from wearpose.geometry import axis_angle_to_matrix, matrix_to_quat, project_to_so3, rotation_between, slerp_matrix
from wearpose.geometry.units import CM_TO_M
from wearpose.motion.bvh import BvhMotion, BvhSkeleton, bvh_forward_kinematics
from wearpose.motion.sequence import NUM_BETAS, MotionSequence


class RetargetError(WearposeError, ValueError):
    """A BVH skeleton cannot be mapped onto SMPL (unknown skeleton, missing joints)."""


#: SMPL joint -> the SMPL joint its primary bone points to (``None``: leaf, no primary bone).
#: spine1 points to spine3 because spine2 has no BVH counterpart in either corpus skeleton.
_NEXT: dict[str, str | None] = {
    "pelvis": "spine1", "spine1": "spine3", "spine2": "spine3", "spine3": "neck", "neck": "head", "head": None,
    "left_collar": "left_shoulder", "right_collar": "right_shoulder",
    "left_shoulder": "left_elbow", "right_shoulder": "right_elbow",
    "left_elbow": "left_wrist", "right_elbow": "right_wrist",
    "left_wrist": "left_hand", "right_wrist": "right_hand", "left_hand": None, "right_hand": None,
    "left_hip": "left_knee", "right_hip": "right_knee", "left_knee": "left_ankle", "right_knee": "right_ankle",
    "left_ankle": "left_foot", "right_ankle": "right_foot", "left_foot": None, "right_foot": None,
}
#: Joints whose twist comes from the vector between two other joints (left minus right): the
#: first pair that is mapped and not (nearly) parallel to the bone in the source's zero pose.
#: The shoulders back up the collars because CMU's ASF layout starts both clavicles at the
#: thorax end, where their difference is zero.
_LATERAL: dict[str, tuple[tuple[str, str], ...]] = {
    "pelvis": (("left_hip", "right_hip"),),
    "spine3": (("left_collar", "right_collar"), ("left_shoulder", "right_shoulder")),
}
#: A lateral reference is usable when its part perpendicular to the bone is at least this
#: fraction of its length (sin 11.5 deg): a nearly parallel one would give an ill-defined twist.
_MIN_LATERAL_SIN = 0.2
#: Hinge joints: (parent segment joint, flexion direction of the child bone in SMPL's world).
_HINGES: dict[str, tuple[str, tuple[float, float, float]]] = {
    "left_knee": ("left_hip", (0.0, 0.0, -1.0)), "right_knee": ("right_hip", (0.0, 0.0, -1.0)),
    "left_elbow": ("left_shoulder", (0.0, 0.0, 1.0)), "right_elbow": ("right_shoulder", (0.0, 0.0, 1.0)),
}
#: Segment joint (thigh, upper arm) -> the hinge at its distal end.
_SEGMENT_HINGE: dict[str, str] = {seg: h for h, (seg, _f) in _HINGES.items()}
#: Bone pairs checked by :func:`bone_direction_errors` (SMPL joint names; the BVH bones are the
#: mapped joints').
BONE_PAIRS: tuple[tuple[str, str], ...] = (
    ("pelvis", "spine1"), ("spine3", "neck"), ("neck", "head"),
    ("left_hip", "left_knee"), ("right_hip", "right_knee"), ("left_knee", "left_ankle"), ("right_knee", "right_ankle"),
    ("left_shoulder", "left_elbow"), ("right_shoulder", "right_elbow"),
    ("left_elbow", "left_wrist"), ("right_elbow", "right_wrist"),
)


@dataclass(frozen=True)
class SkeletonMap:
    """How one BVH skeleton maps onto SMPL-24.

    Attributes:
        name: identifier stored in ``meta["skeleton"]``.
        joints: SMPL joint name -> BVH joint name.
        units_to_m: metres per file unit.
        hinge_axes: optional constants per SMPL hinge joint (``left_knee``...):
            ``(axis in the BVH parent joint's frame, axis in the BVH hinge joint's frame)``,
            the knee/elbow flexion axis (signed: positive rotation flexes).
        foot_joints: BVH joints whose lowest height is reported as the clip's floor.
        mean_twist: SMPL joints (with a primary bone) whose twist about that bone is not taken
            from the BVH zero pose but chosen so that their local twist relative to the
            corrected parent averages zero over the clip (for rigs whose zero pose is twisted).
        description: one line on where the map and constants come from.
    """

    name: str
    joints: Mapping[str, str]
    units_to_m: float = CM_TO_M
    hinge_axes: Mapping[str, tuple[tuple[float, float, float], tuple[float, float, float]]] = field(default_factory=dict)
    foot_joints: tuple[str, ...] = ()
    mean_twist: tuple[str, ...] = ()
    description: str = ""


#: CMU mocap, cgspeed "Daz-friendly" BVH (root ``hip``). SMPL spine2, feet and hands unmapped.
CMU_DAZ = SkeletonMap(
    name="cmu_daz",
    joints={
        "pelvis": "hip", "spine1": "abdomen", "spine3": "chest", "neck": "neck", "head": "head",
        "left_collar": "lCollar", "right_collar": "rCollar", "left_shoulder": "lShldr", "right_shoulder": "rShldr",
        "left_elbow": "lForeArm", "right_elbow": "rForeArm", "left_wrist": "lHand", "right_wrist": "rHand",
        "left_hip": "lThigh", "right_hip": "rThigh", "left_knee": "lShin", "right_knee": "rShin",
        "left_ankle": "lFoot", "right_ankle": "rFoot",
    },
    # Flexion axes from estimate_hinge_axes over 40 random CMU clips (per-clip spread: median
    # 0.1-0.3 deg); the same axis is used in the parent and the hinge frame because CMU-Daz's
    # zero pose is a straight, untwisted limb. The elbow axis is 30 deg off vertical in the
    # rig's T-pose: the upper-arm twist is corrected by that much (SMPL's elbow hinge is +-Y).
    # tests/motion/test_corpus.py re-estimates them.
    hinge_axes={
        "left_knee": ((1.0, -0.017, 0.001),) * 2, "right_knee": ((1.0, 0.017, -0.001),) * 2,
        "left_elbow": ((-0.118, -0.859, 0.498),) * 2, "right_elbow": ((-0.119, 0.860, -0.496),) * 2,
    },
    foot_joints=("lFoot", "rFoot"),
    description="CMU mocap via cgspeed Daz-friendly BVH (43 joints, root hip), centimetres",
)

#: Bandai Namco Research Motion Datasets 1/2 (root ``joint_Root`` > ``Hips``). SMPL spine2 and
#: hands unmapped.
BANDAI = SkeletonMap(
    name="bandai",
    joints={
        "pelvis": "Hips", "spine1": "Spine", "spine3": "Chest", "neck": "Neck", "head": "Head",
        "left_collar": "Shoulder_L", "right_collar": "Shoulder_R", "left_shoulder": "UpperArm_L", "right_shoulder": "UpperArm_R",
        "left_elbow": "LowerArm_L", "right_elbow": "LowerArm_R", "left_wrist": "Hand_L", "right_wrist": "Hand_R",
        "left_hip": "UpperLeg_L", "right_hip": "UpperLeg_R", "left_knee": "LowerLeg_L", "right_knee": "LowerLeg_R",
        "left_ankle": "Foot_L", "right_ankle": "Foot_R", "left_foot": "Toes_L", "right_foot": "Toes_R",
    },
    # Flexion axes from estimate_hinge_axes over 40 random Bandai clips: knees flex about local
    # +Y (spread < 0.2 deg), elbows about local -Y in the upper-arm frame (spread 5 deg). The elbow's
    # own frame also carries forearm pronation (rotation about the bone, local X), so the axis
    # seen in the forearm frame varies per clip; the constant uses the zero-twist forearm frame
    # (Bandai's zero elbow rotation is a straight, untwisted arm), i.e. the same axis.
    hinge_axes={
        "left_knee": ((0.0, 1.0, 0.0),) * 2, "right_knee": ((0.0, 1.0, 0.0),) * 2,
        "left_elbow": ((0.0, -1.0, 0.0),) * 2, "right_elbow": ((0.0, -1.0, 0.0),) * 2,
    },
    foot_joints=("Toes_L", "Toes_R", "Foot_L", "Foot_R"),
    # Bandai's zero pose is not untwisted at the spine and the collars: Spine's frame is turned
    # about 90 deg about the bone relative to Hips (its X channel sits near 90), and so are the
    # Shoulder_L/R frames relative to Chest. Their twist is therefore set from the clip.
    mean_twist=("spine1", "left_collar", "right_collar"),
    description="Bandai Namco Research Motion Dataset 1/2 BVH (22 joints, root joint_Root > Hips), centimetres",
)

BUILTIN_MAPS: dict[str, SkeletonMap] = {m.name: m for m in (CMU_DAZ, BANDAI)}


def next_joint(name: str, mapped: Collection[str]) -> str | None:
    """The SMPL joint that ``name``'s primary bone points to, given the mapped SMPL joints:
    :data:`_NEXT`, except that spine1 points to spine2 when spine2 is mapped (so a source with
    three spine segments, e.g. CMU's ``lowerback > upperback > thorax``, keeps all three)."""
    if name == "spine1" and "spine2" in mapped:
        return "spine2"
    return _NEXT[name]


def bone_pairs(mapped: Collection[str]) -> tuple[tuple[str, str], ...]:
    """Every mapped bone: ``(joint, next joint)`` for each mapped SMPL joint whose
    :func:`next_joint` is mapped too, in SMPL order (the import check compares these)."""
    out = []
    for name in JOINT_NAMES:
        nxt = next_joint(name, mapped) if name in mapped else None
        if nxt is not None and nxt in mapped:
            out.append((name, nxt))
    return tuple(out)


def detect_skeleton_map(skeleton: BvhSkeleton, maps: Sequence[SkeletonMap] | None = None) -> SkeletonMap:
    """The built-in map whose BVH joint names all occur in ``skeleton`` (best coverage wins).

    Raises:
        RetargetError: no map covers the skeleton's joints.
    """
    maps = list(BUILTIN_MAPS.values()) if maps is None else list(maps)
    names = set(skeleton.names)
    best, best_cov = None, 0.0
    for m in maps:
        cov = sum(b in names for b in m.joints.values()) / max(len(m.joints), 1)
        if cov > best_cov:
            best, best_cov = m, cov
    if best is None or best_cov < 1.0:
        known = ", ".join(f"{m.name} (root {m.joints['pelvis']!r})" for m in maps)
        raise RetargetError(
            f"no built-in SMPL joint map fits this BVH skeleton (root {skeleton.names[0]!r}, {skeleton.num_joints} joints); "
            f"known skeletons: {known}; "
            "pass a SkeletonMap for other skeletons")
    return best


# ---------------------------------------------------------------------------- small helpers
def _unit(v: torch.Tensor) -> torch.Tensor:
    return v / v.norm(dim=-1, keepdim=True).clamp_min(1e-12)


def _frame(p: torch.Tensor, s: torch.Tensor, what: str = "the twist reference") -> torch.Tensor:
    """Orthonormal frame (columns) with axis 1 along ``p`` and axis 2 in the ``(p, s)`` plane.

    ``what`` names the joint and its reference in the error (e.g. ``"left_knee: its hinge axis"``).
    """
    e1 = _unit(p)
    s_perp = s - (s @ e1) * e1
    if s_perp.norm() < 1e-6 * max(float(s.norm()), 1e-12) or s_perp.norm() < 1e-12:
        raise RetargetError(f"{what} is parallel to the bone (or zero), so the twist about the bone is undefined")
    e2 = _unit(s_perp)
    return torch.stack([e1, e2, torch.linalg.cross(e1, e2)], dim=-1)


def _path_to_ancestor(skel: BvhSkeleton, desc: int, anc: int) -> list[int] | None:
    """Joints from ``desc`` up to (excluding) ``anc``, or None if ``anc`` is not an ancestor."""
    path = []
    j = desc
    while j != anc:
        if j < 0:
            return None
        path.append(j)
        j = skel.parents[j]
    return path


def _rest_offsets(motion: BvhMotion) -> torch.Tensor:
    """``(J, 3)`` local translations used as bone vectors: the per-joint median over the clip
    (position channels replace OFFSETs; their median is robust to a stale header OFFSET)."""
    return motion.translations.median(dim=0).values


def _position_in(skel: BvhSkeleton, offsets: torch.Tensor, desc: int, anc: int) -> torch.Tensor | None:
    """Position of joint ``desc`` in joint ``anc``'s frame at the BVH zero pose (file units)."""
    path = _path_to_ancestor(skel, desc, anc)
    if path is None:
        return None
    return offsets[path].sum(0)


def _mean_twist(R: torch.Tensor, axis: torch.Tensor) -> float:
    """Circular mean (radians) of the twist of rotations ``R`` ``(T, 3, 3)`` about unit ``axis``
    (swing-twist decomposition ``R = swing @ twist``, twist applied first, about ``axis``)."""
    q = matrix_to_quat(R)  # (w, x, y, z), w >= 0
    psi = 2.0 * torch.atan2(q[:, 1:] @ axis, q[:, 0])
    return float(torch.atan2(torch.sin(psi).mean(), torch.cos(psi).mean()))


# ---------------------------------------------------------------------------- hinge axes
def estimate_hinge_axis(local_rot: torch.Tensor, parent_bone: torch.Tensor, child_bone: torch.Tensor
                        ) -> tuple[torch.Tensor, torch.Tensor, float]:
    """Flexion axis of a hinge-like joint (knee, elbow) from its motion.

    The child bone's direction seen from the parent frame, ``c_t = L_t u``, sweeps a cone about
    the hinge axis, so the axis (in the parent frame) is the direction of least variance of
    ``c_t`` -- exact for a pure hinge whatever the cone angle, and blind to twist about the child
    bone (forearm pronation does not move the bone). In the hinge joint's own frame the axis is
    ``Lm^T a_parent`` with ``Lm`` the chordal mean of ``L_t`` (exact for a pure hinge; with
    pronation it is the axis at the clip's mean pronation).

    Args:
        local_rot: ``(T, 3, 3)`` the hinge joint's local rotation (child frame -> parent frame).
        parent_bone: ``(3,)`` the parent segment's bone direction, in the parent's frame.
        child_bone: ``(3,)`` the child segment's bone direction, in the child's frame.

    Returns:
        ``(axis_in_parent, axis_in_child, rms)``: unit axes, signed so that a positive rotation
        about them increases the angle between the two bones (flexion), and the RMS spread of
        the child bone direction, radians (about the RMS flexion; small means poorly determined).
    """
    L = local_rot.to(torch.float64)
    u = _unit(child_bone.to(torch.float64))
    c = L @ u  # (T, 3) child bone direction in the parent frame
    c0 = c - c.mean(0)
    evals, evecs = torch.linalg.eigh(c0.T @ c0 / max(len(c), 1))
    a_parent = evecs[:, 0]
    # Sign: flexion rotates the child bone away from the parent bone about +axis.
    pb = _unit(parent_bone.to(torch.float64))
    flex = torch.linalg.cross(pb.expand(len(c), 3), c, dim=-1).sum(0)
    if float(flex @ a_parent) < 0:
        a_parent = -a_parent
    Lm = project_to_so3(L.mean(0))
    a_child = _unit(Lm.T @ a_parent)
    return a_parent, a_child, float(evals[-1].clamp_min(0).sqrt())


def estimate_hinge_axes(motion: BvhMotion, smap: SkeletonMap) -> dict[str, tuple[torch.Tensor, torch.Tensor, float]]:
    """:func:`estimate_hinge_axis` for the knees and elbows of ``motion`` under ``smap``.

    Returns:
        SMPL hinge joint name -> ``(axis in BVH parent frame, axis in BVH hinge frame, rms)``.
    """
    skel = motion.skeleton
    offs = _rest_offsets(motion)
    out = {}
    for hinge, (seg, _flex) in _HINGES.items():
        b_h, b_p = skel.index(smap.joints[hinge]), skel.index(smap.joints[seg])
        if skel.parents[b_h] != b_p:
            continue  # only direct parent-child hinges are estimated
        nxt = _NEXT[hinge]
        b_c = skel.index(smap.joints[nxt]) if nxt in smap.joints else None
        if b_c is None:
            continue
        child_bone = _position_in(skel, offs, b_c, b_h)
        parent_bone = offs[b_h]
        out[hinge] = estimate_hinge_axis(motion.rotations[:, b_h], parent_bone, child_bone)
    return out


# ---------------------------------------------------------------------------- the T-pose
@dataclass(frozen=True)
class BoneFix:
    """A mapped bone whose source bone spans joints the map leaves out (e.g. CMU's ``upperneck``
    between ``lowerneck`` and ``head``): their rotations would be lost, so the SMPL joint's
    global rotation is turned per frame by the minimal rotation (a swing, its twist kept) that
    points its bone where the source bone points. Not for the pelvis and the chest (spine3):
    their other children (hips, collars) would move with the swing.

    Attributes:
        source: source joint index of the SMPL joint; target: source joint index the bone ends at;
        bone: ``(3,)`` unit direction of the SMPL bone in SMPL's rest pose (world = joint frame).
    """

    source: int
    target: int
    bone: torch.Tensor


@dataclass
class TPose:
    """The BVH skeleton's T-pose matching SMPL's zero pose.

    Attributes:
        rotations: SMPL joint index -> ``(3, 3)`` BVH joint frame -> world at the T-pose
            (``T_b``; the correction is ``C_j = T_b^T``).
        scale: SMPL/BVH pelvis-to-ankle height ratio (dimensionless, applied after the unit
            change): the root's vertical scale.
        hinge_source: SMPL hinge joint -> ``"map"``, ``"clip"`` or ``"parent"`` (fallback).
        twist_offsets: SMPL joint -> twist (radians) applied by the ``mean_twist`` rule.
        twist_refs: SMPL joint -> what fixed its twist about the bone: ``"left_hip-right_hip"``
            (a lateral pair), ``"hinge"``, ``"parent"`` (minimal twist) or ``"none"`` (no bone).
        bone_fix: SMPL joint index -> :class:`BoneFix` (per-frame swing onto the source bone).
        bone_ends: SMPL joint -> the SMPL joint its primary bone ends at, when that is not the
            next joint (the next joint sits at the same place in the source: a zero-length bone).
        travel_scale: SMPL/BVH hip-to-ankle limb length ratio: the root's horizontal scale
            (``None``: the same as ``scale``, the converter before motion-4).
    """

    rotations: dict[int, torch.Tensor]
    scale: float
    hinge_source: dict[str, str]
    twist_offsets: dict[str, float] = field(default_factory=dict)
    twist_refs: dict[str, str] = field(default_factory=dict)
    bone_fix: dict[int, BoneFix] = field(default_factory=dict)
    bone_ends: dict[str, str] = field(default_factory=dict)
    travel_scale: float | None = None

    @property
    def root_scale(self) -> torch.Tensor:
        """``(3,)`` float64 per-axis scale of the root path: ``(travel, height, travel)``."""
        t = self.scale if self.travel_scale is None else self.travel_scale
        return torch.tensor([t, self.scale, t], dtype=torch.float64)


@dataclass(frozen=True)
class LegMeasures:
    """Leg lengths of a skeleton in its T-pose, metres, mean of both sides.

    Attributes:
        height: vertical distance from the pelvis joint down to the ankle joints (sets where the
            feet are: the root's vertical scale).
        limb: hip-to-ankle distance (how far the legs reach: the root's travel scale).
    """

    height: float
    limb: float


def leg_measures(rest_joints: torch.Tensor) -> LegMeasures:
    """:class:`LegMeasures` of an SMPL rest skeleton ``(24, 3)`` metres (``BodyModel.rest_joints``)."""
    r = rest_joints.to(torch.float64)
    if tuple(r.shape) != (NUM_JOINTS, 3):
        raise ShapeError(f"rest_joints: expected ({NUM_JOINTS}, 3) metres, got {tuple(r.shape)}")
    ankles = [JOINT_INDEX["left_ankle"], JOINT_INDEX["right_ankle"]]
    hips = [JOINT_INDEX["left_hip"], JOINT_INDEX["right_hip"]]
    height = float(r[0, 1] - r[ankles, 1].mean())
    limb = float((r[ankles] - r[hips]).norm(dim=-1).mean())
    return LegMeasures(height, limb)


def _map_advice(smap: SkeletonMap, joint: str) -> str:
    """The way out of an unusable joint, as joint-map lines (docs/motion-import.md)."""
    src = smap.joints.get(joint, "?")
    return (f"write a --joint-map YAML that maps SMPL {joint} to another joint of your skeleton "
            f"('{joint}: OtherJoint') or leaves it unmapped ('{joint}: null'; now {src!r})")


def solve_tpose(motion: BvhMotion, smap: SkeletonMap, rest_joints: torch.Tensor,
                hinge: Literal["auto", "map", "clip"] = "auto", min_hinge_rms: float = math.radians(10.0)) -> TPose:
    """Compute the per-joint T-pose frames ``T_b`` (see module doc) and the leg scale.

    Args:
        motion: the BVH clip (its local translations give the bone vectors; its knee/elbow
            motion gives hinge axes when they are estimated from the clip).
        smap: joint map.
        rest_joints: ``(24, 3)`` SMPL rest joints, metres.
        hinge: ``"map"`` use ``smap.hinge_axes``; ``"clip"`` estimate from this clip; ``"auto"``
            map constants when present, else the clip (if its RMS flexion reaches
            ``min_hinge_rms``), else minimal twist from the parent.

    Raises:
        RetargetError: a mapped joint is not below its mapped SMPL parent's joint, a hinge axis
            lies along its bone, or the legs do not point down (each names the joint and the
            joint-map lines that get round it).
    """
    skel = motion.skeleton
    rest = rest_joints.to(torch.float64)
    offs = _rest_offsets(motion)
    bidx = {s: skel.index(b) for s, b in smap.joints.items()}
    # Bones shorter than this (file units) are zero-length connectors: CMU's lowerback and hip
    # links start exactly at the root.
    eps = 1e-3 * float(offs.norm(dim=-1).max().clamp_min(1e-12))
    clip_axes: dict[str, tuple[torch.Tensor, torch.Tensor, float]] | None = None
    hinge_src: dict[str, str] = {}
    twist_offsets: dict[str, float] = {}
    twist_refs: dict[str, str] = {}
    bone_fix: dict[int, BoneFix] = {}
    bone_ends: dict[str, str] = {}
    world_rot: torch.Tensor | None = None

    def hinge_axes_for(h: str) -> tuple[torch.Tensor, torch.Tensor] | None:
        nonlocal clip_axes
        if hinge in ("auto", "map") and h in smap.hinge_axes:
            hinge_src[h] = "map"
            ap, ac = smap.hinge_axes[h]
            return _unit(torch.tensor(ap, dtype=torch.float64)), _unit(torch.tensor(ac, dtype=torch.float64))
        if hinge == "map":
            raise RetargetError(f"skeleton map {smap.name!r} has no hinge axis for {h}")
        if clip_axes is None:
            clip_axes = estimate_hinge_axes(motion, smap)
        if h in clip_axes and (hinge == "clip" or clip_axes[h][2] >= min_hinge_rms):
            hinge_src[h] = "clip"
            return clip_axes[h][0], clip_axes[h][1]
        hinge_src[h] = "parent"
        return None

    def mapped_ancestor(j: int) -> int | None:
        p = PARENTS[j]
        while p >= 0 and JOINT_NAMES[p] not in bidx:
            p = PARENTS[p]
        return p if p >= 0 else None

    def primary(name: str) -> tuple[torch.Tensor | None, torch.Tensor | None]:
        """SMPL rest bone and source zero-pose bone (in the source joint's frame) of ``name``."""
        nxt = next_joint(name, bidx)
        b = bidx[name]
        while nxt is not None and nxt in bidx:
            p_b = _position_in(skel, offs, bidx[nxt], b)
            if p_b is None:
                return None, None
            if float(p_b.norm()) > eps:
                if nxt != next_joint(name, bidx):
                    bone_ends[name] = nxt
                return rest[JOINT_INDEX[nxt]] - rest[JOINT_INDEX[name]], p_b
            # The next joint sits at this one's place (CMU's lowerback starts at the root): the
            # joint after it gives the direction (the zero-length SMPL bone has no source bone).
            nxt = next_joint(nxt, bidx)
        if nxt is None:
            return None, None
        # No mapped counterpart (e.g. CMU's toe End Site for SMPL's foot, fingers for the hand):
        # use the mean of the joint's child and End Site offsets, if any.
        vecs = [offs[c] for c in skel.children(b)]
        if b in skel.end_sites:
            vecs += list(torch.from_numpy(skel.end_sites[b]))
        p_b = torch.stack(vecs).mean(0) if vecs else None
        if p_b is None or float(p_b.norm()) <= eps:
            return None, None
        return rest[JOINT_INDEX[nxt]] - rest[JOINT_INDEX[name]], p_b

    def lateral(name: str, p_b: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, str] | None:
        """The first usable lateral pair of ``name`` (see :data:`_LATERAL`): (SMPL, source, label)."""
        b = bidx[name]
        for l, r in _LATERAL.get(name, ()):
            if l not in bidx or r not in bidx:
                continue
            pl, pr = _position_in(skel, offs, bidx[l], b), _position_in(skel, offs, bidx[r], b)
            if pl is None or pr is None:
                continue
            s_b = pl - pr
            perp = s_b - (s_b @ _unit(p_b)) * _unit(p_b)
            if float(s_b.norm()) > eps and float(perp.norm()) >= _MIN_LATERAL_SIN * float(s_b.norm()):
                return rest[JOINT_INDEX[l]] - rest[JOINT_INDEX[r]], s_b, f"{l}-{r}"
        return None

    T: dict[int, torch.Tensor] = {}
    for j, name in enumerate(JOINT_NAMES):
        if name not in bidx:
            continue
        b = bidx[name]
        p_s, p_b = primary(name)
        anc = mapped_ancestor(j)
        K = T[anc] if anc is not None else torch.eye(3, dtype=torch.float64)
        if anc is not None:
            # Relative rotation of intermediate BVH joints at the zero pose is the identity.
            if _path_to_ancestor(skel, b, bidx[JOINT_NAMES[anc]]) is None:
                raise RetargetError(f"{smap.name}: joint {smap.joints[name]} (SMPL {name}) is not below "
                                    f"{smap.joints[JOINT_NAMES[anc]]} (SMPL {JOINT_NAMES[anc]}); {_map_advice(smap, name)}")
        s_pair: tuple[torch.Tensor, torch.Tensor] | None = None
        what = ""
        if p_b is not None and (lat := lateral(name, p_b)) is not None:
            s_pair, twist_refs[name] = (lat[0], lat[1]), lat[2]
            what = f"{smap.name}: SMPL {name} ({smap.joints[name]}): its twist reference {lat[2]}"
        hname = name if name in _HINGES else _SEGMENT_HINGE.get(name)
        if s_pair is None and p_b is not None and hname is not None and hname in bidx and _HINGES[hname][0] in bidx:
            axes = hinge_axes_for(hname)
            if axes is not None:
                seg, flex = _HINGES[hname]
                parent_bone_s = rest[JOINT_INDEX[hname]] - rest[JOINT_INDEX[seg]]
                s_s = torch.linalg.cross(_unit(parent_bone_s), torch.tensor(flex, dtype=torch.float64), dim=-1)
                s_pair = (s_s, axes[0] if name == seg else axes[1])
                twist_refs[name] = "hinge"
                what = f"{smap.name}: SMPL {name} ({smap.joints[name]}): the {hname} hinge axis"
        if s_pair is not None:
            try:
                T[j] = _frame(p_s, s_pair[0], what) @ _frame(p_b, s_pair[1], what).T
            except RetargetError as exc:
                raise RetargetError(f"{exc}; {_map_advice(smap, name)}") from None
        elif p_b is not None:
            T[j] = rotation_between(K @ p_b, p_s) @ K
            twist_refs[name] = "parent"
        else:
            T[j] = K.clone()
            twist_refs[name] = "none"
        nxt = next_joint(name, bidx)
        # Not the pelvis or chest: swinging them onto one bone would move their other children
        # (hips, collars) off the source's; their loss shows in the bone check instead.
        if p_b is not None and name not in bone_ends and name not in _LATERAL and nxt in bidx:
            path = _path_to_ancestor(skel, bidx[nxt], b)
            if path is not None and len(path) > 1:
                bone_fix[j] = BoneFix(b, bidx[nxt], _unit(p_s))
        if name in smap.mean_twist and p_s is not None and anc is not None:
            if world_rot is None:
                world_rot = bvh_forward_kinematics(motion)[0]
            b_anc = bidx[JOINT_NAMES[anc]]
            # SMPL local rotation with the current correction: G_parent^T G_b T^T (parent corrected).
            M = (world_rot[:, b_anc] @ T[anc].T).transpose(-1, -2) @ world_rot[:, b] @ T[j].T
            phi = _mean_twist(M, _unit(p_s))
            twist_offsets[name] = phi
            T[j] = axis_angle_to_matrix(_unit(p_s) * phi) @ T[j]

    # Root scales: SMPL rest / BVH T-pose, pelvis-to-ankle height (vertical) and hip-to-ankle
    # limb length (travel); see the module doc.
    def bvh_leg(side: str) -> tuple[float, float]:
        chain = ["pelvis", f"{side}_hip", f"{side}_knee", f"{side}_ankle"]
        seg = []
        for a, c in zip(chain[:-1], chain[1:]):
            v = _position_in(skel, offs, bidx[c], bidx[a])
            if v is None:
                raise RetargetError(f"{smap.name}: cannot measure the {side} leg")
            seg.append(T[JOINT_INDEX[a]] @ v)
        drop = -float(sum(float(v[1]) for v in seg))
        limb = float((seg[1] + seg[2]).norm())
        return drop * smap.units_to_m, limb * smap.units_to_m

    smpl = leg_measures(rest)
    (dl, ll), (dr, lr) = bvh_leg("left"), bvh_leg("right")
    bvh_height, bvh_limb = 0.5 * (dl + dr), 0.5 * (ll + lr)
    if bvh_height <= 1e-6 or bvh_limb <= 1e-6:
        raise RetargetError(f"{smap.name}: legs do not point down in the T-pose (pelvis-to-ankle height {bvh_height:.3f} m)")
    return TPose(T, smpl.height / bvh_height, hinge_src, twist_offsets, twist_refs, bone_fix, bone_ends,
                 travel_scale=smpl.limb / bvh_limb)


# ---------------------------------------------------------------------------- retargeting
@dataclass
class Retargeted:
    """Result of :func:`retarget_bvh`.

    Attributes:
        sequence: the SMPL motion (float32).
        tpose: the T-pose used (corrections ``C_j = tpose.rotations[j].T``).
        smap: the joint map used.
        bvh_world_pos: ``(T, J, 3)`` BVH joint world positions, metres (unscaled; for checks).
        lowest_foot_y: lowest SMPL foot joint height (ankles and feet) over the clip, metres.
        lowest_bvh_foot_y: lowest BVH ``smap.foot_joints`` height over the clip, metres, scaled
            like the SMPL root (so comparable with ``lowest_foot_y``).
    """

    sequence: MotionSequence
    tpose: TPose
    smap: SkeletonMap
    bvh_world_pos: torch.Tensor
    lowest_foot_y: float
    lowest_bvh_foot_y: float
    bvh_names: tuple[str, ...] = ()


#: How the root's horizontal path is made (:func:`root_path`): ``"legs"`` (default) anchors it to
#: the source's planted feet, ``"limb"`` scales the source's by the limb ratio, ``"height"`` by
#: the pelvis-to-ankle ratio (the converter before motion-4; skating feet).
TravelMode = Literal["legs", "limb", "height"]
TRAVEL_MODES: tuple[str, ...] = ("legs", "limb", "height")
#: Source foot contact for ``travel="legs"``: full weight up to the first value, none from the
#: second (linear between). Height above the clip's lowest foot point (m, after the height
#: scale) and horizontal speed (m/s, after the travel scale). Swing feet move at 2-5 m/s and sit
#: 5-13 cm up in mid-swing; planted feet move < 0.1 m/s (Bandai) to 0.4 m/s (CMU-Daz's ankles).
CONTACT_HEIGHT_M: tuple[float, float] = (0.03, 0.08)
CONTACT_SPEED_MS: tuple[float, float] = (0.6, 1.2)


def _ramp(x: torch.Tensor, full: float, none: float) -> torch.Tensor:
    """1 at ``x <= full``, 0 at ``x >= none``, linear between."""
    return ((none - x) / (none - full)).clamp(0.0, 1.0)


def foot_joint_pairs(smap: SkeletonMap, names: Sequence[str]) -> list[tuple[int, int]]:
    """(SMPL joint index, source joint index) of the points that stand on the floor: each side's
    mapped SMPL foot (toe) joint, else its ankle."""
    out = []
    for side in ("left", "right"):
        for j in (f"{side}_foot", f"{side}_ankle"):
            if j in smap.joints and smap.joints[j] in names:
                out.append((JOINT_INDEX[j], list(names).index(smap.joints[j])))
                break
    return out


def root_path(pose: torch.Tensor, source_pos: torch.Tensor, source_names: Sequence[str], smap: SkeletonMap,
              tpose: TPose, rest_joints: torch.Tensor, fps: float, travel: TravelMode = "legs") -> torch.Tensor:
    """The SMPL root translation ``(T, 3)`` metres (float64) of a retargeted clip.

    Height (``y``) always: ``scale * pelvis_src_y - rest_y`` (feet on the floor where the
    source's are). Horizontal (``x``, ``z``), by ``travel``:

    - ``"height"``: the source pelvis path scaled by the pelvis-to-ankle ratio ``tpose.scale``
      (the converter before motion-4: the root outruns the legs by 10-14 % on the corpus).
    - ``"limb"``: scaled by the hip-to-ankle limb ratio ``tpose.travel_scale``.
    - ``"legs"``: the travel comes from the body's own legs: per frame step, the root moves so
      that each planted source foot's SMPL counterpart moves as the source foot does (scaled by
      the limb ratio, so a still source foot gives a still SMPL foot), weighted by how surely
      the foot is planted (:data:`CONTACT_HEIGHT_M`, :data:`CONTACT_SPEED_MS`; both feet
      averaged in double support); with no foot planted (flight, a hang) it moves as the
      ``"limb"`` path does. Why not a scale alone: SMPL's hips sit wider apart than the
      sources' (+-11 cm on the default body) and its thigh/shin proportions differ, so the
      pelvis's yaw and the legs' swing move a planted SMPL foot even with the right scale
      (Bandai walks: 0.06 m/s with ``"limb"``; ``benchmarks/foot_skate.py``). The path
      starts where the ``"limb"`` path starts; the rule is exact for a body with the source's
      proportions (it then equals ``"limb"``).

    Args:
        pose: ``(T, 24, 3, 3)`` SMPL local rotations of the clip.
        source_pos: ``(T, J, 3)`` source joint world positions, metres (unscaled).
        source_names: the ``J`` source joint names; smap: the joint map; tpose: its T-pose.
        rest_joints: ``(24, 3)`` SMPL rest joints, metres; fps: Hz; travel: see above.
    """
    if travel not in TRAVEL_MODES:
        raise WearposeError(f"travel {travel!r}; expected one of {', '.join(TRAVEL_MODES)}")
    rest = rest_joints.to(torch.float64)
    P = source_pos.to(torch.float64)
    pelvis = P[:, list(source_names).index(smap.joints["pelvis"])]
    k = tpose.root_scale if travel != "height" else torch.full((3,), tpose.scale, dtype=torch.float64)
    k[1] = tpose.scale
    trans = k * pelvis - rest[0]
    pairs = foot_joint_pairs(smap, source_names)
    if travel != "legs" or len(pairs) == 0 or pelvis.shape[0] < 2:
        return trans
    _, J = forward_kinematics(pose.to(torch.float64), rest)  # (T, 24, 3), root at the origin
    smpl_feet = J[:, [a for a, _ in pairs]]  # (T, F, 3) relative to the root translation
    src_feet = P[:, [b for _, b in pairs]]
    h = (src_feet[..., 1] - src_feet[..., 1].min()) * tpose.scale  # above the clip's lowest foot point
    v = torch.gradient(src_feet[..., [0, 2]] * k[0], spacing=1.0 / float(fps), dim=0)[0].norm(dim=-1)
    w = _ramp(h, *CONTACT_HEIGHT_M) * _ramp(v, *CONTACT_SPEED_MS)  # (T, F)
    w_step = 0.5 * (w[1:] + w[:-1])  # weight of each frame step
    # Root step that moves SMPL foot f as the (scaled) source foot f moves.
    step_f = torch.diff(k[0] * src_feet[..., [0, 2]] - smpl_feet[..., [0, 2]], dim=0)  # (T-1, F, 2)
    step_0 = torch.diff(trans[:, [0, 2]], dim=0)  # (T-1, 2)
    total = w_step.sum(-1, keepdim=True)
    anchored = (w_step[..., None] * step_f).sum(1) / total.clamp_min(1e-12)
    alpha = total.clamp(max=1.0)
    step = alpha * anchored + (1.0 - alpha) * step_0
    trans[1:, [0, 2]] = trans[0, [0, 2]] + torch.cumsum(step, dim=0)
    return trans


def retarget_bvh(motion: BvhMotion, rest_joints: torch.Tensor, smap: SkeletonMap | None = None,
                 betas: torch.Tensor | None = None, hinge: Literal["auto", "map", "clip"] = "auto",
                 meta: Mapping[str, Any] | None = None, travel: TravelMode = "legs") -> Retargeted:
    """Retarget a BVH clip to SMPL-24 (method in the module doc).

    Args:
        motion: parsed BVH (:func:`wearpose.motion.read_bvh`), ``T`` frames.
        rest_joints: ``(24, 3)`` SMPL rest joints for ``betas``, metres (``BodyModel.rest_joints``).
        smap: joint map; detected from the joint names when ``None``.
        betas: ``(10,)`` shape stored in the sequence (zeros by default).
        hinge: where knee/elbow hinge axes come from (see :func:`solve_tpose`).
        meta: extra entries for ``sequence.meta``.
        travel: how the root's horizontal path is made (:func:`root_path`; default ``"legs"``).

    Returns:
        :class:`Retargeted` whose ``sequence`` has ``pose`` ``(T, 24, 3, 3)``, ``trans`` ``(T, 3)``
        metres (Y-up world) and ``fps = 1 / frame_time``.
    """
    if tuple(rest_joints.shape) != (NUM_JOINTS, 3):
        raise ShapeError(f"rest_joints: expected ({NUM_JOINTS}, 3) metres, got {tuple(rest_joints.shape)}")
    smap = smap or detect_skeleton_map(motion.skeleton)
    skel = motion.skeleton
    rest = rest_joints.to(torch.float64)
    tpose = solve_tpose(motion, smap, rest, hinge=hinge)
    G_b, P_b = bvh_forward_kinematics(motion)
    Tn = motion.num_frames
    eye = torch.eye(3, dtype=torch.float64).expand(Tn, 3, 3)
    G: list[torch.Tensor | None] = [None] * NUM_JOINTS
    for j, name in enumerate(JOINT_NAMES):
        if name in smap.joints:
            G[j] = G_b[:, skel.index(smap.joints[name])] @ tpose.rotations[j].T
    for j, fix in tpose.bone_fix.items():
        # Swing the joint so its bone points where the source bone points (joints the map
        # leaves out in between would otherwise bend it away).
        want = P_b[:, fix.target] - P_b[:, fix.source]
        G[j] = rotation_between(G[j] @ fix.bone, want) @ G[j]  # type: ignore[operator]
    for j, name in enumerate(JOINT_NAMES):
        if G[j] is not None:
            continue
        parent = G[PARENTS[j]] if PARENTS[j] >= 0 else eye
        if name == "spine2" and G[3] is not None and G[9] is not None:
            # Half of the spine1 -> spine3 relative rotation (slerp at 0.5).
            rel = G[3].transpose(-1, -2) @ G[9]
            G[j] = G[3] @ slerp_matrix(eye, rel, torch.full((Tn,), 0.5, dtype=torch.float64))
        else:
            G[j] = parent.clone()  # identity local rotation (hands, unmapped feet)
    G_all = torch.stack(G, dim=1)  # type: ignore[arg-type]
    pose = global_to_local(G_all)
    trans = root_path(pose, P_b * smap.units_to_m, skel.names, smap, tpose, rest, motion.fps, travel)
    b = torch.zeros(NUM_BETAS, dtype=torch.float64) if betas is None else betas.to(torch.float64)
    lowest = lowest_foot_height(pose, trans, rest)
    bvh_feet = [skel.index(n) for n in smap.foot_joints if n in skel.names]
    lowest_bvh = float((P_b[:, bvh_feet, 1] * smap.units_to_m * tpose.scale).min()) if bvh_feet else float("nan")
    m: dict[str, Any] = {
        "source_format": "bvh", "skeleton": smap.name, "source_fps": motion.fps,
        "retarget": {"method": "global-orientation transfer with rest-pose correction", "leg_scale": tpose.scale,
                     "travel_scale": float(tpose.root_scale[0]), "travel": travel,
                     "hinge_axes": tpose.hinge_source, "twist_refs": tpose.twist_refs,
                     "bone_swing_fixed": sorted(JOINT_NAMES[j] for j in tpose.bone_fix),
                     "twist_offsets_deg": {k: math.degrees(v) for k, v in tpose.twist_offsets.items()},
                     "lowest_foot_y": lowest, "lowest_bvh_foot_y": lowest_bvh},
    }
    if motion.path is not None:
        m["source_file"] = str(motion.path)
    m.update(dict(meta or {}))
    seq = MotionSequence(pose.to(torch.float32), b.to(torch.float32), trans.to(torch.float32), motion.fps, m)
    return Retargeted(seq, tpose, smap, P_b * smap.units_to_m, lowest, lowest_bvh, skel.names)


def lowest_foot_height(pose: torch.Tensor, trans: torch.Tensor, rest_joints: torch.Tensor) -> float:
    """Lowest height (metres, world Y) of SMPL's ankle and foot joints over a clip.

    Args:
        pose: ``(T, 24, 3, 3)`` local rotations; trans: ``(T, 3)``; rest_joints: ``(24, 3)``.
    """
    _, joints = forward_kinematics(pose.to(torch.float64), rest_joints.to(torch.float64))
    feet = [JOINT_INDEX[n] for n in ("left_ankle", "right_ankle", "left_foot", "right_foot")]
    return float((joints[:, feet, 1] + trans.to(torch.float64)[:, None, 1]).min())


def bone_direction_errors(result: Retargeted, rest_joints: torch.Tensor,
                          pairs: Sequence[tuple[str, str]] = BONE_PAIRS) -> dict[str, np.ndarray]:
    """Per-frame angle (radians) between each retargeted SMPL bone and its BVH bone.

    SMPL bones come from ``forward_kinematics(pose, rest_joints)``; BVH bones from the clip's own
    FK. Pairs whose joints are not both mapped are skipped, and so are pairs whose source joints
    sit at the same place (a zero-length source bone has no direction: CMU's root and
    ``lowerback``).

    Returns:
        ``"a->b"`` -> ``(T,)`` angles in radians.
    """
    seq = result.sequence
    _, J = forward_kinematics(seq.pose.to(torch.float64), rest_joints.to(torch.float64))
    mapped = result.smap.joints
    out = {}
    P = result.bvh_world_pos
    names = list(result.bvh_names)
    for a, b in pairs:
        if a not in mapped or b not in mapped:
            continue
        vb = P[:, names.index(result.smap.joints[b])] - P[:, names.index(result.smap.joints[a])]
        if float(vb.norm(dim=-1).median()) < 1e-6:
            continue
        ds = _unit(J[:, JOINT_INDEX[b]] - J[:, JOINT_INDEX[a]])
        db = _unit(vb)
        cos = (ds * db).sum(-1).clamp(-1.0, 1.0)
        out[f"{a}->{b}"] = torch.arccos(cos).numpy()
    return out



# ---------------------------------------------------------------------------- other bodies
#: SMPL onto itself: the map :func:`refit_to_body` hands to :func:`root_path`.
SMPL_SELF = SkeletonMap(name="smpl", joints={n: n for n in JOINT_NAMES}, units_to_m=1.0,
                        description="SMPL-24 onto SMPL-24 (re-fitting a motion to another body shape)")


def refit_to_body(motion: MotionSequence, body: Any, betas: torch.Tensor, travel: TravelMode = "legs") -> MotionSequence:
    """The same motion on another body shape, its root re-fitted to that body's legs.

    Joint rotations are kept. The root path is rebuilt as retargeting builds it (:func:`root_path`),
    with the motion on its own body (``motion.betas``) as the source: height scaled by the two
    bodies' standing pelvis height above the soles (the rest pose's pelvis joint over its lowest
    skin point: the sole sits below the ankle by a different amount on every body, so this, not
    the pelvis-to-ankle height, keeps the soles on the floor), travel by default anchored to the
    planted feet (a planted foot stays planted on the new body; ``"limb"``: the travel scaled by
    the hip-to-ankle ratio, :func:`leg_measures`).

    Args:
        motion: the clip (``pose`` ``(T, 24, 3, 3)``, ``trans`` ``(T, 3)`` m, its ``betas``).
        body: the :class:`wearpose.body.BodyModel` both shapes belong to.
        betas: ``(S,)`` the new shape, stored in the result.
        travel: ``"legs"`` (default) or ``"limb"`` (:data:`TRAVEL_MODES`).

    Returns:
        a new :class:`MotionSequence` (float32), ``meta["refit"]`` holding the two scales.
    """
    if tuple(betas.shape) != tuple(motion.betas.shape):
        raise ShapeError(f"refit_to_body: betas expected {tuple(motion.betas.shape)} like the motion's, got {tuple(betas.shape)}")
    eye = torch.eye(3).expand(1, NUM_JOINTS, 3, 3)

    def standing(b: torch.Tensor) -> tuple[torch.Tensor, float]:
        rest = body.rest_joints(b.to(body.dtype)).to(torch.float64)
        sole = float(body.lowest_height(eye, b.to(body.dtype))[0])
        return rest, float(rest[0, 1]) - sole

    (rest_from, h_from), (rest_to, h_to) = standing(motion.betas), standing(betas)
    a, b = leg_measures(rest_from), leg_measures(rest_to)
    tpose = TPose({}, h_to / h_from, {}, travel_scale=b.limb / a.limb)
    pose = motion.pose.to(torch.float64)
    _, J = forward_kinematics(pose, rest_from)
    world = J + motion.trans.to(torch.float64)[:, None]
    trans = root_path(pose, world, JOINT_NAMES, SMPL_SELF, tpose, rest_to, motion.fps, travel)
    meta = dict(motion.meta)
    meta["refit"] = {"height_scale": tpose.scale, "travel_scale": tpose.travel_scale, "travel": travel,
                     "from_betas": [float(x) for x in motion.betas], "betas": [float(x) for x in betas]}
    return MotionSequence(motion.pose.clone(), betas.to(torch.float32).clone(), trans.to(torch.float32), motion.fps, meta)
