"""Pose, mesh, smoothness and translation metrics as the papers define them.

Every function is pure torch: any leading batch/time shape, float32 or float64, CPU or CUDA, and
(except where an SVD is involved, see :func:`pa_mpjpe`) differentiable. Functions return SI
units (metres, radians, m/s^3); :func:`to_report_units` converts to the units the papers
report (mm, deg, cm, km/s^3) at the edge, and :func:`compute_all` / :func:`format_table` build a
report.

Conventions (DESIGN.md): joint positions ``(..., J, 3)`` in metres in the world frame (Y up);
rotations are matrices ``(..., 3, 3)``; *local* joint rotations ``(..., 24, 3, 3)`` are SMPL's
(each joint relative to its parent, joint 0 = root relative to the world); a *global* rotation
maps the joint frame to the world. Sequences put time just before the joint axis:
``(..., T, J, 3)``.

Which rotations the angular metrics compare
-------------------------------------------
DIP, SIP, EM-POSE, TransPose and PIP all evaluate rotations *in the global space with the root
orientation removed*: the local pose is run through forward kinematics with the root rotation
set to identity, giving for joint ``j`` the root-relative global rotation
``R_0^T G_j`` (``G_j`` = global rotation of joint j, ``R_0`` = root rotation). The angular error
of a joint is the geodesic angle between predicted and ground-truth root-relative global
rotations, ``angle(R_pred^T R_gt)`` in ``[0, pi]``. Because these are *global* rotations, an
error at a joint propagates to all its descendants (a wrong shoulder also makes the elbow
wrong), exactly as in the reference implementations. :func:`joint_angle_errors` can also compare
true global rotations (root included) or local rotations, for other uses.

Reference implementations followed where the papers are terse: DIP's ``MetricsEngine`` (used by
EM-POSE) and TransPose/PIP's ``articulate.evaluator.FullMotionEvaluator``; the latter sets the
local rotation of the ignored joints *including the root* to identity in prediction and ground
truth before forward kinematics, which is why "global" SIP/angular/positional/mesh errors in
PIP are root-aligned. See :func:`mask_joint_rotations` to reproduce that masking.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any, NamedTuple

import torch

from wearpose.body.kinematics import forward_kinematics
from wearpose.body.shapes import standing_height, zero_pose_vertices
from wearpose.body.skeleton import IGNORED_JOINTS, MAJOR_JOINTS, NUM_JOINTS, PARENTS, SIP_JOINTS
from wearpose.errors import ShapeError
from wearpose.geometry import geodesic_angle, project_to_so3
from wearpose.geometry.units import M_TO_CM, M_TO_MM, RAD_TO_DEG

__all__ = [
    "ALL_JOINTS", "BIRAE_JOINT_GROUPS", "METRIC_UNITS", "TranslationErrorCurve",
    "root_relative_global_rotations", "mask_joint_rotations", "joint_angle_errors",
    "joint_position_errors", "JointErrorSplit", "joint_error_split", "pool_joint_error_splits",
    "mpjpe", "pa_mpjpe", "procrustes_align", "mpjae", "mpjae_groups",
    "sip_error", "global_angular_error", "positional_error", "mesh_error", "jerk", "jitter",
    "cumulative_translation_error", "stance_foot_speed", "StanceSpeed", "shape_errors", "ShapeErrors", "to_report_units", "compute_all",
    "format_table",
]

#: All 24 SMPL joints.
ALL_JOINTS: tuple[int, ...] = tuple(range(NUM_JOINTS))

#: BiRAE (Butt et al., IEEE Access, Sec. V-A/B, footnote § of Tables 1-4) reports MPJAE per
#: joint group over the 15 major joints: "Distal joints are left/right shoulder and hip joints.
#: Tracking joints are proximal to where sensors are located (Knee, Elbow, Head). Other include
#: all other major joints" (spine1-3, neck, collars). SMPL indices; the groups partition
#: :data:`MAJOR_JOINTS` and ``distal`` equals :data:`SIP_JOINTS`.
BIRAE_JOINT_GROUPS: dict[str, tuple[int, ...]] = {
    "distal": (1, 2, 16, 17),        # left_hip, right_hip, left_shoulder, right_shoulder
    "tracking": (4, 5, 15, 18, 19),  # left_knee, right_knee, head, left_elbow, right_elbow
    "other": (3, 6, 9, 12, 13, 14),  # spine1, spine2, spine3, neck, left_collar, right_collar
}
assert sorted(sum(BIRAE_JOINT_GROUPS.values(), ())) == sorted(MAJOR_JOINTS)

_M_TO_KM = 1.0 / 1000.0  # geometry.units has no km constant; jerk is reported in km/s^3.

#: Report unit of each metric computed by :func:`compute_all`: base name -> (SI unit, report
#: unit, factor SI -> report). :func:`to_report_units` renames ``name`` to ``name_<unit>``.
METRIC_UNITS: dict[str, tuple[str, str, float]] = {
    "mpjpe": ("m", "mm", M_TO_MM),
    "mpjpe_major": ("m", "mm", M_TO_MM),
    "pa_mpjpe": ("m", "mm", M_TO_MM),
    "pa_mpjpe_major": ("m", "mm", M_TO_MM),
    "mpjae": ("rad", "deg", RAD_TO_DEG),
    "mpjae_all": ("rad", "deg", RAD_TO_DEG),
    "mpjae_distal": ("rad", "deg", RAD_TO_DEG),
    "mpjae_tracking": ("rad", "deg", RAD_TO_DEG),
    "mpjae_other": ("rad", "deg", RAD_TO_DEG),
    "sip_error": ("rad", "deg", RAD_TO_DEG),
    "angular_error": ("rad", "deg", RAD_TO_DEG),
    "positional_error": ("m", "cm", M_TO_CM),
    "mesh_error": ("m", "cm", M_TO_CM),
    "jitter_abs": ("m/s^3", "km/s^3", _M_TO_KM),
    "jitter_rel": ("m/s^3", "km/s^3", _M_TO_KM),
    "translation_error": ("m", "cm", M_TO_CM),
    "translation_drift": ("ratio", "%", 100.0),
}

#: Suffix used in result keys for each report unit (``mpjpe_mm``, ``jitter_abs_km_s3``).
_UNIT_SUFFIX = {"mm": "mm", "cm": "cm", "deg": "deg", "km/s^3": "km_s3", "%": "pct", "m": "m",
                "rad": "rad", "m/s^3": "m_s3", "ratio": "ratio"}

_PRETTY = {
    "mpjpe": "MPJPE", "mpjpe_major": "MPJPE (15)", "pa_mpjpe": "PA-MPJPE",
    "pa_mpjpe_major": "PA-MPJPE (15)", "mpjae": "MPJAE (15)", "mpjae_all": "MPJAE (24)",
    "mpjae_distal": "MPJAE distal", "mpjae_tracking": "MPJAE tracking", "mpjae_other": "MPJAE other",
    "sip_error": "SIP err", "angular_error": "Ang err", "positional_error": "Pos err",
    "mesh_error": "Mesh err", "jitter_abs": "Abs jitter", "jitter_rel": "Rel jitter",
    "translation_error": "Transl err", "translation_drift": "Transl drift",
}


# --------------------------------------------------------------------------------------------
# input checks
# --------------------------------------------------------------------------------------------

def _check_tensor(x: Any, name: str) -> torch.Tensor:
    if not isinstance(x, torch.Tensor):
        raise ShapeError(f"{name}: expected a torch.Tensor, got {type(x).__name__}")
    if not x.is_floating_point():
        raise ShapeError(f"{name}: expected a floating-point tensor (float32/float64), got {x.dtype}")
    return x


def _check_last(x: Any, tail: tuple[int, ...], name: str, form: str) -> torch.Tensor:
    x = _check_tensor(x, name)
    if x.dim() < len(tail) or tuple(x.shape[x.dim() - len(tail):]) != tail:
        raise ShapeError(f"{name}: expected shape {form}, got {tuple(x.shape)}")
    return x


def _check_points(x: Any, name: str) -> torch.Tensor:
    """``(..., N, 3)`` with at least one point."""
    x = _check_tensor(x, name)
    if x.dim() < 2 or x.shape[-1] != 3:
        raise ShapeError(f"{name}: expected shape (..., N, 3) (points in metres), got {tuple(x.shape)}")
    return x


def _check_same_shape(a: torch.Tensor, b: torch.Tensor, na: str, nb: str) -> None:
    if a.shape != b.shape:
        raise ShapeError(f"{na} and {nb}: expected identical shapes, got {tuple(a.shape)} and {tuple(b.shape)}")


def _check_local_rot(x: Any, name: str, parents: Sequence[int]) -> torch.Tensor:
    J = len(parents)
    x = _check_last(x, (3, 3), name, f"(..., {J}, 3, 3)")
    if x.dim() < 3 or x.shape[-3] != J:
        raise ShapeError(f"{name}: expected shape (..., {J}, 3, 3) (local joint rotations, one per joint "
                         f"of the {J}-joint tree), got {tuple(x.shape)}")
    return x


def _joint_index(joints: Sequence[int] | None, J: int, name: str = "joints") -> list[int] | None:
    if joints is None:
        return None
    idx = [int(j) for j in joints]
    if not idx:
        raise ShapeError(f"{name}: expected a non-empty joint selection")
    bad = [j for j in idx if not -J <= j < J]
    if bad:
        raise ShapeError(f"{name}: joint indices {bad} out of range for {J} joints")
    return [j % J for j in idx]


def _select(x: torch.Tensor, idx: list[int] | None, dim: int) -> torch.Tensor:
    if idx is None:
        return x
    return x.index_select(dim, torch.as_tensor(idx, device=x.device, dtype=torch.long))


# --------------------------------------------------------------------------------------------
# building blocks
# --------------------------------------------------------------------------------------------

def root_relative_global_rotations(local_rot: torch.Tensor, parents: Sequence[int] = PARENTS) -> torch.Tensor:
    """Global joint rotations with the root orientation removed, ``R_0^T G_j``.

    Forward kinematics (rotations only) of the local pose with the root rotation replaced by the
    identity, as DIP/SIP/EM-POSE/TransPose/PIP do before measuring angular errors.

    Args:
        local_rot: ``(..., J, 3, 3)`` local joint rotations (joint -> parent; root -> world).
        parents: parent per joint (default SMPL's 24-joint tree).

    Returns:
        ``(..., J, 3, 3)``: rotation of each joint's frame relative to the root frame (joint 0 is
        the identity).
    """
    local_rot = _check_local_rot(local_rot, "local_rot", parents)
    eye = torch.eye(3, dtype=local_rot.dtype, device=local_rot.device).expand_as(local_rot[..., :1, :, :])
    rel = torch.cat([eye, local_rot[..., 1:, :, :]], dim=-3)
    rest = torch.zeros(len(parents), 3, dtype=local_rot.dtype, device=local_rot.device)
    g_rot, _ = forward_kinematics(rel, rest, parents)
    return g_rot


def _global_rotations(local_rot: torch.Tensor, parents: Sequence[int]) -> torch.Tensor:
    local_rot = _check_local_rot(local_rot, "local_rot", parents)
    rest = torch.zeros(len(parents), 3, dtype=local_rot.dtype, device=local_rot.device)
    return forward_kinematics(local_rot, rest, parents)[0]


def mask_joint_rotations(local_rot: torch.Tensor, joints: Sequence[int] = IGNORED_JOINTS[1:]) -> torch.Tensor:
    """Set the local rotation of ``joints`` to the identity (out of place).

    TransPose/PIP evaluate after doing this to prediction *and* ground truth for the joints the
    sensors cannot observe (ankles, feet, wrists, hands; the root is handled by root alignment),
    since the networks do not predict them. Apply it to both inputs, then compute joints /
    vertices / rotation metrics from the masked poses, to reproduce their protocol.

    Args:
        local_rot: ``(..., J, 3, 3)``.
        joints: indices to reset (default: :data:`IGNORED_JOINTS` without the root).

    Returns:
        ``(..., J, 3, 3)`` copy with those joints' rotations replaced by the identity.
    """
    local_rot = _check_last(local_rot, (3, 3), "local_rot", "(..., J, 3, 3)")
    if local_rot.dim() < 3:
        raise ShapeError(f"local_rot: expected shape (..., J, 3, 3), got {tuple(local_rot.shape)}")
    idx = _joint_index(joints, local_rot.shape[-3])
    mask = torch.zeros(local_rot.shape[-3], dtype=torch.bool, device=local_rot.device)
    mask[idx] = True
    eye = torch.eye(3, dtype=local_rot.dtype, device=local_rot.device)
    return torch.where(mask[:, None, None], eye, local_rot)


def joint_angle_errors(
    pred_local_rot: torch.Tensor,
    gt_local_rot: torch.Tensor,
    frame: str = "root_relative",
    parents: Sequence[int] = PARENTS,
) -> torch.Tensor:
    """Per-joint geodesic angle between predicted and ground-truth joint rotations.

    Args:
        pred_local_rot, gt_local_rot: ``(..., J, 3, 3)`` local joint rotations (SMPL convention).
        frame: which rotations are compared:
            ``"root_relative"`` (default; DIP/SIP/EM-POSE MPJAE, PIP SIP/angular error):
            global rotations with the root orientation removed, ``R_0^T G_j``;
            ``"global"``: true global rotations ``G_j`` (root orientation included);
            ``"local"``: the local rotations themselves (no propagation along the chain).
        parents: parent per joint.

    Returns:
        ``(..., J)`` angles in radians, in ``[0, pi]``.
    """
    _check_local_rot(pred_local_rot, "pred_local_rot", parents)
    _check_local_rot(gt_local_rot, "gt_local_rot", parents)
    _check_same_shape(pred_local_rot, gt_local_rot, "pred_local_rot", "gt_local_rot")
    if frame == "root_relative":
        rp = root_relative_global_rotations(pred_local_rot, parents)
        rg = root_relative_global_rotations(gt_local_rot, parents)
    elif frame == "global":
        rp = _global_rotations(pred_local_rot, parents)
        rg = _global_rotations(gt_local_rot, parents)
    elif frame == "local":
        rp, rg = pred_local_rot, gt_local_rot
    else:
        raise ShapeError(f"frame: expected 'root_relative', 'global' or 'local', got {frame!r}")
    return geodesic_angle(rp, rg)


def _root_frame(points: torch.Tensor, root_pos: torch.Tensor, root_rot: torch.Tensor | None) -> torch.Tensor:
    """``R_root^T (p - p_root)`` for ``points (..., N, 3)``, ``root_pos (..., 3)``, ``root_rot (..., 3, 3)``."""
    p = points - root_pos.unsqueeze(-2)
    if root_rot is None:
        return p
    return p @ root_rot  # row vectors: (R^T p)^T = p^T R


def joint_position_errors(
    pred_joints: torch.Tensor,
    gt_joints: torch.Tensor,
    root_align: bool = True,
    pred_root_rot: torch.Tensor | None = None,
    gt_root_rot: torch.Tensor | None = None,
    root_index: int = 0,
) -> torch.Tensor:
    """Per-joint Euclidean distance after optional root alignment.

    Args:
        pred_joints, gt_joints: ``(..., J, 3)`` joint positions, metres, world frame.
        root_align: subtract each skeleton's own root joint (``root_index``, the pelvis).
        pred_root_rot, gt_root_rot: optional ``(..., 3, 3)`` root orientations (root frame ->
            world). If both are given (and ``root_align``), positions are also expressed in each
            skeleton's root frame, i.e. the root orientation is aligned too.
        root_index: index of the root joint.

    Returns:
        ``(..., J)`` distances in metres.
    """
    _check_points(pred_joints, "pred_joints")
    _check_points(gt_joints, "gt_joints")
    _check_same_shape(pred_joints, gt_joints, "pred_joints", "gt_joints")
    if (pred_root_rot is None) != (gt_root_rot is None):
        raise ShapeError("pred_root_rot and gt_root_rot: give both or neither")
    if pred_root_rot is not None:
        form = f"{tuple(pred_joints.shape[:-2]) + (3, 3)}"
        for r, n in ((pred_root_rot, "pred_root_rot"), (gt_root_rot, "gt_root_rot")):
            _check_last(r, (3, 3), n, form)
            if r.shape[:-2] != pred_joints.shape[:-2]:
                raise ShapeError(f"{n}: expected shape {form} (one root rotation per frame), got {tuple(r.shape)}")
    J = pred_joints.shape[-2]
    if not -J <= root_index < J:
        raise ShapeError(f"root_index: {root_index} out of range for {J} joints")
    if root_align:
        p = _root_frame(pred_joints, pred_joints[..., root_index, :], pred_root_rot)
        g = _root_frame(gt_joints, gt_joints[..., root_index, :], gt_root_rot)
    else:
        p, g = pred_joints, gt_joints
    return (p - g).norm(dim=-1)


class JointErrorSplit(NamedTuple):
    """:func:`joint_error_split`: one clip's root-relative joint position error, split into the part
    every frame shares and the part that varies (each ``(J,)``, metres;
    ``rms**2 == bias**2 + varying**2`` per joint)."""

    mean: torch.Tensor  #: ``mean_t |e_tj|``: the joint's MPJPE over the clip
    rms: torch.Tensor  #: ``sqrt(mean_t |e_tj|^2)``
    bias: torch.Tensor  #: ``|mean_t e_tj|``: a constant offset (a skeleton, calibration or prior bias)
    varying: torch.Tensor  #: ``sqrt(mean_t |e_tj - mean_t e_tj|^2)``: what moves with the motion
    frames: int  #: ``T``, the weight of this clip in :func:`pool_joint_error_splits`


def joint_error_split(pred_joints: torch.Tensor, gt_joints: torch.Tensor, gt_root_rot: torch.Tensor | None = None,
                      root_index: int = 0) -> JointErrorSplit:
    """Split one clip's joint position error into its constant part and the rest.

    The error vector of joint ``j`` in frame ``t`` is MPJPE's, root-aligned:
    ``e_tj = (p_tj - p_t,root) - (g_tj - g_t,root)``; with ``gt_root_rot`` it is expressed in the
    true root's frame (``R_root^T e``; the norms do not change, only the frame in which an offset
    counts as constant: a skeleton or sensor-calibration offset is constant in the body, not in the
    world). A large ``bias`` says the estimate puts a joint in a consistently wrong place for this
    clip (another capture chain's skeleton, a calibration error, a prior that never saw such a
    body), a large ``varying`` that it follows the motion badly.

    Args:
        pred_joints, gt_joints: ``(T, J, 3)`` joint positions of one clip, metres (``T >= 1``).
        gt_root_rot: optional ``(T, 3, 3)`` true root orientations (root frame -> the joints' frame).
        root_index: index of the root joint (SMPL pelvis = 0).

    Returns:
        :class:`JointErrorSplit`, ``(J,)`` tensors in metres.
    """
    _check_points(pred_joints, "pred_joints")
    _check_points(gt_joints, "gt_joints")
    _check_same_shape(pred_joints, gt_joints, "pred_joints", "gt_joints")
    if pred_joints.dim() != 3 or pred_joints.shape[0] < 1:
        raise ShapeError(f"joint_error_split: expected one clip's joints (T, J, 3) with T >= 1, "
                         f"got {tuple(pred_joints.shape)}")
    T, J = pred_joints.shape[:2]
    if not -J <= root_index < J:
        raise ShapeError(f"root_index: {root_index} out of range for {J} joints")
    e = (pred_joints - pred_joints[:, root_index:root_index + 1]) - (gt_joints - gt_joints[:, root_index:root_index + 1])
    if gt_root_rot is not None:
        _check_last(gt_root_rot, (3, 3), "gt_root_rot", f"({T}, 3, 3)")
        if gt_root_rot.shape[:-2] != (T,):
            raise ShapeError(f"gt_root_rot: expected shape ({T}, 3, 3) (one root rotation per frame), "
                             f"got {tuple(gt_root_rot.shape)}")
        e = e @ gt_root_rot  # row vectors: (R^T e)^T = e^T R
    offset = e.mean(0)
    rms = e.square().sum(-1).mean(0).sqrt()
    varying = (e - offset).square().sum(-1).mean(0).sqrt()
    return JointErrorSplit(e.norm(dim=-1).mean(0), rms, offset.norm(dim=-1), varying, int(T))


def pool_joint_error_splits(splits: Sequence[JointErrorSplit]) -> JointErrorSplit:
    """Several clips' :class:`JointErrorSplit` as one, each weighted by its frames: the means are
    averaged, and so are the mean squares, so ``rms**2 == bias**2 + varying**2`` still holds (``bias`` is then the
    frame-weighted RMS over clips of each clip's constant offset, not one offset shared by all).

    Raises:
        ShapeError: no splits, or splits over different joint counts.
    """
    if not splits:
        raise ShapeError("pool_joint_error_splits: no clips to pool")
    if len({s.rms.shape for s in splits}) != 1:
        shapes = sorted({tuple(s.rms.shape) for s in splits})
        raise ShapeError(f"pool_joint_error_splits: splits over different joints: {shapes}")
    n = sum(s.frames for s in splits)

    def pooled(field: str) -> torch.Tensor:
        return (sum(getattr(s, field).square() * s.frames for s in splits) / max(n, 1)).sqrt()
    mean = sum(s.mean * s.frames for s in splits) / max(n, 1)
    return JointErrorSplit(mean, pooled("rms"), pooled("bias"), pooled("varying"), n)


# --------------------------------------------------------------------------------------------
# positional metrics
# --------------------------------------------------------------------------------------------

def mpjpe(
    pred_joints: torch.Tensor,
    gt_joints: torch.Tensor,
    joints: Sequence[int] | None = None,
    root_align: bool = True,
    root_index: int = 0,
) -> torch.Tensor:
    """Mean per-joint position error (MPJPE) per frame.

    Definition (EM-POSE, Kaufmann et al. ICCV 2021, Sec. 6.2; as in DIP/SIP): mean over the
    selected joints of the Euclidean distance between predicted and ground-truth 3D joint
    positions, after subtracting each skeleton's root (pelvis) position ("root-relative").

    Args:
        pred_joints, gt_joints: ``(..., J, 3)`` joint positions, metres, world frame.
        joints: joint indices to average over (default all ``J``; :data:`MAJOR_JOINTS` for the
            DIP/EM-POSE 15-joint variant). With root alignment the root itself has error 0 and,
            if included, counts in the mean (as in TransPose/PIP's evaluator).
        root_align: subtract the root joint (default True); False gives the absolute error.
        root_index: index of the root joint (SMPL pelvis = 0).

    Returns:
        ``(...)`` per-frame error in metres.
    """
    err = joint_position_errors(pred_joints, gt_joints, root_align=root_align, root_index=root_index)
    return _select(err, _joint_index(joints, err.shape[-1]), -1).mean(-1)


def procrustes_align(source: torch.Tensor, target: torch.Tensor, scale: bool = True) -> torch.Tensor:
    """Similarity transform (``s R x + t``) of ``source`` that best fits ``target`` (least squares).

    Per leading index (i.e. per frame), Umeyama's closed form: with centred point sets ``X``,
    ``Y`` and ``M = Y^T X``, ``R = project_to_so3(M)`` (SVD, reflections excluded),
    ``s = tr(R^T M) / ||X||_F^2``, ``t = mean(Y) - s R mean(X)``.

    Args:
        source, target: ``(..., N, 3)`` corresponding points.
        scale: estimate the scale (similarity); False gives a rigid fit.

    Returns:
        ``(..., N, 3)`` aligned source points.
    """
    _check_points(source, "source")
    _check_points(target, "target")
    _check_same_shape(source, target, "source", "target")
    mu_x = source.mean(-2, keepdim=True)
    mu_y = target.mean(-2, keepdim=True)
    X = source - mu_x
    Y = target - mu_y
    M = Y.transpose(-1, -2) @ X  # (..., 3, 3), sum_i y_i x_i^T
    R = project_to_so3(M)
    if scale:
        num = (R * M).sum((-1, -2))  # tr(R^T M)
        den = (X * X).sum((-1, -2)).clamp_min(torch.finfo(X.dtype).tiny)
        s = (num / den)[..., None, None]
    else:
        s = 1.0
    return s * (X @ R.transpose(-1, -2)) + mu_y


def pa_mpjpe(
    pred_joints: torch.Tensor,
    gt_joints: torch.Tensor,
    joints: Sequence[int] | None = None,
    scale: bool = True,
) -> torch.Tensor:
    """Procrustes-aligned MPJPE (PA-MPJPE) per frame.

    Definition (EM-POSE Sec. 6.2, "MPJPE with Procrustes alignment", as in DIP/SIP and HMR):
    per frame, the prediction of the selected joints is aligned to the ground truth by the
    least-squares similarity transform (rotation, translation and uniform scale), then MPJPE is
    taken. The alignment is fitted on the same joints that are evaluated.

    Args:
        pred_joints, gt_joints: ``(..., J, 3)`` joint positions, metres.
        joints: joint subset (default all; :data:`MAJOR_JOINTS` for the 15-joint variant).
        scale: include the scale in the alignment (default True, as the papers do).

    Returns:
        ``(...)`` per-frame error in metres. Gradients through the SVD are undefined for
        degenerate configurations (e.g. collinear joints); this is a metric, not a loss.
    """
    _check_points(pred_joints, "pred_joints")
    _check_points(gt_joints, "gt_joints")
    _check_same_shape(pred_joints, gt_joints, "pred_joints", "gt_joints")
    idx = _joint_index(joints, pred_joints.shape[-2])
    p = _select(pred_joints, idx, -2)
    g = _select(gt_joints, idx, -2)
    return (procrustes_align(p, g, scale=scale) - g).norm(dim=-1).mean(-1)


def positional_error(
    pred_joints: torch.Tensor,
    gt_joints: torch.Tensor,
    pred_root_rot: torch.Tensor | None,
    gt_root_rot: torch.Tensor | None,
    joints: Sequence[int] | None = None,
    root_index: int = 0,
) -> torch.Tensor:
    """PIP "Positional Error" per frame.

    Definition (PIP, Yi et al. CVPR 2022, Appendix B): "the mean position error of all body
    joints in the global space with the root position and orientation aligned". Each skeleton is
    expressed in its own root frame, ``R_0^T (p_j - p_0)``, before the distance; equivalently
    TransPose/PIP run FK with the root rotation set to identity and subtract the root position.

    Args:
        pred_joints, gt_joints: ``(..., J, 3)`` metres, world frame.
        pred_root_rot, gt_root_rot: ``(..., 3, 3)`` root (pelvis) orientations, root -> world.
            ``None`` for both aligns the root position only (then equals :func:`mpjpe`).
        joints: joint subset (default all joints, as PIP).
        root_index: root joint index.

    Returns:
        ``(...)`` per-frame error in metres (PIP reports cm).
    """
    err = joint_position_errors(pred_joints, gt_joints, True, pred_root_rot, gt_root_rot, root_index)
    return _select(err, _joint_index(joints, err.shape[-1]), -1).mean(-1)


def mesh_error(
    pred_vertices: torch.Tensor,
    gt_vertices: torch.Tensor,
    pred_root_pos: torch.Tensor,
    gt_root_pos: torch.Tensor,
    pred_root_rot: torch.Tensor | None = None,
    gt_root_rot: torch.Tensor | None = None,
) -> torch.Tensor:
    """PIP/TransPose "Mesh Error" per frame.

    Definition (PIP Sec. 4, Metrics 2): "the mean vertex distance between the reconstructed and
    ground-truth meshes with both root position and orientation aligned". Vertices are expressed
    in each body's own root frame, ``R_0^T (v - p_0)``, then the mean Euclidean distance over
    vertices is taken. For SMPL skinning this equals evaluating both meshes with zero root
    rotation and the root joint at the origin, as the TransPose/PIP evaluator does.

    Args:
        pred_vertices, gt_vertices: ``(..., V, 3)`` metres, world frame, same topology.
        pred_root_pos, gt_root_pos: ``(..., 3)`` root *joint* (pelvis) positions, world frame.
        pred_root_rot, gt_root_rot: ``(..., 3, 3)`` root orientations (root -> world); ``None``
            for both aligns position only.

    Returns:
        ``(...)`` per-frame error in metres (PIP reports cm).
    """
    _check_points(pred_vertices, "pred_vertices")
    _check_points(gt_vertices, "gt_vertices")
    _check_same_shape(pred_vertices, gt_vertices, "pred_vertices", "gt_vertices")
    batch = tuple(pred_vertices.shape[:-2])
    for x, n in ((pred_root_pos, "pred_root_pos"), (gt_root_pos, "gt_root_pos")):
        _check_last(x, (3,), n, f"{batch + (3,)}")
        if tuple(x.shape[:-1]) != batch:
            raise ShapeError(f"{n}: expected shape {batch + (3,)} (one root position per frame), got {tuple(x.shape)}")
    if (pred_root_rot is None) != (gt_root_rot is None):
        raise ShapeError("pred_root_rot and gt_root_rot: give both or neither")
    if pred_root_rot is not None:
        for x, n in ((pred_root_rot, "pred_root_rot"), (gt_root_rot, "gt_root_rot")):
            _check_last(x, (3, 3), n, f"{batch + (3, 3)}")
            if tuple(x.shape[:-2]) != batch:
                raise ShapeError(f"{n}: expected shape {batch + (3, 3)}, got {tuple(x.shape)}")
    p = _root_frame(pred_vertices, pred_root_pos, pred_root_rot)
    g = _root_frame(gt_vertices, gt_root_pos, gt_root_rot)
    return (p - g).norm(dim=-1).mean(-1)


# --------------------------------------------------------------------------------------------
# angular metrics
# --------------------------------------------------------------------------------------------

def mpjae(
    pred_local_rot: torch.Tensor,
    gt_local_rot: torch.Tensor,
    joints: Sequence[int] | None = MAJOR_JOINTS,
    parents: Sequence[int] = PARENTS,
) -> torch.Tensor:
    """Mean per-joint angular error (MPJAE) per frame.

    Definition (EM-POSE Sec. 6.2: "mean per-joint angular error computed on root-relative
    orientations", on the 15 major joints as DIP/SIP): for each selected joint the geodesic
    angle between predicted and ground-truth *root-relative global* rotations ``R_0^T G_j``
    (forward kinematics of the local pose with the root set to identity), averaged over joints.
    A local error at a joint therefore also counts at its selected descendants.

    Args:
        pred_local_rot, gt_local_rot: ``(..., 24, 3, 3)`` SMPL local joint rotations.
        joints: joints averaged (default :data:`MAJOR_JOINTS`; ``None`` = all).
        parents: kinematic tree.

    Returns:
        ``(...)`` per-frame error in radians.
    """
    err = joint_angle_errors(pred_local_rot, gt_local_rot, "root_relative", parents)
    return _select(err, _joint_index(joints, err.shape[-1]), -1).mean(-1)


def mpjae_groups(
    pred_local_rot: torch.Tensor,
    gt_local_rot: torch.Tensor,
    groups: Mapping[str, Sequence[int]] = BIRAE_JOINT_GROUPS,
    parents: Sequence[int] = PARENTS,
) -> dict[str, torch.Tensor]:
    """MPJAE per joint group (BiRAE Tables 1-4: distal / tracking / other).

    BiRAE reports per-group mean per-joint angle error and compares to DIP's numbers, so the
    same root-relative global rotations as :func:`mpjae` are compared (BiRAE does not state the
    frame; DIP's MPJAE definition is used for comparability).

    Args:
        pred_local_rot, gt_local_rot: ``(..., 24, 3, 3)`` SMPL local joint rotations.
        groups: name -> joint indices (default :data:`BIRAE_JOINT_GROUPS`).

    Returns:
        name -> ``(...)`` per-frame error in radians.
    """
    err = joint_angle_errors(pred_local_rot, gt_local_rot, "root_relative", parents)
    return {k: _select(err, _joint_index(v, err.shape[-1], k), -1).mean(-1) for k, v in groups.items()}


def sip_error(
    pred_local_rot: torch.Tensor,
    gt_local_rot: torch.Tensor,
    parents: Sequence[int] = PARENTS,
) -> torch.Tensor:
    """SIP error per frame.

    Definition (PIP Sec. 4, Metrics 1; introduced by SIP, used by DIP/TransPose): "the mean
    orientation error of the upper arms and legs in the global space", i.e. the geodesic angle
    of the root-relative global rotations of hips and shoulders (:data:`SIP_JOINTS` = left/right
    hip, left/right shoulder), averaged over those 4 joints. Root-relative because the
    reference evaluators set the root rotation to identity before FK.

    Args:
        pred_local_rot, gt_local_rot: ``(..., 24, 3, 3)`` SMPL local joint rotations.

    Returns:
        ``(...)`` per-frame error in radians.
    """
    return mpjae(pred_local_rot, gt_local_rot, SIP_JOINTS, parents)


def global_angular_error(
    pred_local_rot: torch.Tensor,
    gt_local_rot: torch.Tensor,
    joints: Sequence[int] | None = None,
    root_aligned: bool = True,
    parents: Sequence[int] = PARENTS,
) -> torch.Tensor:
    """PIP "Angular Error" per frame.

    Definition (PIP Appendix B): "the mean rotation error of all body joints in the global
    space": geodesic angle between global joint rotations averaged over all 24 joints. As in
    the TransPose/PIP evaluator the root orientation is aligned (root set to identity), so the
    root contributes 0; ``root_aligned=False`` compares true global rotations (root included),
    for methods whose root orientation is itself an estimate worth scoring.

    Args:
        pred_local_rot, gt_local_rot: ``(..., 24, 3, 3)`` SMPL local joint rotations.
        joints: joints averaged (default all).
        root_aligned: remove the root orientation first (default True).

    Returns:
        ``(...)`` per-frame error in radians.
    """
    frame = "root_relative" if root_aligned else "global"
    err = joint_angle_errors(pred_local_rot, gt_local_rot, frame, parents)
    return _select(err, _joint_index(joints, err.shape[-1]), -1).mean(-1)


# --------------------------------------------------------------------------------------------
# smoothness
# --------------------------------------------------------------------------------------------

def jerk(joints: torch.Tensor, fps: float) -> torch.Tensor:
    """Per-joint jerk magnitude from third finite differences.

    ``j_t = || p_{t+3} - 3 p_{t+2} + 3 p_{t+1} - p_t || * fps^3`` (the TransPose/PIP evaluator's
    forward difference; exact for cubic trajectories).

    Args:
        joints: ``(..., T, J, 3)`` positions in metres, ``T >= 4``.
        fps: frame rate in Hz.

    Returns:
        ``(..., T - 3, J)`` jerk magnitudes in m/s^3.
    """
    _check_points(joints, "joints")
    if joints.dim() < 3:
        raise ShapeError(f"joints: expected shape (..., T, J, 3) (a time axis before joints), got {tuple(joints.shape)}")
    if joints.shape[-3] < 4:
        raise ShapeError(f"joints: jerk needs at least 4 frames on the time axis (dim -3), got {joints.shape[-3]}")
    if not (isinstance(fps, (int, float)) and math.isfinite(fps) and fps > 0):
        raise ShapeError(f"fps: expected a positive frame rate in Hz, got {fps!r}")
    p = joints
    d3 = p[..., 3:, :, :] - 3 * p[..., 2:-1, :, :] + 3 * p[..., 1:-2, :, :] - p[..., :-3, :, :]
    return d3.norm(dim=-1) * float(fps) ** 3


def jitter(
    joints: torch.Tensor,
    fps: float,
    root_relative: bool = False,
    root_rot: torch.Tensor | None = None,
    joint_subset: Sequence[int] | None = None,
    root_index: int = 0,
) -> torch.Tensor:
    """Jitter: mean jerk magnitude of the joints, per window of 4 frames.

    Definition (PIP Sec. 4, Metrics 3, after TransPose): "the mean jerk (time derivative of
    acceleration) of all body joints in the global space" — *absolute* jitter, on world joint
    positions (root translation and orientation included). PIP Appendix B's *relative* jitter is
    "calculated in the local (root-relative) frame, where the root translation is not
    considered": with ``root_relative=True`` the root joint is subtracted and, if ``root_rot`` is
    given, positions are expressed in the root frame ``R_0^T (p_j - p_0)`` (what the reference
    evaluator computes, since it runs FK with root rotation identity and no translation).

    Args:
        joints: ``(..., T, J, 3)`` joint positions, metres, world frame, ``T >= 4``.
        fps: frame rate, Hz.
        root_relative: relative jitter (see above).
        root_rot: ``(..., T, 3, 3)`` root orientations, used only if ``root_relative``.
        joint_subset: joints averaged (default all).
        root_index: root joint index.

    Returns:
        ``(..., T - 3)`` mean jerk over joints in m/s^3 (PIP reports km/s^3); average over time
        for the sequence value.
    """
    _check_points(joints, "joints")
    if root_relative:
        if root_rot is not None:
            _check_last(root_rot, (3, 3), "root_rot", "(..., T, 3, 3)")
            if root_rot.shape[:-2] != joints.shape[:-2]:
                raise ShapeError(f"root_rot: expected shape {tuple(joints.shape[:-2]) + (3, 3)}, got {tuple(root_rot.shape)}")
        J = joints.shape[-2]
        if not -J <= root_index < J:
            raise ShapeError(f"root_index: {root_index} out of range for {J} joints")
        joints = _root_frame(joints, joints[..., root_index, :], root_rot)
    j = jerk(joints, fps)
    return _select(j, _joint_index(joint_subset, j.shape[-1], "joint_subset"), -1).mean(-1)


# --------------------------------------------------------------------------------------------
# translation
# --------------------------------------------------------------------------------------------

class TranslationErrorCurve(NamedTuple):
    """Result of :func:`cumulative_translation_error` (all metres).

    Attributes:
        travelled: ``(..., T)`` ground-truth distance travelled since frame 0 (path length).
        error: ``(..., T)`` drift error ``||(p_t - p_0) - (g_t - g_0)||`` at each frame.
        thresholds: ``(K,)`` travelled distances at which the curve is sampled.
        error_at: ``(..., K)`` error at the first frame where ``travelled >= threshold``; NaN
            where the sequence never travels that far.
        mean_error: ``(...)`` error averaged over frames.
        final_error: ``(...)`` error at the last frame.
        drift: ``(...)`` ``final_error / travelled[..., -1]`` (dimensionless; NaN if the ground
            truth did not move).
    """

    travelled: torch.Tensor
    error: torch.Tensor
    thresholds: torch.Tensor
    error_at: torch.Tensor
    mean_error: torch.Tensor
    final_error: torch.Tensor
    drift: torch.Tensor


def cumulative_translation_error(
    pred_trans: torch.Tensor,
    gt_trans: torch.Tensor,
    thresholds: torch.Tensor | Sequence[float] | None = None,
) -> TranslationErrorCurve:
    """Translation error versus real travelled distance (PIP Fig. 3, TransPose Fig. 8 style).

    Definition (PIP Sec. 4: "cumulative translation error which means the global position error
    w.r.t. the real travelled distance"): both trajectories are anchored at their first frame
    (estimators start from the known initial position), the error at frame ``t`` is
    ``||(p_t - p_0) - (g_t - g_0)||`` and the abscissa is the ground-truth path length
    ``sum_k ||g_k - g_{k-1}||``. The curve is sampled at ``thresholds`` travelled metres (first
    frame reaching each) so that sequences can be averaged (``torch.nanmean`` over the batch).

    Args:
        pred_trans, gt_trans: ``(..., T, 3)`` root translations (or root joint positions),
            metres, world frame.
        thresholds: travelled distances in metres (default 0, 1, ..., 10 m).

    Returns:
        :class:`TranslationErrorCurve` (metres).
    """
    _check_points(pred_trans, "pred_trans")
    _check_points(gt_trans, "gt_trans")
    _check_same_shape(pred_trans, gt_trans, "pred_trans", "gt_trans")
    if thresholds is None:
        thresholds = torch.arange(11, dtype=pred_trans.dtype, device=pred_trans.device)
    thr = torch.as_tensor(thresholds, dtype=pred_trans.dtype, device=pred_trans.device).reshape(-1)
    step = (gt_trans[..., 1:, :] - gt_trans[..., :-1, :]).norm(dim=-1)
    travelled = torch.cat([torch.zeros_like(step[..., :1]), step.cumsum(-1)], dim=-1)
    error = ((pred_trans - pred_trans[..., :1, :]) - (gt_trans - gt_trans[..., :1, :])).norm(dim=-1)
    reached = travelled.unsqueeze(-1) >= thr  # (..., T, K)
    first = reached.to(torch.int32).argmax(dim=-2)  # first True (0 if none)
    got = torch.gather(error.unsqueeze(-1).expand(*error.shape, thr.numel()), -2, first.unsqueeze(-2)).squeeze(-2)
    error_at = torch.where(reached.any(dim=-2), got, torch.full_like(got, float("nan")))
    total = travelled[..., -1]
    final = error[..., -1]
    drift = torch.where(total > 0, final / total.clamp_min(torch.finfo(total.dtype).tiny),
                        torch.full_like(final, float("nan")))
    return TranslationErrorCurve(travelled, error, thr, error_at, error.mean(-1), final, drift)


class StanceSpeed(NamedTuple):
    """Result of :func:`stance_foot_speed` (m/s, m, frames)."""

    speeds: torch.Tensor  #: ``(N,)`` horizontal speed of the stance foot in each mid-stance frame, m/s
    foot: torch.Tensor  #: ``(N,)`` int64 foot index (into the ``F`` axis) of each entry
    frame: torch.Tensor  #: ``(N,)`` int64 frame of each entry
    stances: int  #: stance phases found (all feet)
    stance_travel: torch.Tensor  #: ``(stances,)`` horizontal distance each stance foot moves over its whole stance, m

    @property
    def median(self) -> float:
        """Median mid-stance speed, m/s (NaN when no stance was found)."""
        return float(self.speeds.median()) if self.speeds.numel() else float("nan")


def stance_foot_speed(feet: torch.Tensor, fps: float, height_tol: float = 0.05, min_stance_s: float = 0.2,
                      mid_fraction: float = 0.5, max_vertical_speed: float = 0.25) -> StanceSpeed:
    """Horizontal speed of planted feet in mid-stance: how much a motion's feet skate.

    Stance is found from heights only, so the measure does not assume the stillness it measures:
    a foot is down where its height is within ``height_tol`` of the clip's lowest foot point and
    it moves vertically slower than ``max_vertical_speed``; a stance is a run of such frames
    lasting at least ``min_stance_s``; mid-stance is the middle ``mid_fraction`` of each stance
    (leaving out touch-down and push-off, where a real foot rolls). Speed: central differences
    of the horizontal (x, z) position (Y up). A still planted foot gives 0.

    Args:
        feet: ``(T, F, 3)`` world positions of one point per foot (e.g. SMPL's ``left_foot``,
            ``right_foot`` toe joints, or a source skeleton's toe joints), metres, Y up.
        fps: frame rate, Hz.

    Returns:
        :class:`StanceSpeed`; ``.median`` is the clip's figure.
    """
    _check_points(feet, "feet")
    if feet.dim() != 3:
        raise ShapeError(f"feet: expected (T, F, 3) metres, got {tuple(feet.shape)}")
    if not (isinstance(fps, (int, float)) and math.isfinite(fps) and fps > 0):
        raise ShapeError(f"fps: expected a positive frame rate in Hz, got {fps!r}")
    p = feet.to(torch.float64)
    T = p.shape[0]
    if T < 3:
        empty = torch.zeros(0, dtype=torch.float64)
        return StanceSpeed(empty, empty.long(), empty.long(), 0, empty)
    vel = torch.gradient(p, spacing=1.0 / float(fps), dim=0)[0]
    hspeed = vel[..., [0, 2]].norm(dim=-1)  # (T, F)
    down = (p[..., 1] - p[..., 1].min() < height_tol) & (vel[..., 1].abs() < max_vertical_speed)
    min_len = max(2, int(math.ceil(min_stance_s * fps)))
    speeds, foot, frame, travel = [], [], [], []
    for f in range(p.shape[1]):
        d = down[:, f].to(torch.int8)
        edges = torch.diff(torch.cat([d.new_zeros(1), d, d.new_zeros(1)]))
        starts, ends = torch.nonzero(edges == 1).flatten(), torch.nonzero(edges == -1).flatten()
        for a, b in zip(starts.tolist(), ends.tolist()):
            if b - a < min_len:
                continue
            cut = int(round((b - a) * (1.0 - mid_fraction) / 2.0))
            idx = torch.arange(a + cut, b - cut)
            speeds.append(hspeed[idx, f])
            foot.append(torch.full((len(idx),), f, dtype=torch.int64))
            frame.append(idx)
            travel.append((p[b - 1, f, [0, 2]] - p[a, f, [0, 2]]).norm())
    if not speeds:
        empty = torch.zeros(0, dtype=torch.float64)
        return StanceSpeed(empty, empty.long(), empty.long(), 0, empty)
    return StanceSpeed(torch.cat(speeds), torch.cat(foot), torch.cat(frame), len(travel), torch.stack(travel))


class ShapeErrors(NamedTuple):
    """:func:`shape_errors`: an estimated body shape against the true one, at zero pose."""

    height_error: torch.Tensor  #: ``(...)`` m, ``|height(estimate) - height(truth)|``
    height_difference: torch.Tensor  #: ``(...)`` m, ``height(estimate) - height(truth)`` (signed: + too tall)
    zero_pose_vertex_error: torch.Tensor  #: ``(...)`` m, mean vertex distance at zero pose
    height_true: torch.Tensor  #: ``(...)`` m, the true body's standing height


def shape_errors(body: Any, betas_pred: torch.Tensor, betas_true: torch.Tensor) -> ShapeErrors:
    """How far an estimated body shape is from the true one (EM-POSE estimates it, Sec. 5.3).

    Both bodies at zero pose (T-pose) and zero translation on ``body``: the standing height
    difference (:func:`wearpose.body.shapes.standing_height`, crown to soles) and the mean
    distance between corresponding skin vertices (no alignment: at zero pose and zero
    translation a shape's skin sits where the model puts it, so a wrong shape's offset counts).

    Args:
        body: the :class:`wearpose.body.BodyModel` both shapes belong to.
        betas_pred, betas_true: ``(..., S)`` shape coefficients (broadcast).

    Returns:
        :class:`ShapeErrors`, each ``(...)`` in metres.
    """
    bp, bt = torch.broadcast_tensors(_check_tensor(betas_pred, "betas_pred"), _check_tensor(betas_true, "betas_true"))
    ht = standing_height(body, bt)
    dh = standing_height(body, bp) - ht
    dv = (zero_pose_vertices(body, bp) - zero_pose_vertices(body, bt)).norm(dim=-1).mean(-1)
    return ShapeErrors(dh.abs(), dh, dv, ht)


# --------------------------------------------------------------------------------------------
# reporting
# --------------------------------------------------------------------------------------------

def to_report_units(results_si: Mapping[str, Any]) -> dict[str, Any]:
    """Convert SI metric values to report units and tag the key with the unit.

    ``{"mpjpe": 0.05, "mpjae": 0.1}`` -> ``{"mpjpe_mm": 50.0, "mpjae_deg": 5.73}``. Known base
    names and their units are in :data:`METRIC_UNITS` (mm for MPJPE/PA-MPJPE, deg for angles,
    cm for PIP positional/mesh/translation errors, km/s^3 for jitter, % for drift). Values may be
    floats or tensors; unknown keys raise :class:`ShapeError`.
    """
    out: dict[str, Any] = {}
    for k, v in results_si.items():
        if k not in METRIC_UNITS:
            raise ShapeError(f"results_si[{k!r}]: unknown metric; expected one of {sorted(METRIC_UNITS)}")
        _, unit, factor = METRIC_UNITS[k]
        out[f"{k}_{_UNIT_SUFFIX[unit]}"] = v * factor
    return out


def _get(obj: Any, key: str) -> torch.Tensor | None:
    if obj is None:
        return None
    if isinstance(obj, Mapping):
        return obj.get(key)
    return getattr(obj, key, None)


def _masked_mean(x: torch.Tensor, valid: torch.Tensor | None) -> float:
    x = x.detach()
    if valid is None:
        return float(x.mean()) if x.numel() else float("nan")
    v = valid.to(device=x.device, dtype=torch.bool).expand_as(x)
    return float(x[v].mean()) if bool(v.any()) else float("nan")


def compute_all(
    pred: Any,
    gt: Any,
    fps: float | None = None,
    valid: torch.Tensor | None = None,
    mask_ignored: bool = False,
) -> dict[str, float]:
    """Every metric the available data allows, averaged over frames, in report units.

    ``pred`` and ``gt`` are mappings (or objects with attributes) holding any of:
    ``local_rot`` ``(..., T, 24, 3, 3)`` SMPL local rotations, ``joints`` ``(..., T, 24, 3)``
    world joint positions (m), ``vertices`` ``(..., T, V, 3)`` world vertices (m), ``trans``
    ``(..., T, 3)`` root translation (m). A metric is computed when both sides have what it
    needs:

    - joints: ``mpjpe_mm`` (24 joints, root-relative), ``mpjpe_major_mm`` (15), ``pa_mpjpe_mm``,
      ``pa_mpjpe_major_mm``; with ``fps`` and a time axis also ``jitter_abs_km_s3`` (prediction
      only, world positions) and ``jitter_rel_km_s3`` (root frame; root orientation from
      ``local_rot`` if present);
    - local_rot: ``mpjae_deg`` (15 major), ``mpjae_all_deg`` (24), BiRAE
      ``mpjae_{distal,tracking,other}_deg``, ``sip_error_deg``, ``angular_error_deg`` (PIP);
    - joints + local_rot: ``positional_error_cm`` (PIP, root position and orientation aligned);
    - vertices + joints (+ local_rot): ``mesh_error_cm``;
    - trans (with a time axis): ``translation_error_cm`` (mean drift error over frames) and
      ``translation_drift_pct`` (final error / travelled distance; NaN if no travel).

    Args:
        pred, gt: see above.
        fps: frame rate (Hz), needed for jitter.
        valid: optional boolean ``(..., T)`` frame mask; only valid frames are averaged (jitter:
            windows whose 4 frames are all valid). EM-POSE evaluates only frames where all
            sensors are valid.
        mask_ignored: set the local rotation of the non-root :data:`IGNORED_JOINTS` to identity
            in both before the rotation metrics (TransPose/PIP protocol). This affects only
            metrics computed here from ``local_rot``; joints/vertices must already come from
            masked poses if that protocol is wanted for them.

    Returns:
        ``{"<metric>_<unit>": float}`` means over all frames (and batch).
    """
    si: dict[str, float] = {}
    pr, gr = _get(pred, "local_rot"), _get(gt, "local_rot")
    pj, gj = _get(pred, "joints"), _get(gt, "joints")
    pv, gv = _get(pred, "vertices"), _get(gt, "vertices")
    pt, gt_tr = _get(pred, "trans"), _get(gt, "trans")
    have_rot = pr is not None and gr is not None
    have_j = pj is not None and gj is not None
    if valid is not None:
        valid = torch.as_tensor(valid, dtype=torch.bool)

    if have_rot:
        if mask_ignored:
            pr, gr = mask_joint_rotations(pr), mask_joint_rotations(gr)
        err = joint_angle_errors(pr, gr, "root_relative")
        si["mpjae"] = _masked_mean(_select(err, list(MAJOR_JOINTS), -1).mean(-1), valid)
        si["mpjae_all"] = _masked_mean(err.mean(-1), valid)
        for name, idx in BIRAE_JOINT_GROUPS.items():
            si[f"mpjae_{name}"] = _masked_mean(_select(err, list(idx), -1).mean(-1), valid)
        si["sip_error"] = _masked_mean(_select(err, list(SIP_JOINTS), -1).mean(-1), valid)
        si["angular_error"] = si["mpjae_all"]
    p_root = pr[..., 0, :, :] if have_rot else None
    g_root = gr[..., 0, :, :] if have_rot else None

    if have_j:
        si["mpjpe"] = _masked_mean(mpjpe(pj, gj), valid)
        si["mpjpe_major"] = _masked_mean(mpjpe(pj, gj, MAJOR_JOINTS), valid)
        si["pa_mpjpe"] = _masked_mean(pa_mpjpe(pj, gj), valid)
        si["pa_mpjpe_major"] = _masked_mean(pa_mpjpe(pj, gj, MAJOR_JOINTS), valid)
        if have_rot:
            si["positional_error"] = _masked_mean(positional_error(pj, gj, p_root, g_root), valid)
        if pv is not None and gv is not None:
            si["mesh_error"] = _masked_mean(
                mesh_error(pv, gv, pj[..., 0, :], gj[..., 0, :], p_root, g_root), valid)
        if fps is not None and pj.dim() >= 3 and pj.shape[-3] >= 4:
            wvalid = None
            if valid is not None:
                v = valid
                wvalid = v[..., 3:] & v[..., 2:-1] & v[..., 1:-2] & v[..., :-3]
            si["jitter_abs"] = _masked_mean(jitter(pj, fps), wvalid)
            si["jitter_rel"] = _masked_mean(jitter(pj, fps, root_relative=True, root_rot=p_root), wvalid)

    if pt is not None and gt_tr is not None and pt.dim() >= 2 and pt.shape[-2] >= 2:
        curve = cumulative_translation_error(pt, gt_tr)
        si["translation_error"] = float(curve.mean_error.detach().mean())
        si["translation_drift"] = float(torch.nanmean(curve.drift.detach())) if curve.drift.numel() else float("nan")
    return to_report_units(si)


def _header(key: str) -> str:
    for base, (_, unit, _) in METRIC_UNITS.items():
        if key == f"{base}_{_UNIT_SUFFIX[unit]}":
            return f"{_PRETTY.get(base, base)} [{unit}]"
    return key


def format_table(results: Mapping[str, Any], digits: int = 2) -> str:
    """Markdown table of :func:`compute_all` results.

    Args:
        results: either one result dict (``{"mpjpe_mm": 41.2, ...}``), giving a one-row table,
            or ``{row_name: result_dict}`` (e.g. one row per method or dataset); columns are the
            union of keys in first-seen order, missing cells shown as ``-``.
        digits: decimals shown.

    Returns:
        A GitHub-flavoured markdown table (string, trailing newline).
    """
    if results and all(isinstance(v, Mapping) for v in results.values()):
        rows = dict(results)
    else:
        rows = {"": results}
    cols: list[str] = []
    for r in rows.values():
        for k in r:
            if k not in cols:
                cols.append(k)

    def cell(v: Any) -> str:
        if v is None:
            return "-"
        if isinstance(v, torch.Tensor):
            v = float(v.detach().mean()) if v.numel() else float("nan")
        if isinstance(v, float) and math.isnan(v):
            return "nan"
        if isinstance(v, (int, float)):
            return f"{v:.{digits}f}"
        return str(v)

    lines = ["| | " + " | ".join(_header(c) for c in cols) + " |",
             "|---|" + "---:|" * len(cols)]
    for name, r in rows.items():
        lines.append(f"| {name} | " + " | ".join(cell(r.get(c)) for c in cols) + " |")
    return "\n".join(lines) + "\n"
