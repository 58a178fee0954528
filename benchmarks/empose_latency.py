"""EM-POSE online latency and offline throughput on CPU with shipped weights.

Run: ``python benchmarks/empose_latency.py [--weights empose12_cpu] [--threads N] [--frames N]``.
Simulates a held-out test clip (12 EM sensors, default noise) and replays it frame by frame
through ``EmposeEstimator.step`` (LSTM state carried, N LGD updates per frame), timing each call,
for four set-ups replayed *interleaved frame by frame* (so a load spike on this shared machine
hits all of them alike):

- ``lean``: the closed-form dL_r/dOmega (:mod:`wearpose.estimators.empose.fastgrad`, the default);
- ``autograd``: the same network with the gradient through autograd (the previous path);

each at the checkpoint's N and at N = 4 (the paper's 12-sensor setting and the acceptance
figure; the shipped cpu model was trained with N = 3, so N = 4 only times the loop, the update
network being the same at every iteration). The largest difference between the lean and
autograd estimates over the replay is recorded. Then the offline ``estimate`` over the whole clip
is timed (lean and autograd). Prints a table and writes ``benchmarks/results/empose_latency.json``
with the machine's load average (a busy machine inflates every wall-clock figure) and, per
set-up, the calling thread's CPU time per step (``time.thread_time``), which the waiting for a
core on a loaded machine does not inflate.
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
from wearpose.estimators.empose.data import recording_from_clip, simulate_clip
from wearpose.estimators.empose.estimator import EmposeEstimator
from wearpose.estimators.seeding import clip_seed
from wearpose.motion import load_motion
from wearpose.weights import weight_path


def _stats(lat: list[float]) -> dict[str, float]:
    ms = np.array(lat[5:]) * 1000  # first frames include lazy allocations
    return {"median": float(np.median(ms)), "p99": float(np.percentile(ms, 99)), "max": float(ms.max()),
            "frames": int(len(ms))}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--weights", default="empose12_cpu")
    ap.add_argument("--clip", default="cmu_daz/05/05_01")
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--frames", type=int, default=300, help="frames replayed online")
    ap.add_argument("--out", type=Path, default=Path(__file__).parent / "results" / "empose_latency.json")
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    base = EmposeEstimator.load(weight_path(args.weights))
    seq = load_motion(args.clip, rest_joints=base.body.rest_joints())
    r = simulate_clip(seq, base.config, base.body, clip_seed(args.clip, 0, "bench"), noise="default", offsets="random")
    rec = recording_from_clip(r, base.config)
    R, t = base._offsets_from(rec)
    setups: dict[str, EmposeEstimator] = {}
    for n in sorted({base.config.iterations, 4}):
        for path in ("lean", "autograd"):
            est = EmposeEstimator.load(weight_path(args.weights))
            est.model.cfg = est.config.override(iterations=n)  # timing only when n differs from training
            est.model.lean_inference = path == "lean"
            est.set_offsets(R, t)
            est.reset()
            setups[f"{path} N={n}"] = est
    lat: dict[str, list[float]] = {k: [] for k in setups}
    cpu: dict[str, list[float]] = {k: [] for k in setups}
    diff: dict[int, float] = {}
    load0 = os.getloadavg()[0]
    for k, frame in enumerate(iter_frames(rec, base.sensor_names)):
        if k >= args.frames:
            break
        outs = {}
        for name, est in setups.items():
            t0, c0 = time.perf_counter(), time.thread_time()
            outs[name] = est.step(frame)
            lat[name].append(time.perf_counter() - t0)
            cpu[name].append(time.thread_time() - c0)
        for n in {est.model.cfg.iterations for est in setups.values()}:
            a, b = outs[f"lean N={n}"], outs[f"autograd N={n}"]
            d = max(float((a.local_rot - b.local_rot).abs().max()), float((a.betas - b.betas).abs().max()))
            diff[n] = max(diff.get(n, 0.0), d)
    offline = {}
    for path in ("lean", "autograd"):
        est = setups[f"{path} N={base.config.iterations}"]
        t0 = time.perf_counter()
        track = est.estimate(rec)
        offline[path] = float(track.local_rot.shape[0] / (time.perf_counter() - t0))
    online = {k: _stats(v) for k, v in lat.items()}
    online_cpu = {k: _stats(v) for k, v in cpu.items()}
    n_ck = base.config.iterations
    res = {
        "weights": args.weights, "iterations_trained": n_ck, "sensors": len(base.sensor_names),
        "threads": args.threads, "clip": args.clip,
        "online_ms": online,
        # CPU time of the calling thread per step (time.thread_time): what the step costs this
        # CPU, nearly free of the waiting that other processes' load adds to wall-clock time.
        "online_cpu_ms": online_cpu,
        "speedup_median": {f"N={n}": online[f"autograd N={n}"]["median"] / online[f"lean N={n}"]["median"]
                           for n in sorted({n_ck, 4})},
        "max_abs_diff_lean_vs_autograd": {f"N={n}": v for n, v in sorted(diff.items())},
        "offline_frames_per_s": offline,
        "target_online_median_ms": 5.0,
        "acceptance_setup": "lean N=4",
        "machine": {"platform": platform.platform(), "load_average_1m_start": load0,
                    "load_average_1m_end": os.getloadavg()[0], "torch": torch.__version__, "cpus": os.cpu_count()},
    }
    tab = Table(title=f"EM-POSE {args.weights} online step, {res['sensors']} sensors, {args.threads} thread(s), "
                      f"interleaved replay of {args.frames} frames")
    for c in ("set-up", "median ms", "p99 ms", "max ms", "CPU median ms", "CPU p99 ms"):
        tab.add_column(c)
    for k, v in online.items():
        c = online_cpu[k]
        tab.add_row(k, f"{v['median']:.2f}", f"{v['p99']:.2f}", f"{v['max']:.2f}", f"{c['median']:.2f}", f"{c['p99']:.2f}")
    con = Console()
    con.print(tab)
    con.print(f"offline frames/s: lean {offline['lean']:,.0f}, autograd {offline['autograd']:,.0f}; max |lean - autograd| "
              f"{res['max_abs_diff_lean_vs_autograd']}; load average {load0:.2f} -> {os.getloadavg()[0]:.2f}")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(res, indent=2))


if __name__ == "__main__":
    main()
