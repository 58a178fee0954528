"""Sensor simulation throughput: simulated sensor-frames per second per core, for each kit.

Run: ``python benchmarks/simulate.py [--seconds S] [--repeats N] [--e2e-split val] [--e2e-limit N]``.
Prints tables and writes ``benchmarks/results/simulate.json``.

Workload: a synthetic motion (smooth random joint angles + a walking root, 60 fps, ``--seconds``
long; the corpus is not needed) on the embedded body (float32), simulated with every
registered kit at its own rates (the motion is resampled to 120 Hz for EM/MI-Poser sensors),
with the default noise and with ``noise="none"``. One thread (``torch.set_num_threads(1)``), so
the figure is per core. A *sensor-frame* is one sample of one sensor; the time includes
resampling, ``body.sites`` and every simulator.

End to end (``end_to_end`` rows; skipped when no prepared corpus exists): ``wearpose simulate``'s
library call :func:`wearpose.recording.dataset.simulate_corpus` on the clips of one corpus split
(default ``val``) with kit ``em12``, default noise, into a fresh temporary directory, with 1 and
with 2 worker processes. Wall time includes everything a user waits for: the process pool's
start-up (each worker imports torch and loads the body), loading each clip, simulating,
converting to a Recording and writing the files and the index. ``clips_per_s`` and
``sensor_frames_per_s`` are over that wall time (not per core).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import tempfile
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
    ap.add_argument("--e2e-split", default="val", help="corpus split for the end-to-end rows (default val)")
    ap.add_argument("--e2e-limit", type=int, default=None, help="at most this many clips end to end (default: the whole split)")
    ap.add_argument("--e2e-workers", type=int, nargs="+", default=[1, 2], help="worker counts end to end (default 1 2)")
    args = ap.parse_args()
    torch.set_num_threads(1)
    body = BodyModel()
    motion = synthetic_motion(args.seconds)
    rows = []
    warnings.simplefilter("ignore")  # site substitutions of custom kits (the built-in kits have none)
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
    e2e = end_to_end(args.e2e_split, args.e2e_limit, args.e2e_workers)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps({
        "benchmark": "sensors.simulate", "motion": f"synthetic, {args.seconds} s at 60 fps", "body": body.asset_id,
        "threads": 1, "repeats": args.repeats, "torch": torch.__version__, "python": platform.python_version(),
        "machine": platform.machine(), "processor": platform.processor(), "cpus": os.cpu_count(), "rows": rows,
        "end_to_end": e2e}, indent=2))
    print(f"wrote {args.out}")


def end_to_end(split: str, limit: int | None, worker_counts: list[int]) -> dict:
    """``simulate_corpus`` (what ``wearpose simulate`` runs) on one split, per worker count."""
    from wearpose.errors import WearposeError
    from wearpose.motion import CorpusStore
    from wearpose.recording.dataset import simulate_corpus

    try:
        store = CorpusStore()
    except WearposeError as exc:
        print(f"end to end: skipped ({exc})")
        return {"skipped": str(exc)}
    ids = store.clips(split)[:limit] if limit else store.clips(split)
    motion_s = sum(float(store.entry(c)["seconds"]) for c in ids)
    rows = []
    for w in worker_counts:
        load = os.getloadavg()[0] if hasattr(os, "getloadavg") else None
        with tempfile.TemporaryDirectory(prefix="wearpose-simbench-") as d:
            t0 = time.perf_counter()
            r = simulate_corpus(Path(d) / "set", "em12", split, limit=limit, workers=w, progress=False)
            wall = time.perf_counter() - t0
            sizes = [row["bytes"] / row["seconds"] for row in json.loads((Path(d) / "set" / "index.json").read_text())["clips"].values()
                     if row["seconds"] > 0]
        rows.append({"kit": "em12", "split": split, "clips": r["simulated"], "failed": r["failed"], "workers": w,
                     "motion_seconds": round(motion_s, 1), "sensor_frames": r["sensor_frames"], "wall_s": round(wall, 2),
                     "clips_per_s": round(r["simulated"] / wall, 2), "sensor_frames_per_s": round(r["sensor_frames"] / wall),
                     "motion_seconds_per_s": round(motion_s / wall, 1), "megabytes": round(r["bytes"] / 1e6, 1),
                     "loadavg_1min_before": None if load is None else round(load, 2),
                     "kilobytes_per_motion_second_median": round(sorted(sizes)[len(sizes) // 2] / 1e3, 1) if sizes else None})
    head = f"{'end to end':<12}{'workers':>8}{'clips':>7}{'motion s':>10}{'wall s':>8}{'clips/s':>9}{'sensor-frames/s':>17}{'MB':>7}"
    print()
    print(head)
    print("-" * len(head))
    for r in rows:
        print(f"{'em12 ' + r['split']:<12}{r['workers']:>8}{r['clips']:>7}{r['motion_seconds']:>10.0f}{r['wall_s']:>8.1f}"
              f"{r['clips_per_s']:>9.2f}{r['sensor_frames_per_s']:>17,}{r['megabytes']:>7.1f}")
    return {"call": "wearpose.recording.dataset.simulate_corpus (wearpose simulate), kit em12, noise default, "
                    "offsets random, source pose stored; wall time incl. pool start-up and file writes. Other "
                    "jobs on the machine slow the multi-worker rows (see loadavg_1min_before)", "rows": rows}


if __name__ == "__main__":
    main()
