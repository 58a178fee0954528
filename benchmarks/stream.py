"""Load and fault benchmark of the streaming server over loopback.

Run: ``python benchmarks/stream.py [--duration 600] [--stride 1] [--malformed 0.01] ...``
(the default 10 minutes per scenario; CI never runs it).

Scenarios:

- ``em12``: 12 EM sensors at 120 Hz (a held-out test clip simulated with default EM noise and a
  synthetic subject's offsets, looped) -> ``wearpose serve --model empose12_cpu``, every frame
  estimated (``--stride 1``; the weights were trained at 30 Hz).
- ``em12-auto``: the same stream, the server estimating every 4th frame (``--stride auto``:
  the weights' trained 30 Hz); the other frames are counted ``decimated``, not lost.
- ``em12-null``: the same stream through a pass-through estimator (``--model null``): the
  server's own overhead and the transport, without the network.
- ``imu6``: 6 IMUs at 60 Hz -> ``--imu-weights`` (default ``pip_cpu``: PIP with its physics
  optimizer, as shipped); reported as pending when no IMU weights are shipped.

The server runs in its own process (``python -m wearpose.cli serve``, as a user starts it); the
replay client (:func:`wearpose.stream.replay`) paces frames at real time, injects 1 % malformed
messages (extra messages: no real frame is withheld), random sensor dropouts and a few swapped
frames, and times every frame from send to its pose coming back. Latency is split into
``compute_ms`` (the estimator's ``step``), ``queue_ms`` (waiting for the estimator, incl. the
thread hand-off) and ``transport_ms`` (everything outside the server: encode, loopback, decode,
the client's event loop). CPU use of both processes comes from psutil (100 % = one core).
The server's own per-stage breakdown (``server_stats.stages_ms``: reorder, queue, compute, encode,
send; with each stage's mean over the slowest 1 % of frames), its GC pauses (``server_stats.gc``)
and the client's (``client_gc``), the slowest 1 % of frames split by stage (``tail_top1pct``),
the first two seconds' frames split the same way with their slowest frame (``first_two_seconds``)
and the load average sampled during the run (``load_average_samples``) say where a tail comes from.
Writes ``benchmarks/results/stream.json`` and prints a table.

``--hostile``: the hostile soak instead (``benchmarks/stream_hostile.py``: two honest subjects
beside a foreign-Origin page, a usurper, oversize, malformed and flooding clients and a slow
subscriber, then CPU starvation); writes ``benchmarks/results/stream_hostile.{md,json}``.
"""

from __future__ import annotations

import argparse
import asyncio
import gc
import json
import os
import platform
import signal
import subprocess
import sys
import time
import warnings
from pathlib import Path
from typing import Any

import psutil
import torch
from rich.console import Console
from rich.table import Table

from wearpose.stream import Faults, replay
from wearpose.stream.server import GcPauses

ROOT = Path(__file__).resolve().parents[1]


def kit_recording(clip: str, kit: str, rate: float, seed: int) -> Any:
    """``clip`` as simulated ``kit`` sensors at ``rate`` Hz (default noise, random EM subject offsets)."""
    from wearpose.body import BodyModel
    from wearpose.motion import load_motion, resample
    from wearpose.recording import Recording
    from wearpose.sensors import simulate

    body = BodyModel()
    m = load_motion(clip, rest_joints=body.rest_joints())
    m = resample(m, rate)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sim = simulate(m, kit, body, seed=seed, noise="default", offsets="random", rate=rate)
    return Recording.from_simulation(sim, m)


def imu_weights(preferred: str) -> str | None:
    from wearpose.weights import card, list_weights

    names = list_weights()
    if preferred in names:
        return preferred
    return next((w for w in names if card(w).get("kit") == "imu6"), None)


def git_state() -> dict[str, Any]:
    """The commit and whether the code the benchmark runs (src/) had uncommitted edits."""
    def run(*cmd: str) -> str:
        try:
            return subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=10).stdout.strip()
        except (OSError, subprocess.SubprocessError):
            return ""
    dirty = run("git", "status", "--porcelain", "--", "src")
    return {"commit": run("git", "rev-parse", "HEAD"), "src_uncommitted": dirty.splitlines()}


def cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def start_server(model: str, stride: str, workers: int, threads: int, warmup: int,
                 settings: list[str] | None = None) -> tuple[subprocess.Popen, str]:
    cmd = [sys.executable, "-m", "wearpose.cli", "serve", "--model", model, "--port", "0", "--stride", stride,
           "--workers", str(workers), "--threads", str(threads), "--warmup", str(warmup), "--log-level", "ERROR"]
    for kv in settings or []:
        cmd += ["--set", kv]
    env = {**os.environ, "OMP_NUM_THREADS": str(threads), "MKL_NUM_THREADS": str(threads)}
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, text=True, cwd=ROOT, env=env)
    line = proc.stdout.readline()
    if " on ws://" not in line:
        proc.kill()
        raise RuntimeError(f"server did not start: {line!r}")
    return proc, line.strip().split(" on ")[1].split(" and ")[0]


def run_scenario(name: str, rec: Any, model: str, args: argparse.Namespace, stride: str) -> dict[str, Any]:
    gc.collect()
    gc.freeze()  # the recording and modules: out of the client's collections during the run
    proc, url = start_server(model, stride, args.workers, args.threads, args.warmup, args.set)
    gc_client = GcPauses().install()  # the client's pauses while it streams
    sp, me = psutil.Process(proc.pid), psutil.Process()
    c0s, c0c, t0 = sp.cpu_times(), me.cpu_times(), time.perf_counter()
    faults = Faults(malformed=args.malformed, dropout=args.dropout, dropout_frames=(1, 30), reorder=args.reorder,
                    seed=args.seed)
    last = [time.perf_counter()]
    loads: list[float] = [round(os.getloadavg()[0], 2)]

    def progress(k: int, n: int) -> None:
        if time.perf_counter() - last[0] > 30:
            last[0] = time.perf_counter()
            loads.append(round(os.getloadavg()[0], 2))
            print(f"  {name}: {k}/{n} frames, load {loads[-1]}", flush=True)

    try:
        res = asyncio.run(replay(rec, url, subject=0, fmt=args.format, realtime=True, duration=args.duration,
                                 faults=faults, progress=progress, drain_timeout=args.drain))
        wall = time.perf_counter() - t0
        c1s, c1c = sp.cpu_times(), me.cpu_times()
    finally:
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(30)
        except subprocess.TimeoutExpired:
            proc.kill()
    cpu = lambda a, b: round(100.0 * ((b.user - a.user) + (b.system - a.system)) / wall, 1)  # noqa: E731
    res["cpu_percent_of_one_core"] = {"server": cpu(c0s, c1s), "client": cpu(c0c, c1c)}
    res["wall_s"] = round(wall, 1)
    res["load_average_samples"] = loads + [round(os.getloadavg()[0], 2)]
    res["client_gc"] = gc_client.stats()
    gc.callbacks.remove(gc_client._callback)
    res["model"] = model
    res["server_exit_code"] = proc.returncode
    res["server_stride_option"] = stride
    est_hz = res["ready"]["estimator_fps"]
    period_ms = 1000.0 * res["ready"]["stride"] / res["rate_hz"]
    estimated = int(res["server_stats"].get("estimated", 0))
    server_cpu_s = (c1s.user - c0s.user) + (c1s.system - c0s.system)
    # Keeping up is about throughput: poses estimated per second of the run against the frames due.
    res["estimated_per_s"] = round(estimated / wall, 2)
    res["due_per_s"] = round(res["frames_expected"] / args.duration, 2)
    res["server_cpu_ms_per_estimated_frame"] = round(1000.0 * server_cpu_s / max(1, estimated), 3)
    mean_ms = res["compute_ms"]["mean"]
    res["estimator_keeps_up"] = bool(mean_ms is not None and mean_ms < period_ms and res["frames_lost"] == 0
                                     and not res["gave_up_waiting"])
    res["notes"] = [
        f"estimator step wall time mean {mean_ms} ms / median {res['compute_ms']['median']} ms (server CPU "
        f"{res['server_cpu_ms_per_estimated_frame']} ms per estimated frame) vs frame period {period_ms:.2f} ms "
        f"at {res['rate_hz']:.0f} Hz / stride {res['ready']['stride']}: "
        + ("keeps up" if res["estimator_keeps_up"] else
           f"did NOT keep up ({res['estimated_per_s']} estimated/s vs {res['due_per_s']} due/s): frames queued at the "
           f"server (none dropped by it: {res['frames_lost_by_server']} lost/late), latency grew; "
           f"{res['frames_queued_at_server_at_end']} were still queued when the client stopped waiting"),
        f"the weights were trained at {est_hz:g} Hz; {res['ready']['note'] or 'rates match'}" if est_hz else
        "pass-through estimator: the figures are the server's own overhead and the transport",
        f"machine load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores at the end of the scenario: "
        "step wall times include waiting for a core",
    ]
    return res


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--duration", type=float, default=600.0, help="seconds streamed per scenario")
    ap.add_argument("--scenarios", default="em12,em12-auto,em12-null,imu6",
                    help="em12: EM-POSE on every 120 Hz frame (--stride); em12-auto: EM-POSE at its trained rate "
                         "(server --stride auto); em12-null: pass-through estimator (server + transport only); imu6")
    ap.add_argument("--weights", default="empose12_cpu")
    ap.add_argument("--imu-weights", default="pip_cpu", help="weights of the imu6 scenario")
    ap.add_argument("--warmup", type=int, default=30, help="server --warmup (synthetic steps before ready)")
    ap.add_argument("--set", action="append", default=None, metavar="KEY=VALUE",
                    help="server --set (repeatable), e.g. --set refine_steps=3 (EM-POSE's refinement)")
    ap.add_argument("--clip", default="cmu_daz/05/05_01", help="a test-split clip (looped)")
    ap.add_argument("--rate", type=float, default=120.0, help="EM sensor rate, Hz")
    ap.add_argument("--stride", default="1", help="server --stride: 1 = estimate every frame")
    ap.add_argument("--format", default="binary", choices=("binary", "json"))
    ap.add_argument("--malformed", type=float, default=0.01)
    ap.add_argument("--dropout", type=float, default=0.001, help="per sensor and frame: start of a 1-30 frame dropout")
    ap.add_argument("--reorder", type=float, default=0.005)
    ap.add_argument("--drain", type=float, default=120.0,
                    help="seconds to wait after the last frame for the remaining poses (estimator backlog)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", type=Path, default=None, help="default results/stream.json (--hostile: stream_hostile.json)")
    ap.add_argument("--hostile", action="store_true",
                    help="the hostile soak (benchmarks/stream_hostile.py): two honest em12 subjects for --duration "
                         "beside hostile clients, then --starve-duration of CPU starvation")
    ap.add_argument("--starve-duration", type=float, default=60.0, help="--hostile: seconds of the starvation phase")
    ap.add_argument("--hostile-model", default="null",
                    help="--hostile: estimator of the two honest subjects (null: pass-through; or empose12_cpu)")
    ap.add_argument("--busy", type=int, default=2, help="--hostile: busy-loop processes pinned with the server")
    args = ap.parse_args()
    torch.set_num_threads(1)
    if args.out is None:
        args.out = Path(__file__).parent / "results" / ("stream_hostile.json" if args.hostile else "stream.json")
    if args.hostile:
        sys.path.insert(0, str(Path(__file__).parent))
        import stream_hostile

        machine = {"platform": platform.platform(), "cpu_model": cpu_model(), "cpus": os.cpu_count(),
                   "python": platform.python_version(), "torch": torch.__version__,
                   "load_average_start": [round(x, 2) for x in os.getloadavg()]}
        rec = kit_recording(args.clip, "em12", args.rate, args.seed)
        res = stream_hostile.run(args, rec, ROOT, git_state(), machine)
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps(res, indent=2, default=str) + "\n")
        md = stream_hostile.markdown(res)
        args.out.with_suffix(".md").write_text(md)
        print(md)
        print(f"wrote {args.out} and {args.out.with_suffix('.md')}")
        raise SystemExit(0 if res["passed"] else 1)
    out: dict[str, Any] = {
        "command": "python benchmarks/stream.py " + " ".join(sys.argv[1:]),
        "git": git_state(),
        "targets": {"frames_lost": 0, "latency_p99_ms": 10.0},
        "machine": {"platform": platform.platform(), "cpu_model": cpu_model(), "cpus": os.cpu_count(),
                    "python": platform.python_version(), "torch": torch.__version__,
                    "load_average_start": [round(x, 2) for x in os.getloadavg()],
                    "cpu_affinity": sorted(os.sched_getaffinity(0)),
                    "env": {k: os.environ.get(k) for k in ("OMP_NUM_THREADS", "MKL_NUM_THREADS")},
                    "utc_start": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())},
        "scenarios": {},
    }
    names = args.scenarios.split(",")
    for name in names:
        if name not in ("em12", "em12-auto", "em12-null", "imu6"):
            raise SystemExit(f"unknown scenario {name!r}")
    # Every recording is simulated before the first scenario, so the scenarios run back to back.
    em12 = kit_recording(args.clip, "em12", args.rate, args.seed) if any(n.startswith("em12") for n in names) else None
    imu_w = imu_weights(args.imu_weights) if "imu6" in names else None
    imu6 = kit_recording(args.clip, "imu6", 60.0, args.seed) if imu_w is not None else None

    def write(complete: bool) -> None:
        out["complete"] = complete
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps(out, indent=2, default=str))

    for name in names:
        if name.startswith("em12"):
            model, stride = {"em12": (args.weights, args.stride), "em12-auto": (args.weights, "auto"),
                             "em12-null": ("null", "1")}[name]
            rec = em12
        elif imu_w is None:
            out["scenarios"][name] = {"status": "pending: no shipped IMU (imu6) estimator weights in this build"}
            continue
        else:
            model, stride, rec = imu_w, "1", imu6
        print(f"scenario {name}: {model}, stride {stride}", flush=True)
        t_start = time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())
        r = run_scenario(name, rec, model, args, stride)
        r["utc_start"], r["utc_end"] = t_start, time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())
        r["meets_targets"] = bool(r["frames_lost"] == 0 and r["latency_ms"]["p99"] is not None
                                  and r["latency_ms"]["p99"] < 10.0)
        out["scenarios"][name] = r
        write(False)  # a partial result survives an interrupted run
    out["machine"]["load_average_end"] = [round(x, 2) for x in os.getloadavg()]
    out["machine"]["utc_end"] = time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())
    tab = Table(title=f"stream benchmark, {args.duration:g} s per scenario, loopback, {args.format} packets")
    for c in ("scenario", "sent", "poses", "lost", "e2e med/p99/max ms", "compute med/p99", "queue p99",
              "transport p99", "cpu srv/cli %", "targets"):
        tab.add_column(c)
    for name, r in out["scenarios"].items():
        if "latency_ms" not in r:
            tab.add_row(name, *["-"] * 8, r["status"])
            continue
        L, C = r["latency_ms"], r["compute_ms"]
        tab.add_row(name, str(r["frames_sent"]), str(r["poses_received"]), str(r["frames_lost"]),
                    f"{L['median']}/{L['p99']}/{L['max']}", f"{C['median']}/{C['p99']}", str(r["queue_ms"]["p99"]),
                    str(r["transport_ms"]["p99"]),
                    f"{r['cpu_percent_of_one_core']['server']}/{r['cpu_percent_of_one_core']['client']}",
                    "met" if r["meets_targets"] else "MISSED")
    Console(width=180).print(tab)
    stages = Table(title="server stages, ms: median / p99 (mean over the slowest 1 % of frames)")
    stages.add_column("scenario")
    for c in ("reorder", "queue", "compute", "encode", "send", "server GC max ms", "client GC max ms"):
        stages.add_column(c)
    for name, r in out["scenarios"].items():
        st = r.get("server_stats", {}).get("stages_ms") or {}
        if st:
            stages.add_row(name, *[f"{v['median']} / {v['p99']} ({v['mean_in_top1pct']})" for v in st.values()],
                           str(r["server_stats"]["gc_since_ready"]["max_ms"]), str(r["client_gc"]["max_ms"]))
    Console(width=180).print(stages)
    write(True)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
