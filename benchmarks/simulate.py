"""Sensor simulation throughput: simulated sensor-frames per second per core, for each kit.

Run: ``python benchmarks/simulate.py [--seconds S] [--repeats N]``. Prints a table and writes
``benchmarks/results/simulate.json``.

Workload: a synthetic motion (smooth random joint angles + a walking root, 60 fps, ``--seconds``
long; the corpus is not needed) on the embedded body (float32), simulated with every
registered kit at its own rates (the motion is resampled to 120 Hz for EM/MI-Poser sensors),
with the default noise and with ``noise="none"``. One thread (``torch.set_num_threads(1)``), so
the figure is per core. A *sensor-frame* is one sample of one sensor; the time includes
resampling, ``body.sites`` and every simulator.
"""

from __future__ import annotations

import argparse
import json
import math
import platform
import time
import warnings
from pathlib import Path

import torch

from wearpose.body import BodyModel
from wearpose.geometry import axis_angle_to_matrix
from wearpose.motion.sequence import MotionSequence
from wearpose.sensors import list_kits, simulate


def synthetic_motion(seconds: float, fps: float = 60.0, seed: int = 0) -> MotionSequence:
    T = int(round(seconds * fps))
    g = torch.Generator().manual_seed(seed)
    t = torch.arange(T, dtype=torch.float64) / fps
    a = 0.5 * torch.rand(24, 3, generator=g, dtype=torch.float64)
    f = 0.2 + 1.3 * torch.rand(24, 3, generator=g, dtype=torch.float64)
    ph = 2 * math.pi * torch.rand(24, 3, generator=g, dtype=torch.float64)
    pose = axis_angle_to_matrix(a * torch.sin(2 * math.pi * f * t[:, None, None] + ph)).float()
    trans = torch.stack([0.8 * t, 0.03 * torch.sin(4 * math.pi * t), 0.3 * torch.sin(0.3 * t)], -1).float()
    return MotionSequence(pose, torch.zeros(10), trans, fps, {"source": "synthetic benchmark motion"})


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seconds", type=float, default=60.0, help="motion length (default 60 s)")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--out", type=Path, default=Path(__file__).parent / "results" / "simulate.json")
    args = ap.parse_args()
    torch.set_num_threads(1)
    body = BodyModel()
    motion = synthetic_motion(args.seconds)
    rows = []
    warnings.simplefilter("ignore")  # em12's documented shoulder-site substitution
    with torch.no_grad():
        for kit in list_kits():
            for noise in ("default", "none"):
                simulate(motion, kit, body, seed=0, noise=noise)  # warm-up
                best, frames = float("inf"), 0
                for r in range(args.repeats):
                    t0 = time.perf_counter()
                    res = simulate(motion, kit, body, seed=r, noise=noise)
                    best = min(best, time.perf_counter() - t0)
                    frames = res.num_sensor_frames
                rows.append({"kit": kit, "noise": noise, "sensors": len(res.sensors), "sensor_frames": frames,
                             "seconds": best, "sensor_frames_per_s_per_core": frames / best,
                             "motion_seconds_per_s": args.seconds / best})
    head = f"{'kit':<10}{'noise':<9}{'sensors':>8}{'sensor-frames':>15}{'time s':>9}{'frames/s/core':>15}{'x realtime':>12}"
    print(head)
    print("-" * len(head))
    for r in rows:
        print(f"{r['kit']:<10}{r['noise']:<9}{r['sensors']:>8}{r['sensor_frames']:>15}{r['seconds']:>9.3f}"
              f"{r['sensor_frames_per_s_per_core']:>15,.0f}{r['motion_seconds_per_s']:>12.0f}")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps({
        "benchmark": "sensors.simulate", "motion": f"synthetic, {args.seconds} s at 60 fps", "body": body.asset_id,
        "threads": 1, "repeats": args.repeats, "torch": torch.__version__, "python": platform.python_version(),
        "machine": platform.machine(), "processor": platform.processor(), "rows": rows}, indent=2))
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
