"""PIP online latency per frame on CPU: kinematics (the five LSTMs, one frame, states carried) and
physics (one PhysicsOptimizer step: dynamics, QP, update) separately, end to end, and the QP solve
time distribution.

Run: ``taskset -c 0 python benchmarks/pip_latency.py [--weights pip_cpu | --ckpt runs/pip_cpu/best.pt] [--frames N]``.
Simulates a held-out test clip (imu6, default noise), replays it frame by frame through
``PipEstimator.step_tensors`` with physics (dual PD) and times each call (wall clock; the physics
step also in thread CPU time, less inflated when other processes compete for the 2 cores).
Prints a table and writes ``benchmarks/results/pip_latency.json`` with the machine's load
average (a busy machine inflates every wall-clock figure).
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


def _stats(ms: list[float]) -> dict[str, float]:
    a = np.asarray(ms[5:], dtype=np.float64)  # first frames include lazy allocations
    return {"median": float(np.median(a)), "p99": float(np.percentile(a, 99)), "max": float(a.max()),
            "mean": float(a.mean()), "frames": int(a.size)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--weights", default="pip_cpu", help="shipped weights name")
    ap.add_argument("--ckpt", default=None, help="a checkpoint path instead of shipped weights")
    ap.add_argument("--clip", default=None, help="clip id (default: the first walking clip of the test split)")
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--frames", type=int, default=600, help="frames replayed online")
    ap.add_argument("--out", type=Path, default=Path(__file__).parent / "results" / "pip_latency.json")
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    from wearpose.estimators.seeding import clip_seed
    from wearpose.estimators.pip.data import simulate_clip
    from wearpose.estimators.pip.estimator import PipEstimator
    from wearpose.motion import CorpusStore

    path = args.ckpt or str(__import__("wearpose.weights", fromlist=["weight_path"]).weight_path(args.weights))
    est = PipEstimator.load(path, physics=True, dual_pd=True)
    store = CorpusStore()
    clip = args.clip or next(c for c in store.clips(split="test") if "walk" in c)
    r = simulate_clip(store.load(clip), est.config, est.body, clip_seed(clip, 0, "bench"), noise="default")
    T = min(args.frames, int(r["x"].shape[0]))
    est.set_initial_state(r["pose"][0], r["vel"][0].view(24, 3) * est.config.vel_scale, r["trans"][0], r["betas"])
    est.step_tensors(r["acc"][0], r["ori"][0])  # builds the character (not part of the per-frame cost)
    est.reset()
    total, total_cpu, kin, kin_cpu, phys, phys_cpu, qp = [], [], [], [], [], [], []
    for t in range(T):
        t0, c0 = time.perf_counter(), time.thread_time()
        f = est.step_tensors(r["acc"][t], r["ori"][t])
        total.append((time.perf_counter() - t0) * 1000)
        total_cpu.append((time.thread_time() - c0) * 1000)
        kin.append(f.extras["kin_ms"])
        kin_cpu.append(f.extras["kin_cpu_ms"])
        phys.append(f.extras["physics_ms"])
        phys_cpu.append(f.extras["physics_cpu_ms"])
        qp.append(f.extras["qp_ms"])
    def kinematics_only(fast: bool) -> list[float]:
        """Wall ms per frame with physics off; ``fast=False``: the LSTMs in torch (the pre-numpy path)."""
        est.physics, est.fast_step = False, fast
        est.reset()
        ms = []
        for t in range(T):
            t0 = time.perf_counter()
            est.step_tensors(r["acc"][t], r["ori"][t])
            ms.append((time.perf_counter() - t0) * 1000)
        est.fast_step = True
        return ms

    kin_only, kin_torch = kinematics_only(True), kinematics_only(False)
    qa = np.asarray(qp[5:])
    res = {
        "clip": clip, "frames": T, "weights": path, "threads": args.threads, "fps": est.fps,
        "end_to_end_ms": _stats(total), "end_to_end_cpu_ms": _stats(total_cpu), "kinematics_ms": _stats(kin),
        "kinematics_cpu_ms": _stats(kin_cpu), "kinematics_only_step_ms": _stats(kin_only), "kinematics_only_step_torch_ms": _stats(kin_torch),
        "physics_step_ms": _stats(phys), "physics_step_cpu_ms": _stats(phys_cpu), "qp_solve_ms": _stats(qp),
        "qp_histogram_ms": {"edges": [0, 0.25, 0.5, 1, 2, 4, 8, 16, 1e9],
                            "counts": np.histogram(qa, [0, 0.25, 0.5, 1, 2, 4, 8, 16, 1e9])[0].tolist()},
        "acceptance": {"wall_p99_le_16ms": _stats(total)["p99"] <= 16.0, "wall_median_le_5ms": _stats(total)["median"] <= 5.0,
                       "cpu_p99_le_16ms": _stats(total_cpu)["p99"] <= 16.0,
                       "cpu_median_le_5ms": _stats(total_cpu)["median"] <= 5.0},
        "machine": {"cpu": platform.processor() or platform.machine(), "cores": os.cpu_count(),
                    "load_average": list(os.getloadavg()), "affinity": sorted(os.sched_getaffinity(0))},
        "time_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
    }
    tab = Table(title=f"PIP online latency per frame ({T} frames of {clip}, {args.threads} thread, load {os.getloadavg()[0]:.1f})")
    for c in ("part", "median ms", "p99 ms", "max ms"):
        tab.add_column(c)
    for k in ("end_to_end_ms", "end_to_end_cpu_ms", "kinematics_ms", "kinematics_cpu_ms", "kinematics_only_step_ms",
              "kinematics_only_step_torch_ms", "physics_step_ms", "physics_step_cpu_ms", "qp_solve_ms"):
        s = res[k]
        tab.add_row(k, f"{s['median']:.2f}", f"{s['p99']:.2f}", f"{s['max']:.2f}")
    Console().print(tab)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(res, indent=2))
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
