"""MI-Poser online latency on CPU with shipped weights: ``MiposerEstimator.step`` at 60 Hz.

Run: ``python benchmarks/miposer_latency.py [--weights miposer_cpu] [--threads 1] [--frames 300]``.

A held-out test clip (after the 1 s T-pose) is simulated at the kit's rates (headset 60 Hz,
wrist EM 120 Hz, default noise), calibrated on its T-pose, and replayed frame by frame
(:func:`wearpose.estimators.miposer.frames`) through ``step`` with MIM off and on, the two
replays *interleaved frame by frame* so a load spike on this shared machine hits both alike.
Per set-up: wall-clock median / p99 / max per step and the calling thread's CPU time per step
(``time.thread_time``, which waiting for a core does not inflate), the MIM share (on minus off),
and the offline ``estimate`` throughput. Writes ``benchmarks/results/miposer_latency.json``.
Paper (MacBook Pro, Python): IK 4.2 ms per frame, MIM detection 0.09 ms + correction 0.5 ms.
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


def _stats(x: list[float]) -> dict[str, float]:
    ms = np.array(x[5:]) * 1000  # first frames include lazy allocations
    return {"median_ms": float(np.median(ms)), "p99_ms": float(np.percentile(ms, 99)), "max_ms": float(ms.max()),
            "mean_ms": float(ms.mean()), "frames": int(len(ms))}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--weights", default="miposer_cpu")
    ap.add_argument("--clip", default="cmu_daz/05/05_01")
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--frames", type=int, default=300)
    ap.add_argument("--out", type=Path, default=Path(__file__).parent / "results" / "miposer_latency.json")
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    from wearpose.estimators.seeding import clip_seed
    from wearpose.estimators.miposer import MiposerEstimator, frames
    from wearpose.estimators.miposer.data import simulate_clip
    from wearpose.motion import load_motion

    p = Path(args.weights)
    if not p.suffix:
        from wearpose.weights import weight_path

        p = weight_path(args.weights)
    off = MiposerEstimator.load(p)
    on = MiposerEstimator.load(p, mim=True)
    seq = load_motion(args.clip, rest_joints=off.body.rest_joints())
    r = simulate_clip(seq, off.config, off.body, clip_seed(args.clip, 0, "bench"), native_rates=True)
    rec = r["recording"]
    fr = list(frames(rec, off.kit_name))[: args.frames]
    wall = {"off": [], "on": []}
    cpu = {"off": [], "on": []}
    for e in (off, on):
        e.reset()
        e.set_calibration(r["calibration"])
    for f in fr:
        for k, e in (("off", off), ("on", on)):
            t0, c0 = time.perf_counter(), time.thread_time()
            e.step(f)
            wall[k].append(time.perf_counter() - t0)
            cpu[k].append(time.thread_time() - c0)
    t0 = time.perf_counter()
    track = off.estimate(rec, calibration=r["calibration"])
    offline = time.perf_counter() - t0
    res = {"weights": str(p), "clip": args.clip, "frames": len(fr), "threads": args.threads,
           "machine": {"platform": platform.platform(), "load_avg": os.getloadavg(), "cpus": os.cpu_count()},
           "mim_fallback": getattr((on._mims or [None])[0], "fallback", None),
           "step_mim_off": {"wall": _stats(wall["off"]), "cpu": _stats(cpu["off"])},
           "step_mim_on": {"wall": _stats(wall["on"]), "cpu": _stats(cpu["on"])},
           "mim_added_cpu_ms_median": float(np.median(np.array(cpu["on"][5:]) - np.array(cpu["off"][5:])) * 1000),
           "mim_added_cpu_ms_mean": float((np.mean(cpu["on"][5:]) - np.mean(cpu["off"][5:])) * 1000),
           "offline_estimate": {"frames": track.num_frames, "seconds": offline, "fps": track.num_frames / offline}}
    t = Table(title=f"MI-Poser step latency ({args.threads} thread, load {os.getloadavg()[0]:.1f})")
    for c in ("set-up", "wall median ms", "wall p99 ms", "CPU median ms", "CPU mean ms"):
        t.add_column(c)
    for k in ("off", "on"):
        s = res[f"step_mim_{k}"]
        t.add_row(f"step, MIM {k}", f"{s['wall']['median_ms']:.2f}", f"{s['wall']['p99_ms']:.2f}",
                  f"{s['cpu']['median_ms']:.2f}", f"{s['cpu']['mean_ms']:.2f}")
    Console().print(t)
    print(f"MIM adds {res['mim_added_cpu_ms_mean']:.3f} ms CPU per 60 Hz frame (mean; two wrists); offline "
          f"{res['offline_estimate']['fps']:.0f} frames/s")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(res, indent=2))


if __name__ == "__main__":
    main()
