"""Reading our own SMPL-skeleton BVH exports (see :mod:`wearpose.export.bvh` for the format)
without retargeting: joint rotations are SMPL local rotations as written."""

from __future__ import annotations

from pathlib import Path

import torch

from wearpose.body.skeleton import JOINT_NAMES, PARENTS
from wearpose.errors import InputFileError
from wearpose.geometry.units import CM_TO_M
from wearpose.motion.bvh import BvhMotion, read_bvh
from wearpose.motion.sequence import MotionSequence


def is_smpl_bvh(motion: BvhMotion) -> bool:
    """True when the file's skeleton is exactly SMPL's 24 joints and tree (our own export)."""
    sk = motion.skeleton
    if sorted(sk.names) != sorted(JOINT_NAMES):
        return False
    idx = {n: i for i, n in enumerate(sk.names)}
    return all((sk.parents[idx[n]] == -1) if PARENTS[j] < 0 else sk.parents[idx[n]] == idx[JOINT_NAMES[PARENTS[j]]]
               for j, n in enumerate(JOINT_NAMES))


def read_smpl_bvh(path: str | Path | BvhMotion, rest_joints: torch.Tensor) -> MotionSequence:
    """Read a BVH written by :func:`wearpose.export.write_smpl_bvh` back into a :class:`MotionSequence`.

    BVH carries no body shape: betas come back as zeros (bone lengths in the file are ignored;
    rotations keep their meaning on any SMPL-format body).

    Args:
        path: the ``.bvh``.
        rest_joints: ``(24, 3)`` rest joints (m) of the body to play it on; the root channels
            give the pelvis position, so ``trans = root_cm / 100 - rest_joints[0]``.

    Raises:
        InputFileError: not an SMPL-skeleton BVH (use :func:`wearpose.motion.retarget_bvh` for
            other skeletons).
    """
    motion = path if isinstance(path, BvhMotion) else read_bvh(path)
    path = motion.path or path
    if not is_smpl_bvh(motion):
        raise InputFileError(path, "skeleton is not SMPL's 24-joint tree",
                             "a BVH written by wearpose export (joints named pelvis, left_hip, ...); "
                             "other skeletons go through wearpose.motion.retarget_bvh")
    idx = [motion.skeleton.names.index(n) for n in JOINT_NAMES]
    pose = motion.rotations[:, idx]  # (T, 24, 3, 3) local rotations, frames aligned at rest
    root = motion.translations[:, idx[0]] * CM_TO_M  # position channels replace the OFFSET
    trans = root - rest_joints.to(torch.float64).cpu()[0]
    return MotionSequence(pose.to(torch.float32), torch.zeros(10), trans.to(torch.float32), motion.fps,
                          {"source_file": str(path), "source_format": "bvh", "skeleton": "smpl"})
