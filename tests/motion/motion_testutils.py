"""Helpers for the motion tests: tiny BVH writers and synthetic SMPL-like motion."""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import torch

from wearpose.body.skeleton import JOINT_INDEX, JOINT_NAMES, PARENTS
from wearpose.geometry import axis_angle_to_matrix, matrix_to_euler, rotation_between
from wearpose.motion.retarget import SkeletonMap


def bvh_text(names: Sequence[str], parents: Sequence[int], offsets: np.ndarray, channels: Sequence[Sequence[str]],
             values: np.ndarray, frame_time: float = 1 / 30, end_sites: dict[int, Sequence[float]] | None = None,
             fmt: str = "%.9f") -> str:
    """BVH text for a joint tree (parents precede children) and per-frame channel values ``(T, C)``
    given joint by joint in index order (reordered here to the file's depth-first joint order)."""
    end_sites = end_sites or {}
    order: list[int] = []
    children: dict[int, list[int]] = {i: [] for i in range(len(names))}
    for i, p in enumerate(parents):
        if p >= 0:
            children[p].append(i)
    out = ["HIERARCHY"]

    def emit(j: int, depth: int) -> None:
        order.append(j)
        ind = "  " * depth
        out.append(f"{ind}{'ROOT' if parents[j] < 0 else 'JOINT'} {names[j]}")
        out.append(f"{ind}{{")
        out.append(f"{ind}  OFFSET {' '.join(fmt % v for v in offsets[j])}")
        out.append(f"{ind}  CHANNELS {len(channels[j])} {' '.join(channels[j])}".rstrip())
        for c in children[j]:
            emit(c, depth + 1)
        if j in end_sites:
            out.extend([f"{ind}  End Site", f"{ind}  {{", f"{ind}    OFFSET {' '.join(fmt % v for v in end_sites[j])}", f"{ind}  }}"])
        out.append(f"{ind}}}")

    emit(0, 0)
    starts = np.cumsum([0] + [len(c) for c in channels])
    cols = [c for j in order for c in range(starts[j], starts[j + 1])]
    values = np.asarray(values)[:, cols]
    out += ["MOTION", f"Frames: {len(values)}", f"Frame Time: {frame_time:.7f}"]
    out += [" ".join(fmt % v for v in row) for row in values]
    return "\n".join(out) + "\n"


def random_rotations(n: int, gen: torch.Generator, max_angle: float = math.pi) -> torch.Tensor:
    axis = torch.randn(n, 3, generator=gen, dtype=torch.float64)
    axis = axis / axis.norm(dim=-1, keepdim=True)
    ang = torch.rand(n, 1, generator=gen, dtype=torch.float64) * max_angle
    return axis_angle_to_matrix(axis * ang)


# SMPL joints present in the synthetic BVH (SMPL minus spine2 and hands, like the corpus).
SYN_JOINTS = [n for n in JOINT_NAMES if n not in ("spine2", "left_hand", "right_hand")]
#: Joints whose BVH frame orientation is random (rig joint orients); the others share their
#: mapped parent's orientation so that their BVH zero pose is a straight, untwisted chain.
RANDOM_ORIENT = ("pelvis", "spine3", "left_hip", "right_hip", "left_knee", "right_knee",
                 "left_shoulder", "right_shoulder", "left_elbow", "right_elbow")
SYN_MAP = SkeletonMap(name="synthetic", joints={n: f"J_{n}" for n in SYN_JOINTS}, units_to_m=0.01,
                      foot_joints=("J_left_foot", "J_right_foot"))


def smpl_hinge_axis(rest: torch.Tensor, hinge: str) -> torch.Tensor:
    seg = {"left_knee": "left_hip", "right_knee": "right_hip", "left_elbow": "left_shoulder", "right_elbow": "right_shoulder"}[hinge]
    flex = torch.tensor([0.0, 0.0, -1.0] if "knee" in hinge else [0.0, 0.0, 1.0], dtype=torch.float64)
    d = rest[JOINT_INDEX[hinge]] - rest[JOINT_INDEX[seg]]
    a = torch.linalg.cross(d / d.norm(), flex, dim=-1)
    return a / a.norm()


#: Bone of each swing-only joint (SMPL joint -> the joint its bone points to).
SWING_BONES = {"spine1": "spine3", "left_collar": "left_shoulder", "right_collar": "right_shoulder"}


def synthetic_smpl_motion(rest: torch.Tensor, T: int = 60, seed: int = 0,
                          swing_only: Sequence[str] = ()) -> tuple[torch.Tensor, torch.Tensor]:
    """SMPL local rotations ``(T, 24, 3, 3)`` and pelvis world positions ``(T, 3)`` (metres):
    smooth random ball-joint motion, pure hinge knees/elbows about SMPL's hinge axes (flexing
    0-90 deg), identity spine2 and hands, walking forward along +Z. Joints in ``swing_only``
    (keys of :data:`SWING_BONES`) rotate about axes perpendicular to their bone (no twist)."""
    g = torch.Generator().manual_seed(seed)
    t = torch.linspace(0, 1, T, dtype=torch.float64)
    R = torch.eye(3, dtype=torch.float64).repeat(T, 24, 1, 1)
    for j, name in enumerate(JOINT_NAMES):
        if name in ("spine2", "left_hand", "right_hand"):
            continue
        if name in ("left_knee", "right_knee", "left_elbow", "right_elbow"):
            phase = float(torch.rand(1, generator=g)) * 6.28
            theta = 0.8 * (1 - torch.cos(2 * math.pi * t * 1.5 + phase))  # 0 .. 1.6 rad
            R[:, j] = axis_angle_to_matrix(smpl_hinge_axis(rest, name) * theta[:, None])
            continue
        a = torch.randn(2, 3, generator=g, dtype=torch.float64) * 0.3
        aa = a[0] + a[1] * torch.sin(2 * math.pi * t)[:, None]
        if name in swing_only:
            n = rest[JOINT_INDEX[SWING_BONES[name]]] - rest[j]
            n = n / n.norm()
            aa = aa - (aa @ n)[:, None] * n
        R[:, j] = axis_angle_to_matrix(aa)
    # Root: upright, small yaw wobble.
    yaw = 0.2 * torch.sin(2 * math.pi * t)
    R[:, 0] = axis_angle_to_matrix(torch.stack([torch.zeros_like(yaw), yaw, torch.zeros_like(yaw)], -1))
    pelvis = torch.stack([0.1 * torch.sin(2 * math.pi * t), 0.95 + 0.02 * torch.cos(4 * math.pi * t), 2.0 * t], -1)
    return R, pelvis


def synthetic_bvh_from_smpl(rest: torch.Tensor, local: torch.Tensor, pelvis: torch.Tensor, seed: int = 1,
                            random_orient: Sequence[str] = RANDOM_ORIENT) -> tuple[str, dict[str, torch.Tensor]]:
    """A BVH (centimetres, all joints 6 channels ZXY, position channels = OFFSETs like Bandai)
    whose skeleton is SMPL's minus spine2/hands, with random joint frame orientations ``O_j``
    (BVH frame = SMPL frame @ O_j). Returns the text and ``{smpl name: O_j}``."""
    from wearpose.body.kinematics import forward_kinematics

    g = torch.Generator().manual_seed(seed)
    G, _ = forward_kinematics(local, rest)
    idx = {n: i for i, n in enumerate(SYN_JOINTS)}
    parents = []
    for n in SYN_JOINTS:
        p = PARENTS[JOINT_INDEX[n]]
        while p >= 0 and JOINT_NAMES[p] not in idx:
            p = PARENTS[p]
        parents.append(idx[JOINT_NAMES[p]] if p >= 0 else -1)
    O: dict[str, torch.Tensor] = {}
    for k, n in enumerate(SYN_JOINTS):
        O[n] = random_rotations(1, g)[0] if n in random_orient or parents[k] < 0 else O[SYN_JOINTS[parents[k]]]
    Tn = local.shape[0]
    offsets = np.zeros((len(SYN_JOINTS), 3))
    values = []
    Gb = {n: G[:, JOINT_INDEX[n]] @ O[n] for n in SYN_JOINTS}
    for k, n in enumerate(SYN_JOINTS):
        p = parents[k]
        if p < 0:
            off = torch.zeros(3, dtype=torch.float64)
            pos = pelvis * 100.0
            Lb = Gb[n]
        else:
            pn = SYN_JOINTS[p]
            # Offset in the parent's BVH frame: SMPL rest bone rotated by O_parent^T, in cm.
            off = O[pn].T @ (rest[JOINT_INDEX[n]] - rest[JOINT_INDEX[pn]]) * 100.0
            pos = off.expand(Tn, 3)
            Lb = Gb[pn].transpose(-1, -2) @ Gb[n]
        offsets[k] = off.numpy()
        eul = torch.rad2deg(matrix_to_euler(Lb, "ZXY"))
        values.append(torch.cat([pos, eul], -1))
    vals = torch.cat(values, -1).numpy()
    chans = [("Xposition", "Yposition", "Zposition", "Zrotation", "Xrotation", "Yrotation")] * len(SYN_JOINTS)
    ends = {SYN_JOINTS.index(n): [0.0, 0.0, 0.0] for n in ("head", "left_wrist", "right_wrist", "left_foot", "right_foot")}
    return bvh_text([f"J_{n}" for n in SYN_JOINTS], parents, offsets, chans, vals, 1 / 30, ends), O


def corpus_dir() -> Path | None:
    """The shared corpus if present: ``$WEARPOSE_DATA`` or ``../shared/data-v2`` next to the
    checkout (the library's default, :func:`wearpose.motion.data_dir`)."""
    env = os.environ.get("WEARPOSE_DATA")
    if env:
        p = Path(env)
        return p if (p / "manifest.csv").is_file() else None
    here = Path(__file__).resolve()
    for d in here.parents:
        cand = d.parent / "shared" / "data-v2"
        if (cand / "manifest.csv").is_file():
            return cand
    return None


__all__ = ["bvh_text", "random_rotations", "synthetic_smpl_motion", "synthetic_bvh_from_smpl", "SYN_MAP",
           "SYN_JOINTS", "smpl_hinge_axis", "corpus_dir", "rotation_between"]
