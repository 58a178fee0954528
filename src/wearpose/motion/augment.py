"""Motion augmentation for training data, one place for every method: the left/right mirror
image of a clip, a clip played faster or slower, turned to another heading, the upper body of
one clip on the lower body of another, and sensors strapped on a little off their sites;
:class:`AugmentSettings` records which (a weight's recipe holds its :meth:`~AugmentSettings.to_dict`).

Both return new, valid :class:`~wearpose.motion.MotionSequence` objects that the sensor
simulator turns into consistent virtual sensor data (the sensors are simulated *after*
augmenting, so accelerations, orientations and every target follow the augmented motion).
"""

from __future__ import annotations

import copy
import math
from dataclasses import asdict, dataclass, fields
from typing import Any

import numpy as np
import torch

from wearpose.body.kinematics import forward_kinematics
from wearpose.body.skeleton import JOINT_INDEX, MIRROR, PARENTS
from wearpose.errors import ConfigError, ShapeError
from wearpose.geometry import (
    axis_angle_to_matrix, geodesic_angle, mirror_points, mirror_rotation, project_to_so3, rotation_y,
)
from wearpose.motion.sequence import MotionSequence


def mirror(seq: MotionSequence, root_rest: torch.Tensor | None = None) -> MotionSequence:
    """The left/right mirror image of ``seq`` through the world plane x = 0.

    Joint ``j`` of the result turns like joint ``MIRROR[j]`` of the input, reflected
    (``M R M``, :func:`wearpose.geometry.mirror_rotation`); on a left/right symmetric body every
    joint position is then the reflection of its mirror joint's. ``root_rest`` ``(3,)`` (the
    body's zero-pose pelvis joint, m; ``trans`` is SMPL's, so the pelvis is at ``root_rest +
    trans``) makes the *pelvis* path the exact reflection; without it the pelvis path is off by
    the constant ``2 * root_rest.x`` in x (millimetres for SMPL-like bodies; no sensor sees a
    constant offset). ``betas`` are kept: the same person, mirrored.

    Args:
        seq: ``T`` frames; root_rest: optional ``(3,)``.

    Returns:
        A new sequence, ``meta["augment"]`` extended by ``"mirror"``.
    """
    pose = mirror_rotation(seq.pose[:, list(MIRROR)])
    trans = mirror_points(seq.trans)
    if root_rest is not None:
        r = torch.as_tensor(root_rest).to(trans)
        trans = trans + mirror_points(r) - r
    return MotionSequence(pose, seq.betas.clone(), trans, seq.fps, _tagged(seq.meta, "mirror"))


def play_speed(seq: MotionSequence, factor: float) -> MotionSequence:
    """``seq`` played ``factor`` times faster (``factor`` < 1: slower): the same frames at
    ``fps * factor``; resample afterwards for a fixed output rate. Velocities scale by
    ``factor``, accelerations by ``factor**2`` (gravity does not: a faster jump is not a
    ballistic one, keep factors near 1).

    Returns:
        A new sequence, ``meta["augment"]`` extended by ``"speed=<factor>"``.
    """
    factor = float(factor)
    if not math.isfinite(factor) or factor <= 0:
        raise ShapeError(f"play_speed: factor must be a positive number, got {factor!r}")
    return MotionSequence(seq.pose.clone(), seq.betas.clone(), seq.trans.clone(), seq.fps * factor,
                          _tagged(seq.meta, f"speed={factor:.4g}"))


def _tagged(meta: dict[str, Any], tag: str) -> dict[str, Any]:
    out = copy.deepcopy(meta)
    out["augment"] = [*out.get("augment", []), tag]
    return out


# ---------------------------------------------------------------------------------------- more kinds
def rotate_heading(seq: MotionSequence, angle: float, root_rest: torch.Tensor | None = None) -> MotionSequence:
    """``seq`` turned by ``angle`` rad about the world +Y axis through the origin (the whole clip:
    root orientation and path). ``root_rest`` ``(3,)`` as in :func:`mirror` (SMPL's ``trans`` is the
    pelvis minus its zero-pose position, so the exact turn of the path needs it; without it the
    pelvis path is off by a constant horizontal offset of at most ``2 |root_rest_xz|``).

    Returns:
        A new sequence, ``meta["augment"]`` extended by ``"heading=<deg>"``.
    """
    Ry = rotation_y(torch.tensor(float(angle), dtype=seq.pose.dtype))
    pose = seq.pose.clone()
    pose[:, 0] = Ry @ pose[:, 0]
    r = torch.zeros(3, dtype=seq.trans.dtype) if root_rest is None else torch.as_tensor(root_rest).to(seq.trans)
    trans = (seq.trans + r) @ Ry.T.to(seq.trans) - r
    return MotionSequence(pose, seq.betas.clone(), trans, seq.fps, _tagged(seq.meta, f"heading={math.degrees(angle):.4g}"))


#: SMPL joints of the lower body (root orientation, legs): what :func:`mix_parts` takes from ``lower``.
LOWER_BODY: tuple[int, ...] = (0, 1, 2, 4, 5, 7, 8, 10, 11)


def mix_parts(upper: MotionSequence, lower: MotionSequence) -> MotionSequence:
    """The upper body (spine, neck, head, arms) of ``upper`` on the lower body (root orientation,
    legs, root path, betas) of ``lower``, over the shorter clip's frames. Both at one ``fps``.

    Raises:
        ShapeError: different frame rates.
    """
    if abs(upper.fps - lower.fps) > 1e-9:
        raise ShapeError(f"mix_parts: clips at {upper.fps} and {lower.fps} fps; resample one first")
    T = min(upper.num_frames, lower.num_frames)
    pose = upper.pose[:T].clone()
    pose[:, list(LOWER_BODY)] = lower.pose[:T, list(LOWER_BODY)].to(pose)
    meta = _tagged(lower.meta, f"upper={upper.meta.get('clip', '?')}")
    return MotionSequence(pose, lower.betas.clone(), lower.trans[:T].clone(), lower.fps, meta)


def jitter_sites(body: Any, radius: float, generator: torch.Generator, names: Any = None) -> Any:
    """A copy of ``body`` whose sensor sites (all, or ``names``) each moved to a random vertex of
    the same body part (dominant skinning joint) within ``radius`` metres of it at rest: a sensor
    strapped on a little off its nominal place. The copy shares every array with ``body``; the
    tangent vertex of a moved site is the moved one's nearest neighbour on the mesh.

    Args:
        body: a :class:`~wearpose.body.BodyModel`; radius: metres (0 = unchanged); generator: seeds
            the draw.
    """
    out = copy.copy(body)
    if radius <= 0:
        return out
    names = tuple(body.site_names if names is None else names)
    _, vids, _ = body.site_ids(names)
    v = body.v_template.detach().double()
    part = body.weights.argmax(1)
    new_v = np.asarray(body._site_vertices).copy()
    new_t = np.asarray(body._site_tangent).copy()
    faces = body.faces.cpu().numpy()
    for name, vid in zip(names, vids):
        d = (v - v[int(vid)]).norm(dim=-1)
        cand = torch.nonzero((d <= radius) & (part == part[int(vid)])).flatten()
        pick = int(cand[int(torch.randint(len(cand), (), generator=generator))])
        nb = np.unique(faces[(faces == pick).any(axis=1)])
        nb = nb[nb != pick]
        k = body._site_index[name]
        new_v[k] = pick
        new_t[k] = int(nb[np.argmin(((v[nb] - v[pick]) ** 2).sum(-1).numpy())]) if len(nb) else pick
    out._site_vertices, out._site_tangent = new_v, new_t
    return out


def offset_rest(seq: MotionSequence, offsets: torch.Tensor) -> MotionSequence:
    """``seq`` as another capture chain would store it: every joint's frame turned by a constant
    rotation, ``G'_j = G_j C_j`` (global orientation of joint ``j``), so the local rotations become
    ``R'_j = C_parent(j)^T R_j C_j`` (root: ``R'_0 = R_0 C_0``). Two conversions of the same
    captures differ so: CMU 02_01-04 through the Daz BVH and through CMU's ASF/AMC are up to 30
    deg apart per major joint (collars), nearly constant over a take (docs/augmentation.md). The
    root path is kept; positions of the joints below a turned joint move with it.

    Args:
        seq: ``T`` frames of the 24 SMPL joints; offsets: ``(24, 3, 3)`` rotations ``C_j``.

    Returns:
        A new sequence, ``meta["augment"]`` extended by ``"rest_offset"``.

    Raises:
        ShapeError: ``offsets`` not ``(J, 3, 3)`` for the sequence's ``J`` joints.
    """
    J = seq.pose.shape[1]
    if tuple(offsets.shape) != (J, 3, 3) or J != len(PARENTS):
        raise ShapeError(f"offset_rest: offsets of shape {tuple(offsets.shape)}; expected ({len(PARENTS)}, 3, 3) "
                         f"for a sequence of {J} joints")
    C = offsets.to(seq.pose)
    parent_C = torch.stack([torch.eye(3, dtype=C.dtype) if p < 0 else C[p] for p in PARENTS])
    pose = parent_C.transpose(-1, -2) @ seq.pose @ C
    return MotionSequence(pose, seq.betas.clone(), seq.trans.clone(), seq.fps, _tagged(seq.meta, "rest_offset"))


def random_rest_offsets(max_deg: float, generator: torch.Generator, num_joints: int = len(PARENTS),
                        joints: tuple[int, ...] = ()) -> torch.Tensor:
    """``(num_joints, 3, 3)`` float64 rotations for :func:`offset_rest`: each about a uniformly
    random axis by an angle uniform in ``[0, max_deg]`` degrees (three normal and one uniform draw
    per joint from ``generator``, every joint drawn so a subset keeps the others' draws); with
    ``joints`` (indices) the other joints get the identity."""
    axis = torch.randn(num_joints, 3, generator=generator, dtype=torch.float64)
    axis = axis / axis.norm(dim=-1, keepdim=True).clamp_min(1e-12)
    angle = torch.rand(num_joints, generator=generator, dtype=torch.float64) * math.radians(float(max_deg))
    if joints:
        keep = torch.zeros(num_joints, dtype=torch.bool)
        keep[list(joints)] = True
        angle = torch.where(keep, angle, torch.zeros_like(angle))
    return axis_angle_to_matrix(axis * angle[:, None])


@dataclass(frozen=True)
class JointOffsets:
    """What :func:`joint_frame_offsets` measures between two versions of one motion.

    Attributes:
        mean: ``(J, 3, 3)`` the constant offset ``C_j`` (chordal mean of ``G_a^T G_b`` over frames,
            projected onto SO(3)); ``offset_rest(a, mean)`` is the closest constant-offset model of b.
        angle_deg: ``(J,)`` its rotation angle, degrees.
        spread_deg: ``(J,)`` mean angle between each frame's offset and ``mean``, degrees: how far
            from constant the difference is.
        local_deg: ``(J,)`` mean angle between the two versions' local rotations, degrees (what a
            model's joint-angle targets see).
    """

    mean: torch.Tensor
    angle_deg: torch.Tensor
    spread_deg: torch.Tensor
    local_deg: torch.Tensor


def joint_frame_offsets(a: torch.Tensor, b: torch.Tensor) -> JointOffsets:
    """How ``b`` differs from ``a`` as per-joint frame offsets, the model of :func:`offset_rest`.

    Args:
        a, b: ``(T, J, 3, 3)`` local rotations of the same motion, frame by frame (same rate,
            aligned), on the SMPL tree (:data:`~wearpose.body.skeleton.PARENTS`).

    Raises:
        ShapeError: the shapes differ or are not ``(T, 24, 3, 3)``.
    """
    if a.shape != b.shape or a.dim() != 4 or tuple(a.shape[1:]) != (len(PARENTS), 3, 3):
        raise ShapeError(f"joint_frame_offsets: shapes {tuple(a.shape)} and {tuple(b.shape)}; expected both "
                         f"(T, {len(PARENTS)}, 3, 3)")
    a, b = a.double(), b.double()
    zeros = torch.zeros(len(PARENTS), 3, dtype=torch.float64)  # the rotation part only: rest joints at 0
    Ga, Gb = forward_kinematics(a, zeros)[0], forward_kinematics(b, zeros)[0]
    per_frame = Ga.transpose(-1, -2) @ Gb
    mean = project_to_so3(per_frame.mean(0))
    eye = torch.eye(3, dtype=torch.float64).expand_as(mean)
    return JointOffsets(mean, torch.rad2deg(geodesic_angle(mean, eye)),
                        torch.rad2deg(geodesic_angle(per_frame, mean.expand_as(per_frame))).mean(0),
                        torch.rad2deg(geodesic_angle(a, b)).mean(0))


#: Largest accepted :attr:`AugmentSettings.rest_offset_deg` (the chains measured differ by <= 30 deg
#: at the major joints; beyond 45 a pose stops looking like the captured one).
MAX_REST_OFFSET_DEG = 45.0


@dataclass(frozen=True)
class AugmentSettings:
    """Motion and placement augmentation of a method's *training* clips, in one recordable form
    (:meth:`to_dict` / :meth:`from_dict`: plain JSON/YAML values, what a weight's recipe holds).

    Attributes:
        mirror: add the left/right mirror image of every clip (tag ``mirror``).
        speed_copies: add that many copies of every clip played at a speed drawn log-uniformly
            from ``speed_range`` (tags ``speed<k>``), each mirrored with probability 1/2 when
            ``mirror``.
        speed_range: (low, high) speed factors.
        heading_copies: add that many copies turned by a uniform random heading (tags
            ``heading<k>``).
        mix_copies: add that many copies whose upper body comes from another clip of the split
            (tags ``mix<k>``; the partner is drawn by the caller's generator).
        site_jitter_m: radius (m) of the random displacement of every sensor site, drawn per clip
            (0 = sensors at their nominal sites).
        rest_offset_deg: every joint of every clip turned by a constant offset of up to this many
            degrees, drawn per clip (:func:`offset_rest`: another capture chain's rest pose; 0 = off).
            In place, no copies; left out of :meth:`to_dict` at 0, so fingerprints of runs without
            it stay as they were.
        rest_offset_joints: the SMPL joint names that get offsets (``()``: every joint); left out of
            :meth:`to_dict` when empty.
    """

    mirror: bool = False
    speed_copies: int = 0
    speed_range: tuple[float, float] = (0.8, 1.25)
    heading_copies: int = 0
    mix_copies: int = 0
    site_jitter_m: float = 0.0
    rest_offset_deg: float = 0.0
    rest_offset_joints: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        lo, hi = (float(x) for x in self.speed_range)
        if not (0.0 < lo <= hi):
            raise ConfigError(f"AugmentSettings.speed_range: expected (low, high) with 0 < low <= high, got {self.speed_range!r}")
        for name in ("speed_copies", "heading_copies", "mix_copies"):
            if int(getattr(self, name)) < 0:
                raise ConfigError(f"AugmentSettings.{name}: expected >= 0, got {getattr(self, name)!r}")
        if not (0.0 <= float(self.site_jitter_m) <= 0.1):
            raise ConfigError(f"AugmentSettings.site_jitter_m: expected 0-0.1 m, got {self.site_jitter_m!r}")
        if not (0.0 <= float(self.rest_offset_deg) <= MAX_REST_OFFSET_DEG):
            raise ConfigError(f"AugmentSettings.rest_offset_deg: expected 0-{MAX_REST_OFFSET_DEG:g} deg, "
                              f"got {self.rest_offset_deg!r}")
        unknown = [n for n in self.rest_offset_joints if n not in JOINT_INDEX]
        if unknown:
            raise ConfigError(f"AugmentSettings.rest_offset_joints: unknown joints {unknown}; expected SMPL names "
                              f"({', '.join(JOINT_INDEX)})")
        object.__setattr__(self, "speed_range", (lo, hi))
        object.__setattr__(self, "rest_offset_joints", tuple(self.rest_offset_joints))

    def to_dict(self) -> dict[str, Any]:
        """Plain values (lists for tuples), JSON/YAML-ready."""
        d = asdict(self)
        d["speed_range"] = list(self.speed_range)
        if not self.rest_offset_deg:
            del d["rest_offset_deg"]
        if self.rest_offset_joints:
            d["rest_offset_joints"] = list(self.rest_offset_joints)
        else:
            del d["rest_offset_joints"]
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> AugmentSettings:
        """The inverse of :meth:`to_dict`; an unknown key is refused, naming the known ones."""
        unknown = sorted(set(d) - {f.name for f in fields(cls)})
        if unknown:
            raise ConfigError(f"augmentation settings: unknown key(s) {unknown}; known: {[f.name for f in fields(cls)]}")
        kw = dict(d)
        if "speed_range" in kw:
            kw["speed_range"] = tuple(kw["speed_range"])
        if "rest_offset_joints" in kw:
            kw["rest_offset_joints"] = tuple(kw["rest_offset_joints"])
        return cls(**kw)

    def tags(self) -> list[str]:
        """Tags of the augmented copies of one clip, in order."""
        return ((["mirror"] if self.mirror else []) + [f"speed{k}" for k in range(self.speed_copies)]
                + [f"heading{k}" for k in range(self.heading_copies)] + [f"mix{k}" for k in range(self.mix_copies)])


def augmented_ids(ids: list[str], settings: AugmentSettings) -> list[str]:
    """Ids of the augmented copies of clips ``ids``: ``<id>#<tag>`` for each :meth:`AugmentSettings.tags`."""
    tags = settings.tags()
    return [f"{cid}#{t}" for cid in ids for t in tags]


def augment_clip(aid: str, seq: MotionSequence, settings: AugmentSettings, generator: torch.Generator,
                 root_rest: torch.Tensor | None = None, partner: MotionSequence | None = None) -> MotionSequence:
    """The motion of augmented copy ``aid`` (``<id>#<tag>``, :func:`augmented_ids`) of clip ``seq``.

    ``mirror``: :func:`mirror`. ``speed<k>``: two uniform draws ``u, flip`` (float64) from
    ``generator``; speed ``exp(log lo + u (log hi - log lo))`` (:func:`play_speed`), then mirrored
    when ``settings.mirror`` and ``flip < 0.5``. ``heading<k>``: one draw, heading ``2 pi u - pi``.
    ``mix<k>``: :func:`mix_parts` with ``partner``'s upper body. The caller seeds ``generator`` per
    copy (its own namespace), so each method keeps its own draws.
    """
    tag = aid.rsplit("#", 1)[1]
    if tag == "mirror":
        return mirror(seq, root_rest)
    if tag.startswith("speed"):
        u, flip = torch.rand(2, generator=generator, dtype=torch.float64).tolist()
        lo, hi = (math.log(v) for v in settings.speed_range)
        m = play_speed(seq, math.exp(lo + u * (hi - lo)))
        return mirror(m, root_rest) if settings.mirror and flip < 0.5 else m
    if tag.startswith("heading"):
        u = float(torch.rand((), generator=generator, dtype=torch.float64))
        return rotate_heading(seq, 2 * math.pi * u - math.pi, root_rest)
    if tag.startswith("mix"):
        if partner is None:
            raise ShapeError(f"augment_clip {aid!r}: a mix copy needs the partner clip")
        return mix_parts(partner, seq)
    raise ShapeError(f"augment_clip: unknown augmentation tag {tag!r} in {aid!r}; expected one of {settings.tags()}")
