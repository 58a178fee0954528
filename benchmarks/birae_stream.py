"""BiRAE online with uncertainty at 60 Hz: the streamed online mode against the sliding window.

Run: ``python benchmarks/birae_stream.py [--weights birae6_cpu] [--frames 400] [--stride 10]
[--baseline /tmp/old/src] [--skip-eval]``.

1. Latency, one thread: a test clip's six MIMUs (``noise`` scenario) replayed frame by frame,
   interleaved frame by frame (a load spike hits all alike), through ``BiraeEstimator.step`` in
   three set-ups: today's window mode with the config's M MC samples (the figure to beat; also
   from ``--baseline``, an older checkout imported side by side, when given), the window mode
   with M = 0, and ``online="stream"`` (:mod:`wearpose.estimators.birae.streaming`). Median / p99 /
   max ms over the frames with a full window.
2. Accuracy and calibration on the whole test split (``noise`` scenario, the nominal one of
   benchmarks/results/birae_calibration.md), with :func:`wearpose.estimators.birae.evaluate.evaluate`:
   the stream mode on every ``--stride``-th frame (+-1 / +-2 sigma coverage per exp-map component
   with the checkpoint's validation-fitted scale, Pearson r, MPJAE), and the window mode
   (``--window-mc``, default M = 0) and the stream mode on the same every ``--window-stride``-th
   frame for MPJAE and coverage.

Writes ``benchmarks/results/birae_stream.json`` / ``.md`` with the machine reference
(:func:`wearpose.evaluate.latency.reference_timing`) and the load average.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any

import torch
from rich.console import Console

from wearpose.evaluate.latency import import_baseline, latency_stats, machine_info, reference_timing


def _latency(args: argparse.Namespace) -> dict[str, Any]:
    from wearpose.estimators import iter_frames
    from wearpose.estimators.birae import BiraeEstimator
    from wearpose.estimators.birae.data import SCENARIOS, make_recording, synthesize
    from wearpose.estimators.seeding import clip_seed
    from wearpose.motion import load_motion
    from wearpose.weights import weight_path

    path = weight_path(args.weights)
    setups: dict[str, Any] = {}
    M = BiraeEstimator.load(path).config.mc_samples
    if args.baseline:
        Old = import_baseline(args.baseline, "wearpose.estimators.birae").BiraeEstimator
        setups[f"baseline window M={M}"] = Old.load(path)
    setups[f"window M={M}"] = BiraeEstimator.load(path)
    setups["window M=0"] = BiraeEstimator.load(path)
    setups["window M=0"].mc_samples = 0
    setups["stream"] = BiraeEstimator.load(path)
    setups["stream"].set_online("stream")
    est = setups["stream"]
    clip = args.clip
    s = synthesize(load_motion(clip), 60.0, SCENARIOS["noise"], clip_seed(clip, 0, "birae:bench"), channels=True)
    rec = make_recording(s["R_world"], 60.0, s["sim"])
    for e in setups.values():
        e.reset()
    lat: dict[str, list[float]] = {k: [] for k in setups}
    cpu: dict[str, list[float]] = {k: [] for k in setups}
    full = sum(est.window) + 1
    load0 = machine_info()["load_average"]
    for k, frame in enumerate(iter_frames(rec, est.sensor_names)):
        if k >= args.frames:
            break
        for name, e in setups.items():
            t0, c0 = time.perf_counter(), time.thread_time()
            e.step(frame)
            if k >= full:
                lat[name].append(time.perf_counter() - t0)
                cpu[name].append(time.thread_time() - c0)
    stats = {k: latency_stats(v) for k, v in lat.items()}
    # CPU time of the calling thread per step: what the step costs this CPU, nearly free of the
    # waiting for a core that other processes' load adds to wall-clock time.
    stats_cpu = {k: latency_stats(v) for k, v in cpu.items()}
    today = stats[f"window M={M}"]["median_ms"]
    return {"clip": clip, "window": list(est.window), "mc_samples_config": M, "frames_replayed": args.frames,
            "frame_budget_60hz_ms": 1000 / 60, "steps": stats, "steps_cpu": stats_cpu, "load_average_start": load0,
            "load_average_end": machine_info()["load_average"],
            "stream_speedup_vs_window_mc_median": today / stats["stream"]["median_ms"],
            "stream_speedup_vs_window_mc_p99": stats[f"window M={M}"]["p99_ms"] / stats["stream"]["p99_ms"],
            "stream_speedup_vs_window_mc_cpu_median": stats_cpu[f"window M={M}"]["median_ms"] / stats_cpu["stream"]["median_ms"]}


def _accuracy(args: argparse.Namespace) -> dict[str, Any]:
    from wearpose.estimators.birae import BiraeEstimator
    from wearpose.estimators.birae.evaluate import evaluate, public, scenario_recordings, uncertainty_summary
    from wearpose.weights import weight_path

    est = BiraeEstimator.load(weight_path(args.weights))
    recs = scenario_recordings("test", "noise")
    out: dict[str, Any] = {"split": "test", "scenario": "noise", "clips": len(recs), "sigma_scale": est.sigma_scale}
    t0 = time.perf_counter()
    r = evaluate(est, recs, mode="stream", frame_stride=args.stride, keep_uncertainty=True)
    out["stream"] = {**public(r), **_unc(uncertainty_summary(r)), "seconds": time.perf_counter() - t0}
    for M in args.window_mc:
        t0 = time.perf_counter()
        r = evaluate(est, recs, mode="online", frame_stride=args.window_stride, mc_samples=M, keep_uncertainty=True)
        out[f"window_M{M}"] = {**public(r), **_unc(uncertainty_summary(r)), "seconds": time.perf_counter() - t0}
    t0 = time.perf_counter()
    r = evaluate(est, recs, mode="stream", frame_stride=args.window_stride, keep_uncertainty=True)
    out["stream_same_frames_as_window"] = {**public(r), **_unc(uncertainty_summary(r)), "seconds": time.perf_counter() - t0}
    return out


def _unc(rep: dict[str, Any]) -> dict[str, Any]:
    return {"within_1sigma": rep["within_1sigma"], "within_2sigma": rep["within_2sigma"],
            "pearson_r_sigma_error": rep["pearson_r_sigma_error"],
            "groups_within_1sigma": {g: v["within_1sigma"] for g, v in rep["groups"].items()}}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--weights", default="birae6_cpu")
    ap.add_argument("--frames", type=int, default=400, help="frames replayed online (the first window + 1 not timed)")
    ap.add_argument("--stride", type=int, default=10, help="test frames evaluated in the stream mode: every n-th")
    ap.add_argument("--window-stride", type=int, default=60, help="every n-th test frame for the window-mode comparison")
    ap.add_argument("--window-mc", type=int, nargs="*", default=[0],
                    help="MC samples of the window-mode comparison runs (the config's M costs ~6x M = 0)")
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--baseline", type=Path, default=None, help="an older checkout's src/ folder (its window M path)")
    ap.add_argument("--clip", default="cmu_daz/05/05_01", help="the clip replayed online (a test clip)")
    ap.add_argument("--skip-eval", action="store_true", help="latency only")
    ap.add_argument("--skip-latency", action="store_true", help="test-split evaluation only")
    ap.add_argument("--out", type=Path, default=Path(__file__).parent / "results" / "birae_stream.json")
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    res: dict[str, Any] = {"weights": args.weights, "threads": args.threads, "machine": machine_info(),
                           "reference": reference_timing()}
    if not args.skip_latency:
        res["latency"] = _latency(args)
        res["reference_after_latency"] = reference_timing()
    if not args.skip_eval:
        res["test"] = _accuracy(args)
    res["machine_end"] = machine_info()
    Console().print(res)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(res, indent=2) + "\n")
    md = [f"# BiRAE online with uncertainty at 60 Hz ({args.weights}, {args.threads} thread)", "",
          f"Reference: {res['reference']['loop']} best {res['reference']['best_ms']:.1f} ms "
          f"({res['reference']['gflops']:.1f} GFLOP/s) at the start; load average {res['machine']['load_average']} -> "
          f"{res['machine_end']['load_average']}.", ""]
    if "latency" in res:
        L = res["latency"]
        md += [f"Reference after the latency replay: {res['reference_after_latency']['best_ms']:.1f} ms; load average "
               f"{L['load_average_start']} -> {L['load_average_end']}; window {L['window']}.", "",
               f"Online step, {L['frames_replayed']} frames of {L['clip']} replayed interleaved (frames with a full window timed; "
               f"60 Hz budget {L['frame_budget_60hz_ms']:.1f} ms):", "",
               "| set-up | median ms | p99 ms | max ms | CPU median ms | CPU p99 ms |", "| --- | --- | --- | --- | --- | --- |"]
        md += [f"| {k} | {v['median_ms']:.2f} | {v['p99_ms']:.2f} | {v['max_ms']:.2f} | {L['steps_cpu'][k]['median_ms']:.2f} | "
               f"{L['steps_cpu'][k]['p99_ms']:.2f} |" for k, v in L["steps"].items()]
        md += ["", f"Stream vs window M={L['mc_samples_config']}: {L['stream_speedup_vs_window_mc_median']:.1f}x (median), "
               f"{L['stream_speedup_vs_window_mc_p99']:.1f}x (p99), {L['stream_speedup_vs_window_mc_cpu_median']:.1f}x (CPU median).", ""]
    if "test" in res:
        T = res["test"]
        md += [f"Test split ({T['clips']} clips, noise scenario), sigma scale {T['sigma_scale']:.3f} (fitted on validation):", "",
               "| mode | frames | MPJAE all (deg) | distal | tracking | other | +-1 sigma | +-2 sigma | Pearson r |",
               "| --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
        for k in ["stream", "stream_same_frames_as_window"] + [f"window_M{m}" for m in args.window_mc]:
            v = T[k]
            md.append(f"| {k} (every {v['frame_stride']}th) | {v['frames']} | {v['mpjae_all_deg']:.2f} | {v['mpjae_distal_deg']:.2f} | "
                      f"{v['mpjae_tracking_deg']:.2f} | {v['mpjae_other_deg']:.2f} | {100 * v['within_1sigma']:.1f} % | "
                      f"{100 * v['within_2sigma']:.1f} % | {v['pearson_r_sigma_error']:.3f} |")
    args.out.with_suffix(".md").write_text("\n".join(md) + "\n")


if __name__ == "__main__":
    main()
