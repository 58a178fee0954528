"""PIP under the demo's protocol on N clips of a split: what `wearpose demo --kit imu6` does per
clip (IMUs on skin sites, a 1 s calibration T-pose, T-pose calibration, PIP from rest, metrics
on the clip without the prefix), kinematics only unless ``--physics``, for several weights.

The Table 2 benchmarks (``pip_eval.py``) give PIP the known initial state and bone
orientations (the paper's protocol); this one measures what a user with real IMUs meets first.

Run: ``taskset -c 1 python benchmarks/pip_demo_protocol.py --split val --clips 16
--weights runs/pip_w256_aug3/best.pt runs/pip_w256_mix/best.pt --out NAME``.
Writes ``benchmarks/results/pip_demo_protocol_<NAME>.json`` (per-clip rows and means).
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import torch

RESULTS = Path(__file__).resolve().parent / "results"
METRICS = ("sip_error_deg", "angular_error_deg", "mesh_error_cm", "translation_error_cm")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--split", default="val")
    ap.add_argument("--clips", type=int, default=16, help="clips spread evenly over the split")
    ap.add_argument("--weights", nargs="+", required=True, help="shipped weights names or checkpoint paths")
    ap.add_argument("--physics", action="store_true", help="with the physics module (slower)")
    ap.add_argument("--max-seconds", type=float, default=10.0)
    ap.add_argument("--out", required=True)
    a = ap.parse_args(argv)
    torch.set_num_threads(1)
    from wearpose.viewer.demos.pip import run_demo
    from wearpose.motion import CorpusStore

    ids = CorpusStore().clips(split=a.split)
    ids = [ids[int(i * len(ids) / a.clips)] for i in range(min(a.clips, len(ids)))]
    rows: dict[str, list[dict[str, float | str]]] = {w: [] for w in a.weights}
    t0 = time.time()
    with tempfile.TemporaryDirectory() as tmp:
        for cid in ids:
            line = []
            for w in a.weights:
                m = run_demo(cid, tmp, weights=w, max_seconds=a.max_seconds, physics=a.physics)["metrics"]
                rows[w].append({"clip": cid, **{k: float(m[k]) for k in METRICS if k in m}})
                line.append(f"{m['sip_error_deg']:.1f}")
            print(f"{cid:60s} SIP " + " / ".join(line), file=sys.stderr, flush=True)
    means = {w: {k: sum(float(r[k]) for r in rs) / len(rs) for k in METRICS if all(k in r for r in rs)}
             for w, rs in rows.items()}
    print("| weights | " + " | ".join(METRICS) + " |\n|---|" + "---|" * len(METRICS))
    for w, m in means.items():
        print(f"| {w} | " + " | ".join(f"{m[k]:.2f}" if k in m else "-" for k in METRICS) + " |")
    out = {"command": "python " + " ".join([sys.argv[0], *(argv if argv is not None else sys.argv[1:])]),
           "split": a.split, "clips": ids, "physics": a.physics, "max_seconds": a.max_seconds, "means": means,
           "per_clip": rows, "wall_seconds": time.time() - t0}
    path = RESULTS / f"pip_demo_protocol_{a.out}.json"
    path.write_text(json.dumps(out, indent=1))
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
