"""BiRAE online latency (sliding window) and offline throughput on CPU.

Run: ``python benchmarks/birae_latency.py [--weights birae6_cpu | --ckpt runs/birae6_cpu/best.pt]
[--threads N] [--frames N] [--window 130 30]``.

Synthesises a test clip's six MIMUs (``noise`` scenario), replays it frame by frame through
``BiraeEstimator.step`` (each call runs the Bi-LSTM over the ``past + 1 + future`` window) with
MC-dropout (the config's M) and without (M = 0), and times each call. The latency of an online
pose is the future window (``future / 60`` s, algorithmic) plus this compute time. Then times the
offline ``estimate`` over the whole clip. Writes ``benchmarks/results/birae_latency.json`` with the
machine's load average (a busy machine inflates every figure).
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


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--weights", default="birae6_cpu")
    ap.add_argument("--ckpt", type=Path, default=None, help="a checkpoint instead of shipped weights")
    ap.add_argument("--clip", default=None, help="clip id (default: the first test clip of >= 10 s)")
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--frames", type=int, default=200, help="frames replayed online")
    ap.add_argument("--window", type=int, nargs=2, default=(130, 30), metavar=("PAST", "FUTURE"))
    ap.add_argument("--out", type=Path, default=Path(__file__).parent / "results" / "birae_latency.json")
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    from wearpose.estimators import iter_frames
    from wearpose.estimators.birae import BiraeEstimator
    from wearpose.estimators.birae.data import SCENARIOS, clip_seed, make_recording, synthesize
    from wearpose.motion import CorpusStore
    from wearpose.weights import weight_path

    est = BiraeEstimator.load(args.ckpt or weight_path(args.weights))
    est.set_window(*args.window)
    store = CorpusStore()
    clip = args.clip or next(c for c in store.clips(split="test") if store.entry(c)["seconds"] >= 10.0)
    s = synthesize(store.load(clip), 60.0, SCENARIOS["noise"], clip_seed(clip, 0, "bench"), channels=True)
    rec = make_recording(s["R_world"], 60.0, s["sim"])
    res = {"weights": str(args.ckpt or args.weights), "clip": clip, "rep": est.config.rep, "hidden": est.config.hidden,
           "window": list(args.window), "algorithmic_latency_ms": 1000.0 * est.latency_s, "threads": args.threads,
           "online": {}}
    for M in (est.config.mc_samples, 0):
        est.mc_samples = M
        est.reset()
        lat = []
        for k, frame in enumerate(iter_frames(rec, est.sensor_names)):
            if k >= args.frames:
                break
            t0 = time.perf_counter()
            est.step(frame)
            lat.append(time.perf_counter() - t0)
        ms = np.array(lat[sum(args.window) + 1:] or lat) * 1000  # full windows only
        res["online"][f"mc{M}"] = {"median_ms": float(np.median(ms)), "p99_ms": float(np.percentile(ms, 99)),
                                    "max_ms": float(ms.max()), "frames_timed": int(len(ms)),
                                    "total_latency_median_ms": 1000.0 * est.latency_s + float(np.median(ms))}
    est.mc_samples = est.config.mc_samples
    t0 = time.perf_counter()
    track = est.estimate(rec)
    res["offline_frames_per_s_mc"] = float(track.num_frames / (time.perf_counter() - t0))
    t0 = time.perf_counter()
    est.estimate(rec, mc_samples=0)
    res["offline_frames_per_s_mc0"] = float(track.num_frames / (time.perf_counter() - t0))
    res["machine"] = {"platform": platform.platform(), "load_average_1m": os.getloadavg()[0], "cpus": os.cpu_count(),
                      "torch": torch.__version__}
    tab = Table(title=f"BiRAE {res['weights']} ({res['rep']}, hidden {res['hidden']}), window {args.window} at 60 Hz, "
                      f"{args.threads} thread(s), load {res['machine']['load_average_1m']:.1f}")
    for c in ("mode", "compute median ms", "p99 ms", "total latency ms (future window + compute)"):
        tab.add_column(c)
    for k, v in res["online"].items():
        tab.add_row(f"online step, {k}", f"{v['median_ms']:.1f}", f"{v['p99_ms']:.1f}", f"{v['total_latency_median_ms']:.0f}")
    tab.add_row("offline (frames/s)", f"{res['offline_frames_per_s_mc']:,.0f} (MC) / {res['offline_frames_per_s_mc0']:,.0f} (M=0)", "", "")
    Console().print(tab)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(res, indent=2) + "\n")


if __name__ == "__main__":
    main()
