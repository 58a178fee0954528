"""Exports: BVH on the SMPL skeleton (re-imported exactly by ``wearpose.motion.read_smpl_bvh``), AMASS-style npz, glTF/GLB.

Public entry: :func:`export_motion` (by file extension) and the per-format writers.
"""

from __future__ import annotations

from pathlib import Path

import torch

from wearpose.body import BodyModel
from wearpose.errors import WearposeError
from wearpose.export.bvh import write_smpl_bvh
from wearpose.export.gltf import write_glb
from wearpose.export.meta import export_metadata, read_export_metadata, sidecar_path
from wearpose.motion import MotionSequence, save_amass

__all__ = ["export_motion", "write_smpl_bvh", "write_glb", "export_metadata", "read_export_metadata", "sidecar_path"]


def export_motion(seq: MotionSequence, path: str | Path, body: BodyModel) -> Path:
    """Write ``seq`` to ``path`` in the format its extension names.

    ``.bvh``: SMPL-skeleton BVH (cm); ``.npz``: AMASS-style SMPL-H npz (Z-up world, as AMASS);
    ``.glb``: skinned mesh + skeletal animation (glTF 2.0 binary). Each states its frame and the
    estimate's placement (:mod:`wearpose.export.meta`: GLB ``asset.extras``, an npz key, a BVH
    sidecar ``<file>.json``).

    Args:
        body: the body model the motion plays on (rest skeleton for its betas; mesh for GLB).
    """
    path = Path(path)
    if path.suffix == ".glb":
        return write_glb(seq, path, body)
    rest_joints = body.rest_joints(seq.betas.to(body.dtype))
    if path.suffix == ".bvh":
        return write_smpl_bvh(seq, path, rest_joints)
    if path.suffix == ".npz":
        save_amass(seq, path, rest_joints=rest_joints, metadata=export_metadata(seq, ".npz"))
        return path
    raise WearposeError(f"{path}: unknown export format {path.suffix!r}; expected .bvh, .npz or .glb")
