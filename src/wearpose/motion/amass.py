"""AMASS-format npz reader and writer (SMPL / SMPL-H axis-angle, Z-up world).

AMASS keys: ``poses`` ``(T, 156)`` (SMPL-H: 52 joints) or ``(T, 72)`` (SMPL: 24 joints)
axis-angle radians; ``trans`` ``(T, 3)`` metres; ``betas`` ``(>= 10,)``; ``mocap_framerate`` (or
``mocap_frame_rate``) Hz; ``gender``.

Conversions:

- Joints 0-21 are the same body joints in SMPL and SMPL-H. SMPL-H's joints 22-51 are fingers;
  SMPL's hand joints 22/23 have no SMPL-H counterpart, so reading SMPL-H sets them to the
  identity (and writing SMPL-H drops them, leaving the fingers at zero). A ``(T, 72)`` file keeps
  its hand joints.
- Only the first 10 betas are kept. For SMPL-H files these are SMPL-H shape coefficients, an
  approximation of SMPL's (the two models' shape spaces differ).
- AMASS's world is Z up; ours is Y up (:data:`wearpose.geometry.Z_UP_TO_Y_UP`, ``C``). SMPL
  rotates the body about the rest pelvis joint ``J0 = rest_joints(betas)[0]``, not about the
  origin, so with ``R0' = C R0`` the translation becomes ``t' = C (t + J0) - J0`` (then every
  joint/vertex ``x' = C x``). The writer applies the inverse, ``t = C^T (t' + J0) - J0``.
"""

from __future__ import annotations

import copy
import json
from pathlib import Path
from typing import Any

import numpy as np
import torch

from wearpose.errors import InputFileError, ShapeError
from wearpose.fileio import npz_problem
from wearpose.geometry import Z_UP_TO_Y_UP, axis_angle_to_matrix, matrix_to_axis_angle
from wearpose.motion.sequence import NUM_BETAS, MotionSequence
from wearpose.motion.template import default_rest_joints

#: npz key of an export's metadata (a JSON string; :mod:`wearpose.export.meta`).
METADATA_KEY = "wearpose_metadata"

_POSES_FORM = "(T, 156) SMPL-H or (T, 72) SMPL axis-angle, radians (at least 66 columns: 22 body joints)"


def _pelvis(rest_joints: torch.Tensor | None, betas: torch.Tensor) -> tuple[torch.Tensor, str]:
    if rest_joints is None:
        rest_joints, src = default_rest_joints(betas)
    else:
        src = "argument"
    rj = torch.as_tensor(rest_joints, dtype=torch.float64)
    if rj.shape == (3,):
        return rj, src
    if rj.dim() != 2 or rj.shape[1] != 3:
        raise ShapeError(f"rest_joints: expected (24, 3) or the pelvis (3,), metres; got {tuple(rj.shape)}")
    return rj[0], src


#: Largest plausible |trans| (m) and joint axis-angle (rad) in an AMASS file: beyond these the
#: file is almost surely in centimetres/millimetres or degrees (checked on read).
MAX_TRANS_M = 50.0
MAX_AXIS_ANGLE_RAD = 4 * np.pi


def read_amass(path: str | Path, rest_joints: torch.Tensor | None = None) -> MotionSequence:
    """Read an AMASS npz into a Y-up :class:`MotionSequence`.

    Args:
        path: the ``.npz`` file.
        rest_joints: ``(24, 3)`` SMPL rest joints for the file's betas (or the rest pelvis
            ``(3,)``), metres, in the body's own Y-up frame. Default: from the body model
            (:func:`wearpose.motion.template.default_rest_joints`).

    Returns:
        Sequence with ``pose`` ``(T, 24, 3, 3)``, ``trans`` ``(T, 3)`` metres (Y up), ``betas``
        the first 10 of the file's, ``fps`` the file's frame rate, ``meta`` (gender, source).

    Raises:
        InputFileError: missing/unreadable file, missing key, wrong shape (naming the key).
    """
    path = Path(path)
    if not path.is_file():
        raise InputFileError(path, "file not found", "an AMASS .npz with poses, trans, betas, mocap_framerate")
    try:
        with np.load(path, allow_pickle=False) as data:
            d = {k: data[k] for k in data.files}
    except Exception as exc:  # noqa: BLE001 - zip/npy/pickle errors of any kind
        raise InputFileError(path, npz_problem(path, exc),
                             "an AMASS .npz with poses, trans, betas, mocap_framerate") from exc

    def need(key: str, expected: str) -> np.ndarray:
        if key not in d:
            raise InputFileError(path, "missing key", expected, field=key)
        return d[key]

    poses = need("poses", _POSES_FORM)
    if poses.ndim != 2 or poses.shape[1] < 66 or poses.shape[1] % 3 or not np.issubdtype(poses.dtype, np.number):
        raise InputFileError(path, f"shape {poses.shape} dtype {poses.dtype}", _POSES_FORM, field="poses")
    T = poses.shape[0]
    trans = need("trans", "(T, 3) metres, matching poses")
    if trans.shape != (T, 3):
        raise InputFileError(path, f"shape {trans.shape} for {T} frames of poses", "(T, 3) metres, matching poses", field="trans")
    betas = need("betas", f"(n,) with n >= {NUM_BETAS}")
    betas = np.asarray(betas).reshape(-1)
    if betas.shape[0] < NUM_BETAS:
        raise InputFileError(path, f"{betas.shape[0]} values", f"(n,) with n >= {NUM_BETAS}", field="betas")
    fps_key = "mocap_framerate" if "mocap_framerate" in d else "mocap_frame_rate"
    fps_arr = need(fps_key, "a positive frame rate in Hz (mocap_framerate or mocap_frame_rate)")
    try:
        fps = float(np.asarray(fps_arr).reshape(-1)[0])
    except (ValueError, IndexError):
        fps = float("nan")
    if not np.isfinite(fps) or fps <= 0:
        raise InputFileError(path, f"value {fps_arr!r}", "a positive frame rate in Hz", field=fps_key)
    for key, arr in (("poses", poses), ("trans", trans), ("betas", betas)):
        if not np.all(np.isfinite(arr)):
            raise InputFileError(path, "contains NaN or infinite values", "finite numbers", field=key)
    # Plausible units (a capture volume is metres, not kilometres; an axis-angle is at most a
    # few radians): the usual mistakes are centimetres/millimetres and degrees.
    reach = float(np.abs(trans).max()) if T else 0.0
    if reach > MAX_TRANS_M:
        unit = "millimetres" if reach > 100 * MAX_TRANS_M else "centimetres or millimetres"
        raise InputFileError(path, f"|trans| reaches {reach:.4g}, implausible in metres; looks like {unit}",
                             f"(T, 3) metres (|trans| <= {MAX_TRANS_M:g} m): convert before saving", field="trans")
    angle = float(np.linalg.norm(poses[:, :66].reshape(T, 22, 3), axis=-1).max()) if T else 0.0
    if angle > MAX_AXIS_ANGLE_RAD:
        raise InputFileError(path, f"a joint rotation of {angle:.4g} rad; looks like degrees",
                             "axis-angle in radians (each joint's |angle| <= pi, a few radians at most)",
                             field="poses")
    gender = str(np.asarray(d["gender"]).reshape(-1)[0]) if "gender" in d and np.asarray(d["gender"]).size else "unknown"
    if gender.startswith("b'"):
        gender = gender[2:-1]

    b = torch.from_numpy(betas[:NUM_BETAS].astype(np.float64))
    J0, rest_src = _pelvis(rest_joints, b)
    n_joints = 24 if poses.shape[1] == 72 else 22
    aa = torch.from_numpy(poses[:, : 3 * n_joints].astype(np.float64)).reshape(T, n_joints, 3)
    R = torch.eye(3, dtype=torch.float64).repeat(T, 24, 1, 1)
    R[:, :n_joints] = axis_angle_to_matrix(aa)
    C = Z_UP_TO_Y_UP.to(torch.float64)
    R[:, 0] = C @ R[:, 0]
    t = torch.from_numpy(trans.astype(np.float64))
    t_new = (t + J0) @ C.T - J0
    meta: dict[str, Any] = {"source_file": str(path), "source_format": "amass",
                            "skeleton": "smpl" if poses.shape[1] == 72 else "smplh", "gender": gender,
                            "rest_joints_source": rest_src, "num_source_betas": int(betas.shape[0])}
    return MotionSequence(R.to(torch.float32), b.to(torch.float32), t_new.to(torch.float32), fps, meta)


def save_amass(seq: MotionSequence, path: str | Path, rest_joints: torch.Tensor | None = None,
               layout: str = "smplh", gender: str | None = None, metadata: dict[str, Any] | None = None) -> Path:
    """Write ``seq`` as an AMASS-format npz (Z-up world), inverse of :func:`read_amass`.

    Args:
        seq: the motion (Y-up).
        path: output ``.npz``.
        rest_joints: ``(24, 3)`` rest joints for ``seq.betas`` (or the pelvis ``(3,)``), metres;
            default from the body model.
        layout: ``"smplh"`` -> ``poses`` ``(T, 156)``, body joints 0-21, fingers zero (SMPL's hand
            joints 22/23 are dropped); ``"smpl"`` -> ``(T, 72)`` with all 24 joints.
        gender: stored in ``gender`` (default ``seq.meta["gender"]`` or ``"neutral"``).
        metadata: stored as a JSON string under :data:`METADATA_KEY` when given (the file's
            frame and placement: :func:`wearpose.export.meta.export_metadata`).

    Returns:
        The path written. ``betas`` is padded with zeros to 16 for ``"smplh"``.
    """
    if layout not in ("smplh", "smpl"):
        raise ShapeError(f"save_amass: layout must be 'smplh' or 'smpl', got {layout!r}")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    J0, _ = _pelvis(rest_joints, seq.betas)
    C = Z_UP_TO_Y_UP.to(torch.float64)
    R = seq.pose.to(torch.float64).clone()
    R[:, 0] = C.T @ R[:, 0]
    aa = matrix_to_axis_angle(R)  # (T, 24, 3)
    T = seq.num_frames
    if layout == "smplh":
        poses = torch.zeros(T, 52, 3, dtype=torch.float64)
        poses[:, :22] = aa[:, :22]
        betas = torch.zeros(16, dtype=torch.float64)
        betas[:NUM_BETAS] = seq.betas.to(torch.float64)
    else:
        poses = aa
        betas = seq.betas.to(torch.float64)
    t = (seq.trans.to(torch.float64) + J0) @ C - J0  # C^T (t' + J0) - J0, row-vector form
    extra = {METADATA_KEY: np.array(json.dumps(metadata))} if metadata is not None else {}
    np.savez(path, poses=poses.reshape(T, -1).numpy(), trans=t.numpy(), betas=betas.numpy(),
             mocap_framerate=np.array(seq.fps, dtype=np.float64),
             gender=np.array(gender or copy.deepcopy(seq.meta).get("gender", "neutral")), **extra)
    return path
