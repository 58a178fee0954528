"""Cross-format check of corpus v2: the same CMU captures as ASF/AMC (``crosscheck/cmu_asf/02``,
120 Hz, CMU's own skeleton) and as BVH (``cmu_daz/02``: cgspeed's conversion onto the Daz
skeleton, every second frame kept, a T-pose added as frame 0).

Run by hand for the figures in docs/motion-import.md::

    python tests/motion/crosscheck_testutils.py

Two levels are measured per take, after aligning time (BVH frame k = AMC frame 2k - 1, 0-based,
found by search) and placement (the rotation about the vertical and the translation that fit
one onto the other best, over all joints and frames):

- **source**: what the two readers read. The BVH's joint world rotations equal the ASF's up to
  one constant rotation per joint (the two skeletons' joint frames differ); with those constants
  removed, the BVH's rotations drive the ASF skeleton and its joint positions are compared with
  the ASF's own (metres).
- **SMPL**: the two files retargeted as the corpus does (:func:`wearpose.motion.import_motion`
  with the built-in ``cmu_asf`` map; :func:`wearpose.motion.retarget_bvh` with ``cmu_daz``), SMPL
  joint positions compared: as they are, root-relative (pelvis subtracted), and with the BVH
  clip's horizontal root travel rescaled to the ASF's (what the two leg scalings leave).
"""

from __future__ import annotations

import math
import sys
from pathlib import Path
from typing import Any

import torch

from wearpose.body.kinematics import forward_kinematics
from wearpose.body.skeleton import JOINT_NAMES
from wearpose.geometry import geodesic_angle, project_to_so3
from wearpose.motion import BvhMotion, bvh_forward_kinematics, read_asf_amc, read_bvh, retarget_bvh
from wearpose.motion.importer import import_motion

TAKES = ("02_01", "02_02", "02_03", "02_04")
#: BVH frames left out: 0 is cgspeed's T-pose, 1 still blends from it (its arms are 30-45 deg
#: from both neighbours; every other frame is within 7 deg).
BVH_SKIP = 2
#: ASF bone -> the Daz joint whose world rotation it has in the conversion (measured: constant
#: offsets, spreads of a few degrees). Daz has one spine joint below the chest (``abdomen``, which
#: follows ``upperback``), one neck joint, no toes, fingers or forearm twist.
ASF_TO_DAZ: dict[str, str] = {
    "root": "hip", "lhipjoint": "hip", "rhipjoint": "hip", "lowerback": "abdomen", "upperback": "abdomen",
    "thorax": "chest", "lowerneck": "neck", "upperneck": "neck", "head": "head",
    **{f"{s}{a}": f"{s}{d}" for s in "lr" for a, d in (
        ("femur", "Thigh"), ("tibia", "Shin"), ("foot", "Foot"), ("toes", "Foot"), ("clavicle", "Collar"),
        ("humerus", "Shldr"), ("radius", "ForeArm"), ("wrist", "ForeArm"), ("hand", "Hand"), ("fingers", "Hand"),
        ("thumb", "Hand"))},
}


def take_files(data: Path, take: str) -> tuple[Path, Path]:
    """``(amc, bvh)`` of one cross-check take in the corpus folder ``data``."""
    return data / "crosscheck" / "cmu_asf" / "02" / f"{take}.amc.gz", data / "cmu_daz" / "02" / f"{take}.bvh.gz"


def time_offset(asf: BvhMotion, bvh: BvhMotion, search: int = 4) -> int:
    """AMC frame index (0-based) of BVH frame 1: the offset whose root world rotations agree best
    (BVH frame k then matches AMC frame ``2 (k - 1) + offset``)."""
    Ga = bvh_forward_kinematics(asf)[0][:, 0]
    Gb = bvh_forward_kinematics(bvh)[0][BVH_SKIP:, 0]
    best, best_err = 0, math.inf
    for o in range(search):
        idx = torch.arange(len(Gb)) * 2 + o + 2 * (BVH_SKIP - 1)
        ok = idx < len(Ga)
        err = float(geodesic_angle(Ga[idx[ok]], Gb[ok]).mean())
        if err < best_err:
            best, best_err = o, err
    return best


def _pairs(n_bvh: int, n_amc: int, offset: int) -> tuple[torch.Tensor, torch.Tensor]:
    """Matching (BVH frame, AMC frame) indices for the kept BVH frames."""
    k = torch.arange(BVH_SKIP, n_bvh)
    a = 2 * (k - 1) + offset
    ok = a < n_amc
    return k[ok], a[ok]


def _fit_yaw(A: torch.Tensor, B: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Rotation about +Y and translation minimising ``|A R^T + t - B|^2`` over points ``(N, 3)``."""
    ca, cb = A.mean(0), B.mean(0)
    a, b = A - ca, B - cb
    th = torch.atan2((a[:, 2] * b[:, 0] - a[:, 0] * b[:, 2]).sum(), (a[:, 0] * b[:, 0] + a[:, 2] * b[:, 2]).sum())
    c, s = float(torch.cos(th)), float(torch.sin(th))
    R = torch.tensor([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]], dtype=A.dtype)
    return R, cb - R @ ca


def _stats(d: torch.Tensor) -> dict[str, float]:
    """Mean, 95th percentile and max of distances (m) -> cm."""
    return {"mean_cm": 100 * float(d.mean()), "p95_cm": 100 * float(d.flatten().quantile(0.95)), "max_cm": 100 * float(d.max())}


def source_level(asf: BvhMotion, bvh: BvhMotion, offset: int) -> dict[str, Any]:
    """Rotation agreement per ASF bone and the ASF skeleton driven by the BVH's rotations."""
    kb, ka = _pairs(bvh.num_frames, asf.num_frames, offset)
    Ga, Pa = bvh_forward_kinematics(asf)
    Gb = bvh_forward_kinematics(bvh)[0][kb]
    Ga, Pa = Ga[ka], Pa[ka]
    names = asf.skeleton.names
    G2 = torch.empty_like(Ga)
    spread: dict[str, float] = {}
    for j, name in enumerate(names):
        Gd = Gb[:, bvh.skeleton.index(ASF_TO_DAZ[name])]
        R = Ga[:, j].transpose(-1, -2) @ Gd
        M = project_to_so3(R.mean(0))  # the constant frame offset of the two skeletons' joints
        spread[name] = math.degrees(float(geodesic_angle(R, M.expand_as(R)).mean()))
        G2[:, j] = Gd @ M.T
    offs = asf.translations[ka]
    P2 = torch.empty_like(Pa)
    for j, p in enumerate(asf.skeleton.parents):
        P2[:, j] = Pa[:, 0] if p < 0 else P2[:, p] + (G2[:, p] @ offs[:, j, :, None])[..., 0]
    d = (P2 - Pa).norm(dim=-1) * asf.meta["units_to_m"]
    return {**_stats(d), "rotation_spread_deg": spread, "root_spread_deg": spread["root"]}


def _smpl_joints(seq: Any, rest: torch.Tensor) -> torch.Tensor:
    _, J = forward_kinematics(seq.pose.to(torch.float64), rest)
    return J + seq.trans.to(torch.float64)[:, None]


def smpl_level(amc: Path, bvh: Path, asf_m: BvhMotion, bvh_m: BvhMotion, offset: int, rest: torch.Tensor) -> dict[str, Any]:
    """The two files retargeted as the corpus does, SMPL joints compared (see module doc)."""
    ia = import_motion(amc, rest, up="y", fps=120.0)
    rb = retarget_bvh(bvh_m, rest)
    kb, ka = _pairs(bvh_m.num_frames, asf_m.num_frames, offset)
    A, B = _smpl_joints(ia.sequence, rest)[ka], _smpl_joints(rb.sequence, rest)[kb]
    R, t = _fit_yaw(A.reshape(-1, 3), B.reshape(-1, 3))
    A = A @ R.T + t
    d = (A - B).norm(dim=-1)
    rel = ((A - A[:, :1]) - (B - B[:, :1])).norm(dim=-1)
    # The BVH clip's horizontal root travel rescaled to the ASF's (least squares), then placed again.
    ta, tb = A[:, 0, [0, 2]] - A[:, 0, [0, 2]].mean(0), B[:, 0, [0, 2]] - B[:, 0, [0, 2]].mean(0)
    k = float((ta * tb).sum() / (tb * tb).sum().clamp_min(1e-12))
    B2 = B.clone()
    B2[..., [0, 2]] = B[..., [0, 2]] + (k - 1) * tb[:, None]
    R2, t2 = _fit_yaw(A.reshape(-1, 3), B2.reshape(-1, 3))
    d2 = (A - (B2 @ R2.T + t2)).norm(dim=-1)  # rigid placement of B2 onto A (same distances as the inverse)
    per_joint = {n: 100 * float(v) for n, v in zip(JOINT_NAMES, rel.mean(0))}
    return {**_stats(d), "root_relative": _stats(rel), "travel_rescaled": {**_stats(d2), "factor": k},
            "per_joint_root_relative_cm": per_joint, "leg_scale_asf": ia.report.translation_scale,
            "leg_scale_bvh": rb.tpose.scale, "yaw_deg": math.degrees(math.atan2(float(R[0, 2]), float(R[0, 0])))}


def crosscheck_take(data: Path, take: str, rest: torch.Tensor) -> dict[str, Any]:
    """Both levels for one take: ``{"take", "offset", "frames", "source", "smpl"}``."""
    amc, bvh = take_files(data, take)
    asf_m, bvh_m = read_asf_amc(amc), read_bvh(bvh)
    offset = time_offset(asf_m, bvh_m)
    return {"take": take, "offset": offset, "frames": len(_pairs(bvh_m.num_frames, asf_m.num_frames, offset)[0]),
            "source": source_level(asf_m, bvh_m, offset), "smpl": smpl_level(amc, bvh, asf_m, bvh_m, offset, rest)}


def main() -> None:
    sys.path.insert(0, str(Path(__file__).parent))
    from motion_testutils import corpus_dir  # noqa: PLC0415

    from wearpose.motion import default_rest_joints  # noqa: PLC0415

    data = corpus_dir()
    if data is None or not (data / "crosscheck").is_dir():
        sys.exit("corpus v2 (with crosscheck/) not found: set WEARPOSE_DATA")
    rest, src = default_rest_joints()
    rest = rest.to(torch.float64)
    print(f"rest joints: {src}; corpus {data}")
    for take in TAKES:
        r = crosscheck_take(data, take, rest)
        s, m = r["source"], r["smpl"]
        worst = sorted(m["per_joint_root_relative_cm"].items(), key=lambda kv: -kv[1])[:3]
        spread = sorted(s["rotation_spread_deg"].items(), key=lambda kv: -kv[1])[:3]
        print(f"{take}: {r['frames']} frames, AMC offset {r['offset']} | source: mean {s['mean_cm']:.2f} p95 {s['p95_cm']:.2f} "
              f"max {s['max_cm']:.2f} cm, root spread {s['root_spread_deg']:.3f} deg, worst spreads "
              f"{', '.join(f'{k} {v:.1f}' for k, v in spread)} | SMPL: mean {m['mean_cm']:.2f} max {m['max_cm']:.2f} cm, "
              f"root-relative {m['root_relative']['mean_cm']:.2f}, travel rescaled x{m['travel_rescaled']['factor']:.3f} "
              f"{m['travel_rescaled']['mean_cm']:.2f} cm; leg scales asf {m['leg_scale_asf']:.3f} bvh {m['leg_scale_bvh']:.3f}; "
              f"worst joints {', '.join(f'{k} {v:.1f}' for k, v in worst)}")


if __name__ == "__main__":
    main()
