"""Exports: BVH on the SMPL skeleton (re-imported exactly by ``wearpose.motion.read_smpl_bvh``), AMASS-style npz, glTF/GLB.

Public entry: :func:`export_motion` (by file extension) and the per-format writers.
"""

from __future__ import annotations

from pathlib import Path

import torch

from wearpose.errors import WearposeError
from wearpose.export.bvh import write_smpl_bvh
from wearpose.motion import MotionSequence, save_amass

__all__ = ["export_motion", "write_smpl_bvh"]


def export_motion(seq: MotionSequence, path: str | Path, rest_joints: torch.Tensor) -> Path:
    """Write ``seq`` to ``path`` in the format its extension names.

    ``.bvh``: SMPL-skeleton BVH (cm); ``.npz``: AMASS-style SMPL-H npz (Z-up world, as AMASS).

    Args:
        rest_joints: ``(24, 3)`` rest joints (m) of the body the motion belongs to.
    """
    path = Path(path)
    if path.suffix == ".bvh":
        return write_smpl_bvh(seq, path, rest_joints)
    if path.suffix == ".npz":
        save_amass(seq, path, rest_joints=rest_joints)
        return path
    raise WearposeError(f"{path}: unknown export format {path.suffix!r}; expected .bvh or .npz")
