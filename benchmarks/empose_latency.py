"""EM-POSE online latency and offline throughput on CPU with shipped weights.

Run: ``python benchmarks/empose_latency.py [--weights empose12_cpu] [--threads N] [--frames N]``.
Simulates a held-out test clip (12 EM sensors, default noise), replays it frame by frame through
``EmposeEstimator.step`` (LSTM state carried, N LGD updates per frame) and times each call; then
times the offline ``estimate`` over the whole clip. Prints a table and writes
``benchmarks/results/empose_latency.json`` (with the machine's load average: a busy machine
inflates every figure).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
from pathlib import Path

import numpy as np
import torch
from rich.console import Console
from rich.table import Table

from wearpose.estimators.base import iter_frames
from wearpose.estimators.empose.data import clip_seed, recording_from_clip, simulate_clip
from wearpose.estimators.empose.estimator import EmposeEstimator
from wearpose.motion import load_motion
from wearpose.weights import weight_path


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--weights", default="empose12_cpu")
    ap.add_argument("--clip", default="cmu_daz/05/05_01")
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--frames", type=int, default=300, help="frames replayed online")
    ap.add_argument("--out", type=Path, default=Path(__file__).parent / "results" / "empose_latency.json")
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    est = EmposeEstimator.load(weight_path(args.weights))
    seq = load_motion(args.clip, rest_joints=est.body.rest_joints())
    r = simulate_clip(seq, est.config, est.body, clip_seed(args.clip, 0, "bench"), noise="default", offsets="random")
    rec = recording_from_clip(r, est.config)
    R, t = est._offsets_from(rec)
    est.set_offsets(R, t)
    est.reset()
    lat = []
    for k, frame in enumerate(iter_frames(rec, est.sensor_names)):
        if k >= args.frames:
            break
        t0 = time.perf_counter()
        est.step(frame)
        lat.append(time.perf_counter() - t0)
    lat_ms = np.array(lat[5:]) * 1000  # first frames include lazy allocations
    t0 = time.perf_counter()
    track = est.estimate(rec)
    off_s = time.perf_counter() - t0
    res = {
        "weights": args.weights, "iterations": est.config.iterations, "sensors": len(est.sensor_names),
        "threads": args.threads, "frames_online": int(len(lat_ms)),
        "online_ms": {"median": float(np.median(lat_ms)), "p99": float(np.percentile(lat_ms, 99)), "max": float(lat_ms.max())},
        "offline_frames_per_s": float(track.local_rot.shape[0] / off_s),
        "target_online_median_ms": 5.0,
        "machine": {"platform": platform.platform(), "load_average_1m": os.getloadavg()[0], "torch": torch.__version__},
    }
    tab = Table(title=f"EM-POSE {args.weights}: N={res['iterations']} LGD iterations, {res['sensors']} sensors, {args.threads} thread(s)")
    for c in ("online median ms", "online p99 ms", "online max ms", "offline frames/s", "load avg"):
        tab.add_column(c)
    tab.add_row(f"{res['online_ms']['median']:.1f}", f"{res['online_ms']['p99']:.1f}", f"{res['online_ms']['max']:.1f}",
                f"{res['offline_frames_per_s']:,.0f}", f"{res['machine']['load_average_1m']:.2f}")
    Console().print(tab)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(res, indent=2))


if __name__ == "__main__":
    main()
