"""MI-Poser's spine twist about the bone (issue 22's waist tear): median twist of spine1-3 (and
of their product) in a MI-Poser estimate against the ground truth.

Run: ``python benchmarks/miposer_twist.py [--weights miposer_cpu ...] [--clip cmu_daz/05/05_01]
[--seconds 5] [--out miposer_twist]``.

The clip (first ``--seconds`` s, prepared store ``$WEARPOSE_CACHE``) is simulated with kit
``miposer`` (default noise, seed 0, as ``tests/estimators/test_mesh_integrity.py``) and estimated
through :func:`wearpose.estimators.run.estimate_recording`; per frame the magnitude of each spine
joint's local twist about its bone (+Y, :func:`wearpose.geometry.twist_angle`), deg, median over
the frames. The v1 ``miposer_cpu`` weights turned spine1 ~180 deg and spine2 ~130 deg (nearly
cancelling along the chain): a torn waist no joint-position metric sees. Writes
``benchmarks/results/<out>.{md,json}``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shlex
import sys
import warnings
from pathlib import Path

import torch

RESULTS = Path(__file__).parent / "results"
SPINE = {"spine1": 3, "spine2": 6, "spine3": 9}


def twist_medians(pose: torch.Tensor) -> dict[str, float]:
    """Median twist magnitude (deg) about +Y of spine1-3 and of their product, local rotations
    ``pose`` ``(T, 24, 3, 3)``."""
    from wearpose.geometry import RAD_TO_DEG, twist_angle

    y = torch.tensor([0.0, 1.0, 0.0])
    P = pose.double()
    out = {n: float(twist_angle(P[:, j], y).median()) * RAD_TO_DEG for n, j in SPINE.items()}
    out["spine1 x spine2 x spine3"] = float(twist_angle(P[:, 3] @ P[:, 6] @ P[:, 9], y).median()) * RAD_TO_DEG
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--weights", nargs="+", default=["miposer_cpu"], help="shipped weights or NAME=checkpoint.pt")
    ap.add_argument("--clip", default="cmu_daz/05/05_01")
    ap.add_argument("--seconds", type=float, default=5.0)
    ap.add_argument("--out", default="miposer_twist")
    args = ap.parse_args()
    torch.set_num_threads(1)
    from wearpose.body import BodyModel
    from wearpose.estimators.run import estimate_recording, open_model
    from wearpose.motion import MotionSequence, load_motion
    from wearpose.recording import Recording
    from wearpose.sensors import simulate

    body = BodyModel()
    m = load_motion(args.clip, rest_joints=body.rest_joints())
    n = int(round(args.seconds * m.fps))
    m = MotionSequence(m.pose[:n], m.betas, m.trans[:n], m.fps, m.meta)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rec = Recording.from_simulation(simulate(m, "miposer", body, seed=0), m)
    rows = {"ground truth": twist_medians(m.pose)}
    for w in args.weights:
        name, _, path = w.partition("=")
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            rows[name] = twist_medians(estimate_recording(open_model(path or name), rec).track.local_rot)
    command = "python benchmarks/miposer_twist.py " + " ".join(shlex.quote(a) for a in sys.argv[1:])
    res = {"clip": args.clip, "seconds": args.seconds, "frames": n, "kit": "miposer", "seed": 0, "noise": "default",
           "unit": "deg, median over frames of the twist magnitude about the bone (+Y)", "rows": rows,
           "command": command, "machine": {"platform": platform.platform(), "load_avg": os.getloadavg()}}
    cols = list(next(iter(rows.values())))
    md = (f"# MI-Poser spine twist about the bone (issue 22)\n\n`{command}`\n\n{args.seconds:g} s of `{args.clip}` "
          f"({n} frames), kit miposer simulated with default noise, seed 0; median over frames of each joint's local "
          "twist magnitude about +Y, deg.\n\n| | " + " | ".join(cols) + " |\n|---|" + "---:|" * len(cols) + "\n"
          + "".join(f"| {r} | " + " | ".join(f"{v[c]:.1f}" for c in cols) + " |\n" for r, v in rows.items()))
    RESULTS.mkdir(parents=True, exist_ok=True)
    (RESULTS / f"{args.out}.md").write_text(md)
    (RESULTS / f"{args.out}.json").write_text(json.dumps(res, indent=2))
    print(md)


if __name__ == "__main__":
    main()
