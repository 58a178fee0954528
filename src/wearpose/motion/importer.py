"""Bring your own motion: any BVH or ASF/AMC clip -> SMPL-24 :class:`MotionSequence`, with the
skeleton map, length unit, up axis and rest pose detected and reported.

Pipeline of :func:`import_motion` (each step's outcome goes into :class:`ImportReport`):

1. **read**: ``.bvh``/``.bvh.gz`` (:func:`wearpose.motion.read_bvh`) or ``.amc``/``.amc.gz`` with its
   ``.asf`` (:func:`wearpose.motion.read_asf_amc`; AMC has no frame rate: ``fps`` or 120 Hz).
   A BVH on SMPL's own tree (our export) is read exactly (:func:`read_smpl_bvh`), no retargeting.
2. **map** the skeleton onto SMPL-24 (:func:`wearpose.motion.mapping.match_skeleton`).
3. **units** (:func:`detect_units`): the leg length hip -> knee -> ankle in file units, from the
   bone vectors (pose independent), is read in each candidate unit (m, cm, mm, inch, Acclaim's
   1/0.45 inch); a unit declared by the file (ASF ``:units``) or by a built-in corpus map is kept
   when it gives a plausible adult-to-child leg (0.35-1.4 m), otherwise the candidate whose leg
   is nearest 0.8 m wins. ``units=`` overrides.
4. **up axis** (:func:`detect_up`): over the whole clip, two kinds of evidence: the floor (along
   the true up the body's lowest point per frame stays on the floor; along a horizontal axis it
   moves as the body travels, turns or lies down) and the standing frames (the mean ankles ->
   head direction where the body is most extended). The floor decides when it is decisive,
   else the standing frames; the signed world axis (``y``, ``z``, ``-z``, ...) is up and the
   whole clip is turned about the origin so that it becomes +Y (Z up -> Y up is
   :data:`wearpose.geometry.Z_UP_TO_Y_UP`). Facing is kept as captured. When the evidence
   disagrees or is weak the report warns. ``up=`` overrides.
5. **rest pose**: retargeting (:func:`wearpose.motion.retarget_bvh`) rebuilds per joint the
   rotation that takes the source's zero pose to SMPL's T-pose (bone directions, left-right
   vectors, knee/elbow hinge axes), so an A-pose or any bind pose keeps SMPL pose parameters
   meaningful; the report labels the zero pose (T-pose, A-pose, other) from its bone directions
   and gives the correction per joint (:func:`rest_pose_correction`).
   The root translation is scaled by SMPL's over the source's pelvis-to-ankle height.
6. **check**: the angle between every mapped bone of the result and the same bone of the source,
   per frame (:func:`wearpose.motion.retarget.bone_pairs` of the map), in degrees: per bone its
   mean and maximum over the clip, worst first, and a warning for every bone whose maximum
   exceeds :data:`BONE_WARN_DEG` (a wrong map, or source joints the map leaves out).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import torch

from wearpose.body.skeleton import JOINT_INDEX, JOINT_NAMES, PARENTS
from wearpose.errors import InputFileError, WearposeError
from wearpose.geometry import Z_UP_TO_Y_UP, geodesic_angle, rotation_x, rotation_z
from wearpose.geometry.units import CM_TO_M, INCH_TO_M, MM_TO_M
from wearpose.motion.asf import read_asf_amc
from wearpose.motion.bvh import BvhMotion, bvh_forward_kinematics, read_bvh
from wearpose.motion.mapping import SkeletonMatch, match_skeleton
from wearpose.motion.retarget import (
    BANDAI, BONE_PAIRS, CMU_DAZ, RetargetError, Retargeted, SkeletonMap, TPose, _position_in, _rest_offsets,
    bone_direction_errors, bone_pairs, next_joint, retarget_bvh,
)
from wearpose.motion.sequence import MotionSequence
from wearpose.motion.smpl_bvh import is_smpl_bvh, read_smpl_bvh
from wearpose.motion.template import default_rest_joints

#: Length units a file may use: name -> metres per unit.
UNITS: dict[str, float] = {"m": 1.0, "cm": CM_TO_M, "mm": MM_TO_M, "inch": INCH_TO_M, "acclaim": INCH_TO_M / 0.45}
#: Leg length (hip -> knee -> ankle) of a typical adult, and the range taken as plausible, metres.
TYPICAL_LEG_M = 0.80
PLAUSIBLE_LEG_M = (0.35, 1.4)
#: Up axes: name -> rotation taking that file axis to wearpose's +Y (right-handed, proper).
_HALF_PI = torch.tensor(math.pi / 2, dtype=torch.float64)
UP_AXES: dict[str, torch.Tensor] = {
    "y": torch.eye(3, dtype=torch.float64),
    "-y": rotation_x(2 * _HALF_PI),
    "z": Z_UP_TO_Y_UP.to(torch.float64),
    "-z": rotation_x(_HALF_PI),
    "x": rotation_z(_HALF_PI),
    "-x": rotation_z(-_HALF_PI),
}
#: A mapped bone whose direction differs from the source bone's by more than this (degrees) in
#: any frame is named in the report's warnings. A correct map gives ~0 everywhere (bone
#: directions are transferred exactly); 10 deg is the import acceptance bound.
BONE_WARN_DEG = 10.0
#: The bones of the SMPL tree with a counterpart in every corpus skeleton (the import check
#: itself compares every mapped bone of the map used, :func:`wearpose.motion.retarget.bone_pairs`).
IMPORT_BONE_PAIRS: tuple[tuple[str, str], ...] = BONE_PAIRS + (
    ("left_collar", "left_shoulder"), ("right_collar", "right_shoulder"),
    ("left_ankle", "left_foot"), ("right_ankle", "right_foot"),
)
_CORPUS_MAPS = (CMU_DAZ.name, BANDAI.name)
MOTION_SUFFIXES = (".bvh", ".bvh.gz", ".amc", ".amc.gz")


@dataclass
class ImportReport:
    """What :func:`import_motion` found and did (all JSON-serialisable).

    Attributes:
        file: source file; format: ``"bvh"``, ``"asf/amc"`` or ``"bvh (wearpose SMPL export)"``;
        skeleton: map name; map_source: how the map was chosen; mapping: rows ``[smpl, joint, how]``;
        map_notes: remarks; units: ``{"name", "m_per_unit", "how", "leg_m"}``;
        up: ``{"axis", "how", "agreement"}`` (agreement: cosine of the measured up with the axis);
        rest_pose: ``{"kind", "max_deg", "max_joint", "bone_deg", "total_deg"}``; frames; fps;
        translation_scale: SMPL/source leg ratio applied to the root trajectory;
        bone_error_deg: see :func:`bone_error_summary` (per bone mean and max over the clip,
        worst first); hinge_axes: where knee/elbow axes came from; warnings: what the user
        should look at (bones above :data:`BONE_WARN_DEG`, assumptions); seconds: wall time.
    """

    file: str
    format: str = ""
    skeleton: str = ""
    map_source: str = ""
    mapping: list[list[str]] = field(default_factory=list)
    map_notes: list[str] = field(default_factory=list)
    units: dict[str, Any] = field(default_factory=dict)
    up: dict[str, Any] = field(default_factory=dict)
    rest_pose: dict[str, Any] = field(default_factory=dict)
    frames: int = 0
    fps: float = 0.0
    translation_scale: float = 1.0
    bone_error_deg: dict[str, Any] = field(default_factory=dict)
    hinge_axes: dict[str, str] = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)
    seconds: float = 0.0

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


@dataclass
class Imported:
    """Result of :func:`import_motion`: the SMPL motion, its report and (when retargeted) the
    :class:`Retargeted` details."""

    sequence: MotionSequence
    report: ImportReport
    retargeted: Retargeted | None = None


# ---------------------------------------------------------------------------- reading
def read_motion_file(path: str | Path, fps: float | None = None, asf: str | Path | None = None) -> BvhMotion:
    """Read a BVH (``.bvh``/``.bvh.gz``) or an AMC (``.amc``/``.amc.gz``, its ASF beside it, or
    ``asf``: the skeleton file to use, for folders with several actors' ASF files).

    Raises:
        InputFileError: unknown extension, a lone ``.asf``, or any reader error.
    """
    path = Path(path)
    name = path.name.lower()
    if name.endswith((".bvh", ".bvh.gz")):
        return read_bvh(path)
    if name.endswith((".amc", ".amc.gz")):
        if asf is not None and not Path(asf).is_file():
            raise InputFileError(asf, "ASF skeleton file not found", "the .asf file of this AMC's actor (--asf FILE)")
        return read_asf_amc(path, asf=asf, fps=fps)
    if name.endswith(".asf"):
        raise InputFileError(path, "an .asf file holds only the skeleton", "the .amc motion files (their .asf beside them is found automatically)")
    raise InputFileError(path, f"unsupported file type {path.suffix!r}", "a .bvh, .bvh.gz, .amc or .amc.gz motion file")


# ---------------------------------------------------------------------------- units
def leg_length(motion: BvhMotion, smap: SkeletonMap) -> float:
    """Mean hip -> knee -> ankle length over both legs, in file units (from the bone vectors)."""
    skel = motion.skeleton
    offs = _rest_offsets(motion)
    total = []
    for side in ("left", "right"):
        chain = [skel.index(smap.joints[f"{side}_{j}"]) for j in ("hip", "knee", "ankle")]
        segs = [_position_in(skel, offs, c, a) for a, c in zip(chain[:-1], chain[1:])]
        if any(s is None for s in segs):
            raise RetargetError(f"{side} leg joints are not in one chain")
        total.append(sum(float(s.norm()) for s in segs))  # type: ignore[union-attr]
    return float(np.mean(total))


def parse_units(value: str | float) -> tuple[str, float]:
    """``"cm"`` -> ``("cm", 0.01)``; a number -> ``("<n> m/unit", n)``.

    Raises:
        WearposeError: unknown unit name.
    """
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        if not value > 0:
            raise WearposeError(f"units: {value!r} is not a positive number of metres per unit")
        return f"{float(value):g} m/unit", float(value)
    v = str(value).strip().lower()
    aliases = {"meter": "m", "metre": "m", "centimeter": "cm", "centimetre": "cm", "millimeter": "mm",
               "millimetre": "mm", "in": "inch", "inches": "inch"}
    v = aliases.get(v, aliases.get(v[:-1], v) if v.endswith("s") else v)
    if v in UNITS:
        return v, UNITS[v]
    try:
        return parse_units(float(v))
    except ValueError:
        raise WearposeError(f"unknown length unit {value!r}; expected one of {', '.join(UNITS)} or metres per unit (a number)") from None


def detect_units(leg_file_units: float, declared: tuple[str, float] | None = None) -> dict[str, Any]:
    """Pick the length unit from the leg length (rule in the module doc).

    Returns:
        ``{"name", "m_per_unit", "how", "leg_m"}``.
    """
    lo, hi = PLAUSIBLE_LEG_M
    if declared is not None:
        leg = leg_file_units * declared[1]
        if lo <= leg <= hi:
            return {"name": declared[0], "m_per_unit": declared[1], "how": "declared", "leg_m": leg}
    best = min(UNITS, key=lambda u: abs(math.log(max(leg_file_units * UNITS[u], 1e-12) / TYPICAL_LEG_M)))
    leg = leg_file_units * UNITS[best]
    how = f"detected from leg length ({leg_file_units:.4g} file units)"
    if declared is not None:
        how += f"; declared {declared[0]} gives an implausible {leg_file_units * declared[1]:.3g} m leg"
    if not lo <= leg <= hi:
        how += f"; WARNING: {leg:.3g} m is outside {lo}-{hi} m"
    return {"name": best, "m_per_unit": UNITS[best], "how": how, "leg_m": leg}


# ---------------------------------------------------------------------------- up axis
#: Frames of the clip the up-axis evidence is computed on (evenly spread over the whole clip).
UP_MAX_FRAMES = 600
#: Floor evidence along a direction counts only when the body's extent along it changes by at
#: least this many leg lengths over the clip (lying down, sitting up, getting up): a clip that
#: keeps one posture tells nothing about the floor (a straight walk keeps its sideways extremes
#: as still as its feet).
UP_FLOOR_MIN_EXTENT_CHANGE = 0.5
#: ... and when the lowest point along it moves less than this share of that change and less
#: than :data:`UP_FLOOR_MAX_SUPPORT` leg lengths (a floor holds the lowest point to a few cm).
UP_FLOOR_RATIO = 0.15
UP_FLOOR_MAX_SUPPORT = 0.08
#: ... and when the body's ankles -> head vector along it goes from upright (at least this share
#: of its longest length) to flat (at most :data:`UP_FLOOR_FLAT`): the clip stands and lies on
#: that floor. Without such a change a clip is as much "upright, reaching forward" as "lying,
#: lifting the arms" (or "toe touches" as "sit-ups"), and upright, the common case, is kept.
UP_FLOOR_TALL = 0.7
UP_FLOOR_FLAT = 0.45
#: Standing evidence whose mean direction agrees less than this (cosine) is weak: a warning.
UP_STANDING_AGREEMENT = 0.9


def floor_evidence(P: torch.Tensor, leg: float) -> dict[str, dict[str, float]]:
    """Per signed world axis ``a`` (``"x"``, ``"-x"``, ...), from joint positions ``P`` ``(T, J, 3)``
    (file units) and the leg length (same units):

    - ``support``: spread of the body's lowest point along ``a`` over the clip (median minus
      5th percentile of ``min_j a . P[t, j]``: jumps lift only the upper half), leg lengths;
    - ``extent_change``: how much the body's extent along ``a`` (highest minus lowest point)
      changes (95th minus 5th percentile), leg lengths;
    - ``ratio``: support / extent_change: small when the body changes posture along ``a`` while
      its lowest point stays put -- a floor;
    - ``on_support``: mean share of joints within 0.15 leg lengths of the lowest point (a body
      lying on a floor rests many joints on it; the far end of a lying body, only its feet);
    - ``extent``: the body's extent along ``a``, 5th and 95th percentile, leg lengths
      (:func:`detect_up` adds ``upright``: the ankles -> head vector along ``a`` over its
      longest length, 5th and 95th percentile).
    """
    out: dict[str, dict[str, float]] = {}
    qs = torch.tensor([0.05, 0.5, 0.95], dtype=P.dtype)
    for k in range(3):
        for sign in (1.0, -1.0):
            h = sign * P[..., k]
            low, high = h.amin(dim=1), h.amax(dim=1)
            ql, qe = torch.quantile(low, qs), torch.quantile(high - low, qs)
            support = float(ql[1] - ql[0]) / max(leg, 1e-12)
            change = float(qe[2] - qe[0]) / max(leg, 1e-12)
            near = float(((h - low[:, None]) < 0.15 * leg).double().mean())
            out[("" if sign > 0 else "-") + "xyz"[k]] = {"support": round(support, 4), "extent_change": round(change, 4),
                                                        "ratio": round(support / max(change, 1e-12), 4),
                                                        "on_support": round(near, 4),
                                                        "extent": [round(float(qe[0]) / max(leg, 1e-12), 4),
                                                                   round(float(qe[2]) / max(leg, 1e-12), 4)]}
    return out


def _floor_axis(ev: dict[str, dict[str, Any]], need_upright: bool = True) -> str | None:
    """The signed axis the floor evidence picks, or None when it does not decide (thresholds
    ``UP_FLOOR_*``; between two floor-like axes, the one with more joints on it).
    ``need_upright=False``: the floor-like axis even without upright and flat frames on it."""
    cand = [a for a, e in ev.items() if e["extent_change"] >= UP_FLOOR_MIN_EXTENT_CHANGE and e["ratio"] < UP_FLOOR_RATIO
            and e["support"] < UP_FLOOR_MAX_SUPPORT
            and (not need_upright or (e["upright"][1] >= UP_FLOOR_TALL and e["upright"][0] <= UP_FLOOR_FLAT))]
    if not cand:
        return None
    best = min(ev[a]["ratio"] for a in cand)
    # Within a factor 3 of the best ratio the evidence is alike (a sit-up keeps both the back and
    # the feet at the far end still): the floor is the side more joints rest on.
    return max((a for a in cand if ev[a]["ratio"] <= 3 * best), key=lambda a: (ev[a]["on_support"], -ev[a]["ratio"]))


def detect_up(motion: BvhMotion, smap: SkeletonMap, max_frames: int = UP_MAX_FRAMES) -> dict[str, Any]:
    """Up axis of the file's world from the whole clip (up to ``max_frames`` frames spread
    evenly over it), from two kinds of evidence:

    - **standing**: in the frames where the body is most extended (head to the mid-ankle point
      at least 90 % of its longest), the mean ankles -> head direction. Lying down is extended
      too, so this alone calls a clip that lies down "Z up" or "X up";
    - **floor** (:func:`floor_evidence`, on the mapped joints): a body on a floor keeps its
      lowest point on it while it changes posture (lies down, sits up, gets up); along a
      horizontal axis the lowest point moves as the posture changes.

    The floor decides when it has evidence (:func:`_floor_axis`), else the standing frames do.
    When the two disagree, or the standing evidence is weak and the floor has none, the
    result's ``warnings`` say so (pass ``--up`` if the axis is wrong).

    Returns:
        ``{"axis": "y"|"-y"|"z"|..., "how", "agreement"`` (cosine between the standing direction
        and the axis), ``"evidence"`` (``standing``: axis, agreement, frames; ``floor``: the axis
        it picks or None, and per signed axis :func:`floor_evidence`), ``"warnings"``}.
    """
    T = motion.num_frames
    idx = torch.linspace(0, T - 1, min(T, max_frames)).round().long().unique()
    sub = BvhMotion(motion.skeleton, motion.frame_time, motion.rotations[idx], motion.translations[idx], motion.path)
    _, P = bvh_forward_kinematics(sub)
    skel = motion.skeleton
    top_name = next(smap.joints[k] for k in ("head", "neck", "spine3", "spine2", "spine1", "pelvis") if k in smap.joints)
    top = P[:, skel.index(top_name)]
    feet = 0.5 * (P[:, skel.index(smap.joints["left_ankle"])] + P[:, skel.index(smap.joints["right_ankle"])])
    v = top - feet
    ext = v.norm(dim=-1)
    sel = ext >= 0.9 * ext.max()
    u = (v[sel] / ext[sel, None].clamp_min(1e-12)).sum(0)
    u = u / u.norm().clamp_min(1e-12)
    k_stand = int(u.abs().argmax())
    stand_axis = ("-" if float(u[k_stand]) < 0 else "") + "xyz"[k_stand]
    try:
        leg = leg_length(motion, smap)
    except RetargetError:
        leg = float(ext.max()) / 2
    # Mapped joints only: a rig's static helper joints (Bandai's joint_Root stays at the origin
    # while the body walks away) would pose as a still "lowest point".
    body = sorted({skel.index(n) for n in smap.joints.values()})
    fev = floor_evidence(P[:, body], leg)
    # How upright the body stands along each signed axis: ankles -> head along it over its
    # longest length (5th and 95th percentile over the clip).
    for a, e in fev.items():
        share = (-1.0 if a.startswith("-") else 1.0) * v[:, "xyz".index(a[-1])] / ext.max().clamp_min(1e-12)
        q = torch.quantile(share, torch.tensor([0.05, 0.95], dtype=share.dtype))
        e["upright"] = [round(float(q[0]), 4), round(float(q[1]), 4)]
    floor_axis = _floor_axis(fev)
    axis = floor_axis if floor_axis is not None else stand_axis
    k = "xyz".index(axis[-1])
    agreement = float((-1.0 if axis.startswith("-") else 1.0) * u[k])
    if floor_axis is not None:
        e = fev[floor_axis]
        how = (f"detected from the whole clip ({len(idx)} frames): the floor (the body's extent along {axis} changes "
               f"{e['extent_change']:.2f} leg lengths while its lowest point moves {e['support']:.2f})")
    else:
        how = f"detected from the whole clip ({len(idx)} frames): {int(sel.sum())} standing frames ({top_name} above the ankles)"
    warnings = []
    if floor_axis is not None and floor_axis != stand_axis:
        warnings.append(f"up axis: the most extended frames point along {stand_axis} (agreement {abs(float(u[k_stand])):.2f}), "
                        f"but the floor says {axis} (the clip lies down, sits up or gets up); {axis} was used "
                        f"(pass --up {stand_axis} if the subject is upright along it)")
    elif floor_axis is None and (maybe := _floor_axis(fev, need_upright=False)) is not None and maybe != axis:
        warnings.append(f"up axis: the lowest point stays still along {maybe} while the body changes posture (a floor?), "
                        f"but the body is never both upright and flat along it; the upright reading {axis} was kept (pass "
                        f"--up {maybe} if the clip lies on a floor: sit-ups and toe touches move alike)")
    elif floor_axis is None and agreement < UP_STANDING_AGREEMENT:
        warnings.append(f"up axis: weak evidence: the most extended frames agree with {axis} only {agreement:.2f} and the "
                        "clip never changes posture on a floor; check the result (wearpose view) and pass --up if it is wrong")
    evidence = {"standing": {"axis": stand_axis, "agreement": round(abs(float(u[k_stand])), 4), "frames": int(sel.sum())},
                "floor": {"axis": floor_axis, "per_axis": fev}}
    return {"axis": axis, "how": how, "agreement": agreement, "evidence": evidence, "warnings": warnings}


def to_y_up(motion: BvhMotion, axis: str) -> BvhMotion:
    """The motion with its world turned so that file axis ``axis`` becomes +Y (root joint only)."""
    R = UP_AXES[axis]
    if axis == "y":
        return motion
    rot = motion.rotations.clone()
    trans = motion.translations.clone()
    for j, p in enumerate(motion.skeleton.parents):
        if p < 0:
            rot[:, j] = R @ rot[:, j]
            trans[:, j] = trans[:, j] @ R.T
    return replace(motion, rotations=rot, translations=trans)


# ---------------------------------------------------------------------------- rest pose
def rest_pose_correction(tpose: TPose, rest_joints: torch.Tensor, motion: BvhMotion, smap: SkeletonMap) -> dict[str, Any]:
    """How far the source's zero pose is from SMPL's T-pose.

    ``bone_deg``: per mapped joint with a mapped next joint, the angle (degrees) between its bone
    in the source's zero pose and the same bone in SMPL's T-pose, both seen from the pelvis (so
    the facing of the zero pose does not count): 45 at the shoulders of an A-pose, a few degrees
    where only proportions differ. ``total_deg``: the angle of the SMPL local rotation the zero
    pose retargets to (``T_parent @ T_j^T``: swing and twist, i.e. the per-joint correction).
    ``kind`` (from the upper arms' ``bone_deg``): ``"T-pose"`` (both < 20 deg), ``"A-pose"`` (both
    lowered by 25-70 deg), else ``"other bind pose"``. Proportions alone (a source collar or
    spine steeper than SMPL's) give 5-30 deg on other bones; that is not a bind-pose change.
    """
    T = tpose.rotations
    rest = rest_joints.to(torch.float64)
    skel = motion.skeleton
    offs = _rest_offsets(motion)
    # Zero-pose positions: every local rotation is the identity, so offsets add up in the world.
    pos = torch.zeros(skel.num_joints, 3, dtype=torch.float64)
    for j, p in enumerate(skel.parents):
        pos[j] = offs[j] if p < 0 else pos[p] + offs[j]
    bone: dict[str, float] = {}
    total: dict[str, float] = {}
    eye = torch.eye(3, dtype=torch.float64)
    T0 = T.get(0, eye)
    for j, Tj in T.items():
        name = JOINT_NAMES[j]
        p = PARENTS[j]
        while p >= 0 and p not in T:
            p = PARENTS[p]
        if p >= 0:
            total[name] = round(math.degrees(float(geodesic_angle(T[p] @ Tj.T, eye))), 2)
        nxt = tpose.bone_ends.get(name, next_joint(name, smap.joints))
        if nxt is not None and nxt in smap.joints:
            d = pos[skel.index(smap.joints[nxt])] - pos[skel.index(smap.joints[name])]
            b = rest[JOINT_INDEX[nxt]] - rest[j]
            if d.norm() > 0 and b.norm() > 0:
                c = float((T0 @ d) @ b / (d.norm() * b.norm()))
                bone[name] = round(math.degrees(math.acos(max(-1.0, min(1.0, c)))), 2)
    if not bone:
        return {"kind": "unknown", "max_deg": 0.0, "max_joint": "", "bone_deg": {}, "total_deg": total}
    mj = max(bone, key=bone.get)  # type: ignore[arg-type]
    arms = [bone.get(s) for s in ("left_shoulder", "right_shoulder")]
    if all(a is not None and a < 20 for a in arms):
        kind = "T-pose"
    elif all(a is not None and 25 <= a <= 70 for a in arms):
        kind = "A-pose"
    else:
        kind = "other bind pose"
    return {"kind": kind, "max_deg": bone[mj], "max_joint": mj, "bone_deg": bone, "total_deg": total}


# ---------------------------------------------------------------------------- import
def bone_error_summary(res: Retargeted, rest_joints: torch.Tensor, warn_deg: float = BONE_WARN_DEG) -> dict[str, Any]:
    """Angle between every mapped bone of the result and the same bone of the source, degrees.

    Returns:
        ``{"mean"`` (over bones of the per-bone clip means), ``"worst_bone"``, ``"worst_bone_mean"``,
        ``"worst_bone_max"``, ``"per_bone"`` (bone -> clip mean), ``"per_bone_max"`` (bone -> clip
        max), ``"ranked"`` (rows ``{"bone", "source", "mean", "max", "max_frame"}``, largest max
        first), ``"warn_deg"``, ``"warnings"`` (one line per bone whose max exceeds ``warn_deg``)``}``.
        Bones are ``"smpl_a->smpl_b"``; ``source`` names the file's joints.
    """
    errs = bone_direction_errors(res, rest_joints, bone_pairs(res.smap.joints))
    rows = []
    for k, v in errs.items():
        deg = np.degrees(v)
        a, b = k.split("->")
        rows.append({"bone": k, "source": f"{res.smap.joints[a]}->{res.smap.joints[b]}",
                     "mean": round(float(np.nanmean(deg)), 3), "max": round(float(np.nanmax(deg)), 3),
                     "max_frame": int(np.nanargmax(deg))})
    rows.sort(key=lambda r: -r["max"])
    if not rows:
        return {"mean": float("nan"), "worst_bone": "", "worst_bone_mean": float("nan"), "worst_bone_max": float("nan"),
                "per_bone": {}, "per_bone_max": {}, "ranked": [], "warn_deg": warn_deg, "warnings": []}
    warnings = [f"bone {r['bone']} (your {r['source']}) is {r['max']:.1f} deg off the source at frame {r['max_frame']} "
                f"(mean {r['mean']:.1f}; bound {warn_deg:g}): joints of yours between the two that the map leaves out bend "
                f"it, or the map is wrong there; check those rows of the joint table and map them with --joint-map lines "
                f"such as '{r['bone'].split('->')[1]}: YourJoint'"
                for r in rows if r["max"] > warn_deg]
    return {"mean": float(np.mean([r["mean"] for r in rows])), "worst_bone": rows[0]["bone"],
            "worst_bone_mean": rows[0]["mean"], "worst_bone_max": rows[0]["max"],
            "per_bone": {r["bone"]: r["mean"] for r in rows}, "per_bone_max": {r["bone"]: r["max"] for r in rows},
            "ranked": rows, "warn_deg": warn_deg, "warnings": warnings}


def import_motion(path: str | Path, rest_joints: torch.Tensor | None = None,
                  joint_map: str | Path | Mapping[str, Any] | None = None, units: str | float | None = None,
                  up: str | None = None, fps: float | None = None, betas: torch.Tensor | None = None,
                  meta: Mapping[str, Any] | None = None, asf: str | Path | None = None) -> Imported:
    """Import one BVH or AMC file onto SMPL-24 (pipeline in the module doc).

    Args:
        path: the ``.bvh``/``.bvh.gz``/``.amc``/``.amc.gz``.
        rest_joints: ``(24, 3)`` rest joints (m) of the body to play it on (default body model).
        joint_map: YAML file or loaded map overriding the skeleton match.
        units: override: ``m``, ``cm``, ``mm``, ``inch``, ``acclaim`` or metres per unit.
        up: override: ``y``, ``z``, ``-y``, ``-z``, ``x``, ``-x``.
        fps: frame rate of AMC files (they store none; default 120).
        betas: ``(10,)`` shape stored in the sequence.
        meta: extra ``sequence.meta`` entries.
        asf: the ASF skeleton of an AMC file (default: found beside it, see
            :func:`wearpose.motion.asf.find_asf_for`); ignored for BVH files.

    Returns:
        :class:`Imported`; ``sequence.meta["import"]`` holds the report.

    Raises:
        InputFileError: unreadable or malformed file, unmappable skeleton (names the file,
            line or joint, and the problem).
    """
    t0 = time.perf_counter()
    path = Path(path)
    if rest_joints is None:
        rest_joints, _ = default_rest_joints()
    rest = rest_joints.to(torch.float64)
    if up is not None and up.lower() not in UP_AXES:
        raise WearposeError(f"up axis {up!r}; expected one of {', '.join(UP_AXES)}")
    motion = read_motion_file(path, fps=fps, asf=asf)
    fmt = motion.meta.get("format", "bvh")
    report = ImportReport(file=str(path), format=fmt)
    if fmt == "bvh" and is_smpl_bvh(motion):
        seq = read_smpl_bvh(motion, rest)
        report.format = "bvh (wearpose SMPL export)"
        report.skeleton, report.map_source = "smpl", "exact (SMPL tree, rotations read as written)"
        report.mapping = [[n, n, "exact"] for n in JOINT_NAMES]
        report.units = {"name": "cm", "m_per_unit": CM_TO_M, "how": "format (wearpose export)", "leg_m": float("nan")}
        report.up = {"axis": "y", "how": "format (wearpose export)", "agreement": 1.0}
        report.rest_pose = {"kind": "T-pose", "max_deg": 0.0, "max_joint": "", "bone_deg": {}, "total_deg": {}}
        report.frames, report.fps = seq.num_frames, seq.fps
        report.bone_error_deg = {"mean": 0.0, "worst_bone": "", "worst_bone_mean": 0.0, "worst_bone_max": 0.0,
                                 "per_bone": {}, "per_bone_max": {}, "ranked": [], "warn_deg": BONE_WARN_DEG, "warnings": []}
        report.seconds = time.perf_counter() - t0
        seq.meta.update(dict(meta or {}))
        seq.meta["import"] = report.to_dict()
        return Imported(seq, report)

    if motion.num_frames == 0:
        raise InputFileError(path, "no frames", "at least one frame of motion", field="MOTION")
    offs = _rest_offsets(motion).numpy()
    match: SkeletonMatch = match_skeleton(motion.skeleton, offs, joint_map, path)
    smap = match.smap
    opts = match.joint_map_options
    # Units.
    units = units if units is not None else opts.get("units")
    try:
        leg_fu = leg_length(motion, smap)
    except RetargetError as exc:
        raise InputFileError(path, f"cannot measure the legs: {exc}", "hip, knee and ankle joints in one chain per leg",
                             field=f"joint {smap.joints['left_hip']}") from exc
    if not leg_fu > 0:
        raise InputFileError(path, "the legs have zero length", "hip, knee and ankle joints at distinct places",
                             field=f"joint {smap.joints['left_hip']}")
    if units is not None:
        uname, m_per = parse_units(units)
        ures = {"name": uname, "m_per_unit": m_per, "how": "given", "leg_m": leg_fu * m_per}
    else:
        declared = None
        if "units_to_m" in motion.meta:
            declared = (motion.meta.get("units_declared", "ASF :units"), float(motion.meta["units_to_m"]))
            for k, v in UNITS.items():
                if abs(v - declared[1]) < 1e-9 * v:
                    declared = (k, v)
        elif smap.name in _CORPUS_MAPS:
            declared = ("cm", smap.units_to_m)
        ures = detect_units(leg_fu, declared)
    smap = replace(smap, units_to_m=ures["m_per_unit"])
    # Up axis.
    up = up if up is not None else opts.get("up")
    if up is not None:
        up_res = {"axis": str(up).lower(), "how": "given", "agreement": float("nan")}
        if up_res["axis"] not in UP_AXES:
            raise WearposeError(f"up axis {up!r}; expected one of {', '.join(UP_AXES)}")
    elif smap.name in _CORPUS_MAPS:
        up_res = {"axis": "y", "how": "declared (corpus skeleton)", "agreement": float("nan")}
    else:
        up_res = detect_up(motion, smap)
    up_warnings = up_res.pop("warnings", [])
    motion_y = to_y_up(motion, up_res["axis"])
    m = {"source_format": fmt, "import": {}}
    m.update(dict(meta or {}))
    try:
        res = retarget_bvh(motion_y, rest, smap, betas=betas, meta=m)
    except RetargetError as exc:
        raise InputFileError(path, f"cannot retarget: {exc}", "a humanoid skeleton with legs, or a --joint-map") from exc
    report.skeleton, report.map_source = smap.name, match.source
    report.mapping = [list(r) for r in match.table()]
    report.map_notes = match.notes
    report.units = {k: (round(v, 6) if isinstance(v, float) else v) for k, v in ures.items()}
    report.up = up_res
    report.rest_pose = rest_pose_correction(res.tpose, rest, motion, smap)
    report.frames, report.fps = res.sequence.num_frames, res.sequence.fps
    report.translation_scale = round(res.tpose.scale, 5)
    report.hinge_axes = dict(res.tpose.hinge_source)
    report.bone_error_deg = bone_error_summary(res, rest)
    if "WARNING" in str(ures["how"]):
        report.warnings.append(f"units: {ures['how'].split('WARNING: ')[-1]}; pass --units if the leg length {ures['leg_m']:.3g} m is wrong")
    report.warnings += up_warnings
    report.warnings += report.bone_error_deg["warnings"]
    if motion.meta.get("fps_assumed"):
        report.map_notes.append(f"AMC stores no frame rate: {res.sequence.fps:g} fps assumed (pass fps/--fps)")
    report.seconds = time.perf_counter() - t0
    res.sequence.meta["import"] = report.to_dict()
    return Imported(res.sequence, report, res)


def collect_motion_files(paths: Iterable[str | Path]) -> list[Path]:
    """Files to import: each given file, and every ``.bvh``/``.bvh.gz``/``.amc``/``.amc.gz`` below
    each given folder (sorted). Lone ``.asf`` files in folders are skeletons, not clips: skipped."""
    out: list[Path] = []
    for p in map(Path, paths):
        if p.is_dir():
            out += sorted(f for f in p.rglob("*") if f.is_file() and f.name.lower().endswith(MOTION_SUFFIXES))
        else:
            out.append(p)
    return out


def _out_name(f: Path, root: Path | None) -> Path:
    name = f.name
    for s in MOTION_SUFFIXES:
        if name.lower().endswith(s):
            name = name[: -len(s)]
            break
    rel = f.parent.relative_to(root) if root is not None and f.is_relative_to(root) else Path()
    return rel / f"{name}.npz"


def import_paths(paths: Sequence[str | Path], out_dir: str | Path, rest_joints: torch.Tensor | None = None,
                 joint_map: str | Path | None = None, units: str | float | None = None, up: str | None = None,
                 fps: float | None = None, on_file: Callable[[Path, dict[str, Any]], None] | None = None,
                 asf: str | Path | None = None) -> dict[str, Any]:
    """Import files and folders (mixed formats) into ``out_dir`` as MotionSequence ``.npz``.

    ``asf`` is the skeleton for every AMC file (a folder of one actor's takes whose ASF is not
    named after them, or several actors' ASF files side by side); other arguments as
    :func:`import_motion`.

    A file that fails is reported and the others carry on.

    Returns:
        ``{"converted", "failed", "out", "files": [report dict + "out" or "error"]}``.
    """
    out_dir = Path(out_dir)
    if rest_joints is None:
        rest_joints, _ = default_rest_joints()
    files: list[tuple[Path, Path | None]] = []
    for p in map(Path, paths):
        if p.is_dir():
            files += [(f, p) for f in collect_motion_files([p])]
        else:
            files.append((p, None))
    rows: list[dict[str, Any]] = []
    for f, root in files:
        try:
            imp = import_motion(f, rest_joints, joint_map=joint_map, units=units, up=up, fps=fps, asf=asf)
            dest = out_dir / _out_name(f, root)
            dest.parent.mkdir(parents=True, exist_ok=True)
            imp.sequence.save(dest)
            row = {**imp.report.to_dict(), "out": str(dest), "ok": True}
        except WearposeError as exc:
            row = {"file": str(f), "ok": False, "error": str(exc)}
        except Exception as exc:  # noqa: BLE001 - one bad file must not stop the batch
            row = {"file": str(f), "ok": False, "error": f"{type(exc).__name__}: {exc}"}
        rows.append(row)
        if on_file is not None:
            on_file(f, row)
    return {"converted": sum(r["ok"] for r in rows), "failed": sum(not r["ok"] for r in rows), "out": str(out_dir), "files": rows}


__all__ = ["import_motion", "import_paths", "collect_motion_files", "read_motion_file", "ImportReport", "Imported",
           "detect_units", "detect_up", "floor_evidence", "leg_length", "parse_units", "rest_pose_correction", "to_y_up",
           "UNITS", "UP_AXES", "IMPORT_BONE_PAIRS", "MOTION_SUFFIXES", "BONE_WARN_DEG", "bone_error_summary"]
