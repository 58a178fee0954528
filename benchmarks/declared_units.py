"""Declared units and frames give the same estimate (issue 21's acceptance), per shipped model.

Run: ``python benchmarks/declared_units.py [--clip cmu_daz/05/05_01] [--seconds 2]
[--models empose12_cpu ...] [--out declared_units]``.

The clip (first ``--seconds`` s of the prepared store ``$WEARPOSE_CACHE``; a held-out walk) after
a marked 1 s T-pose is simulated without noise with each model's kit at its trained rate
(:func:`wearpose.evaluate.conventions.kit_recording`); then the canonical recording and its copies
declared in mm and in cm, deg/s, g, sensor-frame acceleration with gravity and a Z-up world are
estimated through ``wearpose estimate``'s path and compared
(:func:`wearpose.evaluate.conventions.declared_differences`): max |difference| of the local
rotations, root translation (m) and betas over every frame. Writes
``benchmarks/results/<out>.{md,json}``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shlex
import sys
from pathlib import Path

import torch

RESULTS = Path(__file__).parent / "results"


def main() -> None:
    from wearpose.cli.models import pose_weights

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--clip", default="cmu_daz/05/05_01")
    ap.add_argument("--seconds", type=float, default=2.0)
    ap.add_argument("--models", nargs="+", default=pose_weights(), help="shipped weights (default: every pose model)")
    ap.add_argument("--out", default="declared_units")
    args = ap.parse_args()
    torch.set_num_threads(1)
    from wearpose.body import BodyModel
    from wearpose.estimators.run import open_model
    from wearpose.evaluate.conventions import DECLARATIONS, declared_differences, kit_recording
    from wearpose.motion import load_motion, resample

    clip = load_motion(args.clip, rest_joints=BodyModel().rest_joints())
    rows = {}
    for name in args.models:
        s = open_model(name)
        s.estimator_class  # a method may register its own kit (IMUPoser's) when imported
        fps = float(s.fps or 60.0)
        m = clip if abs(clip.fps - fps) < 1e-9 else resample(clip, fps)
        m = m.slice(0, int(round(args.seconds * fps)))
        rows[name] = declared_differences(s, kit_recording(s.kit, m, fps))
        print(name, json.dumps(rows[name]), flush=True)
    worst = max(max(d.values()) for r in rows.values() for d in r.values())
    command = "python benchmarks/declared_units.py " + " ".join(shlex.quote(a) for a in sys.argv[1:])
    res = {"clip": args.clip, "seconds": args.seconds, "tpose_s": 1.0, "noise": "none", "seed": 2,
           "weights": list(rows), "declarations": DECLARATIONS,
           "unit": "max |difference| over frames and elements; rotations as matrix elements, trans in m", "rows": rows, "max": worst, "tolerance": 1e-4, "command": command,
           "machine": {"platform": platform.platform(), "load_avg": os.getloadavg()}}
    decl = ", ".join(f"{k}={v}" for k, v in DECLARATIONS["mm"].items() if k != "position_unit")
    md = (f"# Declared units and frames give the same estimate (issue 21)\n\n`{command}`\n\n"
          f"{args.seconds:g} s of `{args.clip}` after a marked 1 s T-pose, each model's kit simulated without noise "
          f"at its trained rate (seed 2); the canonical recording against its copies declared with positions in mm "
          f"and in cm and {decl}, each estimated as `wearpose estimate` does (in the world, on the floor). Max "
          f"|difference| over every frame: local rotation matrix elements, root translation (m), betas. "
          f"Acceptance: < 1e-4; worst here {worst:.2g}.\n\n"
          "| model | rot (mm) | trans m (mm) | rot (cm) | trans m (cm) |\n|---|---:|---:|---:|---:|\n"
          + "".join(f"| {n} | {r['mm']['local_rot']:.2g} | {r['mm'].get('trans', float('nan')):.2g} | "
                    f"{r['cm']['local_rot']:.2g} | {r['cm'].get('trans', float('nan')):.2g} |\n" for n, r in rows.items()))
    RESULTS.mkdir(parents=True, exist_ok=True)
    for suffix, text in (("md", md), ("json", json.dumps(res, indent=2))):
        (RESULTS / f"{args.out}.{suffix}").write_text(text)
    print(md)


if __name__ == "__main__":
    main()
