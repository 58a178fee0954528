"""MIM's per-frame cost (MI-Poser's metal-interference mitigation, online) against an older checkout.

Run: ``python benchmarks/mim_cost.py --baseline /tmp/old/src [--frames 3000] [--out PATH]``
(``git worktree add /tmp/old <commit>`` gives a baseline). Times
:func:`wearpose.estimators.miposer.mim.step_mim` -- what ``MiposerEstimator.step`` adds with
``mim=True``: both wrists' MIM step plus the tensor conversions -- for the estimator's default
config (``position="none"``) and for the Kalman ``"fusion"`` position correction, on one
synthetic 120 Hz stream with short and long interference bursts, this checkout's code and the
baseline's called alternately frame by frame (load hits both alike). Records the outputs'
largest difference, the machine reference and the load. Writes ``OUT.json`` and ``OUT.md``.
"""

from __future__ import annotations

import argparse
import inspect
import json
import shlex
import sys
from pathlib import Path
from types import SimpleNamespace
from typing import Any, Callable

import numpy as np
import torch

from wearpose.evaluate.latency import (baseline_modules, import_baseline, latency_stats, machine_info,
                                       reference_timing, time_calls)

FPS = 120.0
NAMES = ("head", "left_wrist", "right_wrist")


def _stream(T: int, seed: int = 0) -> tuple[np.ndarray, ...]:
    """Wrist rotations (T, 2, 3, 3) with interference bursts (20 frames of 10-17 deg, then 2 s of
    17 deg), positions (T, 2, 3), gyro and acc (T, 2, 3)."""
    from wearpose.geometry import axis_angle_to_matrix

    rng = np.random.default_rng(seed)
    w = np.cumsum(rng.normal(0, 0.3, (T, 2, 3)), 0) * 0.05
    R = axis_angle_to_matrix(torch.from_numpy(np.cumsum(w, 0) / FPS)).numpy()
    Ri = R.copy()
    for start, length in ((int(0.2 * T), 20), (int(0.5 * T), 240)):
        bump = axis_angle_to_matrix(torch.tensor([0.3, 0.0, 0.0], dtype=torch.float64)).numpy()
        Ri[start:start + length] = Ri[start:start + length] @ bump
    p = np.cumsum(rng.normal(0, 0.002, (T, 2, 3)), 0)
    return Ri, p, w + rng.normal(0, 0.01, (T, 2, 3)), rng.normal(0, 0.5, (T, 2, 3))


def _stepper(step_mim: Callable[..., Any], data: tuple[np.ndarray, ...], cfg: Any,
             outs: list[Any]) -> Callable[[], None]:
    """One call = one frame of ``step_mim`` (both wrists), cycling through the stream."""
    R, p, gyro, acc = data
    T = R.shape[0]
    state = {"t": 0, "mims": [None, None]}
    takes_cols = "cols" in inspect.signature(step_mim).parameters
    Rh = np.eye(3)[None]

    def call() -> None:
        t = state["t"]
        Rt = torch.from_numpy(np.concatenate([Rh, R[t]]).astype(np.float32))
        pt = torch.from_numpy(np.concatenate([np.zeros((1, 3)), p[t]]).astype(np.float32))
        frame = SimpleNamespace(names=NAMES, channels={"angular_velocity": np.concatenate([np.zeros((1, 3)), gyro[t]]),
                                                       "acceleration": np.concatenate([np.zeros((1, 3)), acc[t]])})
        cols = (range(len(NAMES)),) if takes_cols else ()  # the frame's columns (newer step_mim takes them)
        Ro, po, _ = step_mim(state["mims"], frame, NAMES, *cols, Rt, pt, 1.0 / FPS, cfg)
        if len(outs) < T:
            outs.append((Ro, po))
        state["t"] = (t + 1) % T
        if state["t"] == 0:
            state["mims"] = [None, None]
    return call


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--baseline", type=Path, required=True, help="an older checkout's src/ folder")
    ap.add_argument("--frames", type=int, default=3000, help="frames timed per config and version")
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--out", type=Path, default=Path(__file__).parent / "results" / "mim_cost")
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    from wearpose.estimators.miposer import mim as new
    from wearpose.interference import MIMConfig

    old = import_baseline(args.baseline, "wearpose.estimators.miposer.mim")
    with baseline_modules(old):
        from wearpose.interference import MIMConfig as OldConfig
    data = _stream(args.frames)
    machine = machine_info()
    rows = {}
    for name, kw in (("default (position none)", {"position": "none"}), ("fusion", {"position": "fusion"})):
        outs_new: list[Any] = []
        outs_old: list[Any] = []
        fns = {"new": _stepper(new.step_mim, data, MIMConfig(**kw), outs_new),
               "baseline": _stepper(old.step_mim, data, OldConfig(**kw), outs_old)}
        with baseline_modules(old):  # the baseline's MIM objects (and forecaster) made by its own code
            fns["baseline"]()
        fns["new"]()
        times = time_calls(fns, args.frames - 1, warmup=0)
        st = {k: latency_stats(v) for k, v in times.items()}
        diff = max(max(float((a[0] - b[0]).abs().max()), float((a[1] - b[1]).abs().max()))
                   for a, b in zip(outs_new, outs_old))
        rows[name] = {**st, "speedup_median": st["baseline"]["median_ms"] / st["new"]["median_ms"],
                      "max_abs_diff": diff}
    res = {"title": "MIM per-frame cost (step_mim, 2 wrists) against a baseline checkout",
           "command": shlex.join(["python", "benchmarks/mim_cost.py", *sys.argv[1:]]),
           "baseline": str(args.baseline), "frames": args.frames, "threads": args.threads, "rows": rows,
           "reference": reference_timing(), "machine": {**machine, "load_average_end": machine_info()["load_average"]}}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.with_suffix(".json").write_text(json.dumps(res, indent=2) + "\n")
    lines = [f"# {res['title']}", "", f"Produced by `{res['command']}`", "",
             "| config | this median ms | this p99 ms | baseline median ms | baseline p99 ms | speed-up | max diff |",
             "| --- | ---: | ---: | ---: | ---: | ---: | ---: |"]
    for name, r in rows.items():
        lines.append(f"| {name} | {r['new']['median_ms']:.3f} | {r['new']['p99_ms']:.3f} | "
                     f"{r['baseline']['median_ms']:.3f} | {r['baseline']['p99_ms']:.3f} | {r['speedup_median']:.2f}x | "
                     f"{r['max_abs_diff']:.1e} |")
    load = ", ".join(f"{x:.2f}" for x in machine["load_average"])
    lines += ["", f"{args.frames} frames per version at {FPS:g} Hz, the two versions called alternately; "
              f"{args.threads} thread(s). Machine reference: {res['reference']['best_ms']:.1f} ms best; load average "
              f"{load} at the start.", ""]
    args.out.with_suffix(".md").write_text("\n".join(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
