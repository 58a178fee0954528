"""BVH export on SMPL's 24-joint skeleton, and its exact re-import.

Written file: joints named as SMPL's (``pelvis``, ``left_hip``, ...), OFFSETs from the body's
rest joints in **centimetres** (what Blender, MotionBuilder and most BVH tools assume), Y up,
facing +Z. Because SMPL joint frames are aligned with the body frame at zero pose, the BVH zero
pose is SMPL's T-pose and each joint's BVH rotation **is** its SMPL local rotation, written as
intrinsic ``Zrotation Xrotation Yrotation`` in degrees. The root carries ``Xposition Yposition
Zposition`` = world position of the pelvis joint (``rest_joints[0] + trans``), in cm, and has
OFFSET 0. Leaves (head, hands, feet) get an End Site 5 cm along their bone.

:func:`wearpose.motion.read_smpl_bvh` reads such a file back to a :class:`MotionSequence` without retargeting
(recognised by its joint names and tree), so our own exports round-trip exactly up to the
printed precision.

BVH has no metadata field (and comment lines break many parsers), so the file's frame and the
estimate's placement go into a sidecar ``<file>.json`` (:mod:`wearpose.export.meta`).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import torch

from wearpose.body.skeleton import JOINT_NAMES, NUM_JOINTS, PARENTS
from wearpose.export.meta import export_metadata, sidecar_path
from wearpose.fileio import atomic_write_text
from wearpose.geometry import matrix_to_euler
from wearpose.geometry.units import M_TO_CM, RAD_TO_DEG
from wearpose.motion.sequence import MotionSequence

_ORDER = "ZXY"
_ROT_CHANNELS = "Zrotation Xrotation Yrotation"
_END_SITE_CM = 5.0


def _children(j: int) -> list[int]:
    return [c for c in range(NUM_JOINTS) if PARENTS[c] == j]


def write_smpl_bvh(seq: MotionSequence, path: str | Path, rest_joints: torch.Tensor, decimals: int = 6) -> Path:
    """Write ``seq`` as a BVH on the SMPL skeleton (format in the module docstring).

    Args:
        seq: motion (pose ``(T, 24, 3, 3)``, trans ``(T, 3)`` m).
        path: output ``.bvh``.
        rest_joints: ``(24, 3)`` rest joints (m) of the body the motion belongs to; they give the
            OFFSETs (``BodyModel.rest_joints(seq.betas)``).
        decimals: digits after the decimal point for channel values.

    Returns:
        The BVH path; its metadata sidecar (:func:`~wearpose.export.meta.sidecar_path`) is
        written beside it.
    """
    rest = rest_joints.detach().to(torch.float64).cpu().numpy() * M_TO_CM
    lines = ["HIERARCHY"]

    def emit(j: int, depth: int) -> None:
        ind = "  " * depth
        p = PARENTS[j]
        off = rest[j] - rest[p] if p >= 0 else np.zeros(3)
        head = "ROOT" if p < 0 else "JOINT"
        lines.append(f"{ind}{head} {JOINT_NAMES[j]}")
        lines.append(f"{ind}{{")
        lines.append(f"{ind}  OFFSET {off[0]:.6f} {off[1]:.6f} {off[2]:.6f}")
        chans = f"6 Xposition Yposition Zposition {_ROT_CHANNELS}" if p < 0 else f"3 {_ROT_CHANNELS}"
        lines.append(f"{ind}  CHANNELS {chans}")
        kids = _children(j)
        for c in kids:
            emit(c, depth + 1)
        if not kids:
            bone = off / (np.linalg.norm(off) or 1.0)
            e = bone * _END_SITE_CM
            lines.append(f"{ind}  End Site")
            lines.append(f"{ind}  {{")
            lines.append(f"{ind}    OFFSET {e[0]:.6f} {e[1]:.6f} {e[2]:.6f}")
            lines.append(f"{ind}  }}")
        lines.append(f"{ind}}}")

    emit(0, 0)
    order = _dfs_order()
    pose = seq.pose.detach().to(torch.float64).cpu()
    euler = matrix_to_euler(pose[:, order], _ORDER).numpy() * RAD_TO_DEG  # (T, 24, 3)
    root = (seq.trans.detach().to(torch.float64).cpu().numpy() * M_TO_CM) + rest[0]  # (T, 3) cm
    values = np.concatenate([root, euler.reshape(euler.shape[0], -1)], axis=1)
    lines += ["MOTION", f"Frames: {seq.num_frames}", f"Frame Time: {1.0 / seq.fps:.9f}"]
    fmt = f"{{:.{decimals}f}}"
    lines += [" ".join(fmt.format(v) for v in row) for row in values]
    out = atomic_write_text(path, "\n".join(lines) + "\n")
    atomic_write_text(sidecar_path(out), json.dumps(export_metadata(seq, ".bvh"), indent=2) + "\n")
    return out


def _dfs_order() -> list[int]:
    """SMPL joint ids in the depth-first order the hierarchy is written (= BVH joint order)."""
    out: list[int] = []

    def visit(j: int) -> None:
        out.append(j)
        for c in _children(j):
            visit(c)

    visit(0)
    return out
