"""Measure retargeting quality over a sample of the corpus (not a test; run by hand).

    python tests/motion/measure_retarget.py [--per-source N] [--rest template|body]

Per source: bone-direction error (mean/max of per-clip means and overall max, degrees), the
SMPL knee/elbow local-rotation axis deviation from SMPL's hinge axes (a twist check), the
lowest foot joint height, and for walk clips: head above pelvis, facing vs travel direction.
"""

from __future__ import annotations

import argparse
import csv
import math
import random
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).parent))
from motion_testutils import corpus_dir  # noqa: E402

from wearpose.body.kinematics import forward_kinematics  # noqa: E402
from wearpose.geometry import matrix_to_axis_angle  # noqa: E402
from wearpose.motion import bone_direction_errors, default_rest_joints, read_bvh, retarget_bvh, template_rest_joints  # noqa: E402


def hinge_axis_dev(pose: torch.Tensor, j: int, want: torch.Tensor) -> float:
    w = matrix_to_axis_angle(pose[:, j])
    _, evecs = torch.linalg.eigh(w.T @ w)
    return math.degrees(math.acos(min(1.0, abs(float(evecs[:, -1] @ want)))))


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--per-source", type=int, default=100)
    ap.add_argument("--rest", choices=["template", "body"], default="body")
    args = ap.parse_args()
    data = corpus_dir()
    if data is None:
        sys.exit("corpus not found")
    warnings.simplefilter("ignore")
    rest, rest_src = (template_rest_joints(), "template") if args.rest == "template" else default_rest_joints()
    print(f"rest joints: {rest_src}")
    rows = list(csv.DictReader(open(data / "manifest.csv")))
    rng = random.Random(0)
    for source in ("cmu_daz", "bandai"):
        rs = [r for r in rows if r["source"] == source]
        rng.shuffle(rs)
        rs = rs[: args.per_source]
        clip_means, clip_max, knee_dev, elbow_dev, lowest, facing, upright_fail = [], [], [], [], [], [], 0
        per_bone: dict[str, list[float]] = {}
        t0 = time.perf_counter()
        for r in rs:
            path = data / r["path"].removeprefix("data/")
            res = retarget_bvh(read_bvh(path), rest)
            skip = 1 if r.get("frame0_is_tpose") == "1" else 0
            errs = {k: np.degrees(v[skip:]) for k, v in bone_direction_errors(res, rest).items()}
            allv = np.concatenate(list(errs.values()))
            clip_means.append(allv.mean())
            clip_max.append(allv.max())
            for k, v in errs.items():
                per_bone.setdefault(k, []).append(float(v.mean()))
            pose = res.sequence.pose.double()[skip:]
            knee_dev += [hinge_axis_dev(pose, j, torch.tensor([1.0, 0, 0], dtype=torch.float64)) for j in (4, 5)]
            elbow_dev += [hinge_axis_dev(pose, j, torch.tensor([0, 1.0, 0], dtype=torch.float64)) for j in (18, 19)]
            lowest.append(res.lowest_foot_y)
            if r["description"].startswith("walk"):
                G, J = forward_kinematics(pose, rest)
                J = J + res.sequence.trans.double()[skip:, None]
                upright_fail += int(bool((J[:, 15, 1] <= J[:, 0, 1]).any()))
                d = J[-1, 0] - J[0, 0]
                d[1] = 0
                f = G[:, 0, :, 2].mean(0)
                f[1] = 0
                if d.norm() > 1.0 and "back" not in r["description"] and "left" not in r["description"] and "right" not in r["description"]:
                    facing.append(math.degrees(math.acos(float(torch.dot(d, f) / d.norm() / f.norm()))))
        dt = time.perf_counter() - t0
        print(f"\n== {source}: {len(rs)} clips ({dt:.1f} s)")
        print(f"bone-direction error, per-clip mean over all 11 bones: mean {np.mean(clip_means):.2e} deg, "
              f"max {np.max(clip_means):.2e} deg; worst single frame {np.max(clip_max):.2e} deg")
        print("  per bone (mean of clip means): " + ", ".join(f"{k} {np.mean(v):.1e}" for k, v in per_bone.items()))
        print(f"SMPL knee rotation axis vs +X: median {np.median(knee_dev):.1f} deg, 90th pct {np.percentile(knee_dev, 90):.1f}")
        print(f"SMPL elbow rotation axis vs +-Y: median {np.median(elbow_dev):.1f} deg, 90th pct {np.percentile(elbow_dev, 90):.1f}")
        print(f"lowest foot joint y (m): median {np.median(lowest):.3f}, min {np.min(lowest):.3f}, max {np.max(lowest):.3f}")
        if facing:
            print(f"walk clips travelling forward > 1 m: {len(facing)}; facing vs travel: median {np.median(facing):.1f} deg, "
                  f"max {np.max(facing):.1f} deg; walk clips with head ever below pelvis: {upright_fail}")


if __name__ == "__main__":
    main()
