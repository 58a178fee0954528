"""Motion import per skeleton: detected units / up axis / rest pose and the bone-direction check.

Run: ``python benchmarks/motion_import.py [--per-source N] [--frames T]``. Prints a table and
writes ``benchmarks/results/motion_import.json``.

Skeletons:
- every corpus skeleton (``cmu_daz``, ``bandai``): ``--per-source`` clips each (random, seed 0;
  all splits: this is a conversion check, nothing is trained);
- synthetic skeletons written by the test utilities from known SMPL motion
  (``tests/motion/import_testutils.py``): 3ds-Max-Biped names, A-pose rest, millimetres, Z up,
  as BVH and as ASF/AMC (mm under ``length 1``); Mixamo names (cm, Y up); CMU-ASF names
  (ASF/AMC, ``length 0.45``, Y up); Rigify names (m, -Z up).

Per skeleton: ``bone_err_deg`` = mean over clips of the clip-mean angle between every mapped bone
of the result and the same bone of the source file (``ImportReport.bone_error_deg``), its worst
clip and worst bone; for the synthetic ones also ``truth_err_deg`` = the same bones against the
known SMPL motion the file was written from (independent of the importer's own check). The corpus
maps declare cm and Y up; ``detected_without_declaration`` counts the clips where the unit and
up-axis detectors, run without that declaration, find them. The corpus
maps declare cm and Y up; ``detected_without_declaration`` counts the clips where the unit and
up-axis detectors, run without that declaration, find them. The result plays
on the default body model (its proportions differ from every source).
"""

from __future__ import annotations

import argparse
import csv
import json
import platform
import random
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import torch
from rich.console import Console
from rich.table import Table

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "motion"))
from import_testutils import (  # noqa: E402
    BIPED_NAMES, custom_bvh_text, custom_skeleton_motion, joint_tree_to_asf_amc,
)
from motion_testutils import corpus_dir, synthetic_smpl_motion  # noqa: E402

from wearpose.body.kinematics import forward_kinematics  # noqa: E402
from wearpose.body.skeleton import JOINT_NAMES  # noqa: E402
from wearpose.motion import MIXAMO, RIGIFY, default_rest_joints, import_motion, template_rest_joints  # noqa: E402
from wearpose.motion import read_bvh  # noqa: E402
from wearpose.motion.importer import IMPORT_BONE_PAIRS, UP_AXES, detect_units, detect_up, leg_length  # noqa: E402

CMU_ASF_NAMES = {
    "pelvis": "root", "spine1": "upperback", "spine2": "midback", "spine3": "thorax", "neck": "lowerneck", "head": "head",
    **{f"{s}_{k}": f"{s[0]}{v}" for s in ("left", "right") for k, v in (
        ("collar", "clavicle"), ("shoulder", "humerus"), ("elbow", "radius"), ("wrist", "hand"),
        ("hip", "femur"), ("knee", "tibia"), ("ankle", "foot"), ("foot", "toes"))},
}


def truth_error(seq, sk: dict, rest: torch.Tensor) -> float:
    """Mean angle (deg) between result bones and the known source bones, over the bones of
    :data:`IMPORT_BONE_PAIRS` (the ones the importer checks)."""
    _, J = forward_kinematics(seq.pose.double(), rest)
    errs = []
    for a_name, b_name in IMPORT_BONE_PAIRS:
        ka, kb = sk["names"].index(a_name), sk["names"].index(b_name)
        a, b = JOINT_NAMES.index(a_name), JOINT_NAMES.index(b_name)
        ds, dt = J[:, b] - J[:, a], sk["smpl_pos"][:, kb] - sk["smpl_pos"][:, ka]
        cos = (ds * dt).sum(-1) / ds.norm(dim=-1) / dt.norm(dim=-1)
        errs.append(float(torch.rad2deg(torch.arccos(cos.clamp(-1, 1))).mean()))
    return float(np.mean(errs))


def row_from(name: str, reports: list, truth: list[float] | None, seconds: float, frames: int) -> dict:
    be = [r.bone_error_deg for r in reports]
    worst = max(be, key=lambda b: b["worst_bone_mean"])
    r0 = reports[0]
    return {
        "skeleton": name, "clips": len(reports), "format": r0.format, "map": f"{r0.skeleton} ({r0.map_source})",
        "units": sorted({r.units["name"] for r in reports}), "up": sorted({r.up["axis"] for r in reports}),
        "rest_pose": sorted({r.rest_pose["kind"] for r in reports}),
        "bone_err_deg_mean": float(np.mean([b["mean"] for b in be])),
        "bone_err_deg_worst_clip": float(max(b["mean"] for b in be)),
        "worst_bone": worst["worst_bone"], "worst_bone_deg": worst["worst_bone_mean"],
        "truth_err_deg": None if truth is None else float(np.mean(truth)),
        "unmapped": [row[0] for row in r0.mapping if row[1] == "-"],
        "frames": frames, "frames_per_s": frames / seconds if seconds > 0 else None,
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--per-source", type=int, default=20)
    ap.add_argument("--frames", type=int, default=120, help="frames of each synthetic clip")
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "motion_import.json")
    args = ap.parse_args()
    torch.set_num_threads(1)
    rest, asset = default_rest_joints()
    rows = []
    data = corpus_dir()
    if data is not None:
        manifest = list(csv.DictReader(open(data / "manifest.csv", encoding="utf-8")))
        rng = random.Random(0)
        for source in ("cmu_daz", "bandai"):
            rs = [r for r in manifest if r["source"] == source]
            rng.shuffle(rs)
            reps, t0, frames, det = [], time.perf_counter(), 0, []
            for r in rs[: args.per_source]:
                path = data / r["path"].removeprefix("data/")
                imp = import_motion(path, rest)
                reps.append(imp.report)
                frames += imp.report.frames
                # The corpus maps declare cm and Y up; run the detectors anyway to measure them.
                motion, smap = read_bvh(path), imp.retargeted.smap
                det.append((detect_up(motion, smap)["axis"], detect_units(leg_length(motion, smap))["name"]))
            row = row_from(f"corpus {source}", reps, None, time.perf_counter() - t0, frames)
            row["detected_without_declaration"] = {
                "up_y": sum(d[0] == "y" for d in det), "units_cm": sum(d[1] == "cm" for d in det), "clips": len(det),
                "other": sorted({f"{a}/{u}" for a, u in det if (a, u) != ("y", "cm")})}
            rows.append(row)
    local, pelvis = synthetic_smpl_motion(template_rest_joints(), T=args.frames, seed=0)
    tmpl = template_rest_joints()
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        cases = []
        biped = custom_skeleton_motion(local, pelvis, tmpl, scale=1000.0, z_up=True)
        (d / "biped.bvh").write_text(custom_bvh_text(biped))
        cases.append(("biped A-pose mm Z-up (BVH)", d / "biped.bvh", biped))
        asf, amc, _ = joint_tree_to_asf_amc(biped, BIPED_NAMES, length_mult=1.0, seed=4)
        (d / "biped.asf").write_text(asf)
        (d / "biped_01.amc").write_text(amc)
        cases.append(("biped A-pose mm Z-up (ASF/AMC)", d / "biped_01.amc", biped))
        mix = custom_skeleton_motion(local, pelvis, tmpl, scale=100.0, z_up=False, arm_down_deg=0.0)
        (d / "mixamo.bvh").write_text(custom_bvh_text(mix, {s: "mixamorig:" + n for s, n in MIXAMO.joints.items()}))
        cases.append(("mixamo T-pose cm Y-up (BVH)", d / "mixamo.bvh", mix))
        cmu = custom_skeleton_motion(local, pelvis, tmpl, scale=0.45 / 0.0254, z_up=False, arm_down_deg=0.0)
        asf, amc, _ = joint_tree_to_asf_amc(cmu, CMU_ASF_NAMES, length_mult=1.0, seed=5)
        (d / "cmu.asf").write_text(asf.replace("length 1\n", "length 0.45\n"))
        (d / "cmu_01.amc").write_text(amc)
        cases.append(("CMU-ASF names 1/0.45 in Y-up (ASF/AMC)", d / "cmu_01.amc", cmu))
        rig = custom_skeleton_motion(local, pelvis, tmpl, scale=1.0, world=UP_AXES["-z"].T, arm_down_deg=30.0)
        (d / "rigify.bvh").write_text(custom_bvh_text(rig, {s: "DEF-" + n for s, n in RIGIFY.joints.items()}))
        cases.append(("rigify A30 m -Z-up (BVH)", d / "rigify.bvh", rig))
        for name, path, sk in cases:
            t0 = time.perf_counter()
            imp = import_motion(path, rest, fps=30)
            dt = time.perf_counter() - t0
            rows.append(row_from(name, [imp.report], [truth_error(imp.sequence, sk, rest)], dt, imp.report.frames))
    t = Table(title=f"motion import per skeleton (body {asset}; bone error = mean angle result vs source bone)")
    for c in ("skeleton", "clips", "map", "units", "up", "rest pose", "bone err deg", "worst clip", "worst bone", "truth err", "frames/s"):
        t.add_column(c)
    for r in rows:
        t.add_row(r["skeleton"], str(r["clips"]), r["map"], ",".join(r["units"]), ",".join(r["up"]), ",".join(r["rest_pose"]),
                  f"{r['bone_err_deg_mean']:.3g}", f"{r['bone_err_deg_worst_clip']:.3g}", f"{r['worst_bone']} {r['worst_bone_deg']:.3g}",
                  "-" if r["truth_err_deg"] is None else f"{r['truth_err_deg']:.3g}",
                  f"{r['frames_per_s']:.0f}" if r["frames_per_s"] else "-")
    Console(width=200).print(t)
    for r in rows:
        if "detected_without_declaration" in r:
            d = r["detected_without_declaration"]
            print(f"{r['skeleton']}: detectors without the map's declaration: up y in {d['up_y']}/{d['clips']}, "
                  f"units cm in {d['units_cm']}/{d['clips']} clips; other: {d['other'] or 'none'}")
    out = {"command": "python benchmarks/motion_import.py " + " ".join(sys.argv[1:]), "body_asset": asset,
           "machine": platform.platform(), "threads": 1, "per_source": args.per_source, "rows": rows}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(out, indent=1))
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
