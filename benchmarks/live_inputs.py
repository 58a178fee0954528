"""Live device inputs end to end (issue 26 acceptance): for each of LSL, OSC (NGIMU profile),
the Xsens MVN streamer and x-IMU3 (the ximu3 package over TCP), ``wearpose stream emulate INPUT`` plays a simulated recording for 60 s
on 127.0.0.1 into ``wearpose serve --input INPUT`` with a shipped model, as a user starts them
(two processes). A WebSocket subscriber collects every pose; the same model stepping through the
same frames in this process is the reference. Two runs per input: clean (frames lost, every
frame estimated in order, max |pose - reference|), and with 1 % malformed packets and random
sensor dropouts (the server keeps running, each malformed packet counted in /stats, dropouts
masked). The server runs with ``--max-lag 0`` (never shed): on the shared 2-core machine the
estimator may fall behind real time, and every frame is then estimated late rather than shed.

    nice -n 10 python benchmarks/live_inputs.py            # -> benchmarks/results/live_inputs.{md,json}
    nice -n 10 python benchmarks/live_inputs.py --inputs ximu3 --merge   # replace those inputs' rows only

Recordings: the test-split clip ``--clip`` simulated with default noise (EM: identity sensor
offsets, since a device stream carries no subject calibration), looped to 60 s. LSL runs with
the loopback liblsl configuration (``--lsl-loopback``).
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
import urllib.request
import warnings
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))
from stream import cpu_model, git_state  # noqa: E402  (benchmarks/stream.py helpers)

#: input -> (kit, rate Hz, weights, extra serve options, extra emulate options)
CASES: dict[str, tuple[str, float, str, list[str], list[str]]] = {
    "lsl": ("em12", 30.0, "empose12_cpu", ["--lsl-loopback", "--lsl-stream", "wearpose-bench"],
            ["--lsl-loopback", "--lsl-stream", "wearpose-bench"]),
    "osc": ("imu6", 60.0, "pip_cpu", ["--osc-profile", "ngimu", "--device-rate", "60"], ["--osc-profile", "ngimu"]),
    "mvn": ("imu6", 60.0, "pip_cpu", ["--mvn-port", "19763", "--device-rate", "60"], ["--port", "19763"]),
    # x-IMU3 over TCP (the emulated devices listen on 127.0.0.1; the server's ximu3 connections connect)
    "ximu3": ("imu6", 60.0, "pip_cpu", ["--device-rate", "60", "--ximu3-transport", "tcp"], ["--ximu3-transport", "tcp"]),
}


def recording(clip: str, kit: str, rate: float, seed: int = 0) -> Any:
    from wearpose.body import BodyModel
    from wearpose.motion import load_motion, resample
    from wearpose.recording import Recording
    from wearpose.sensors import simulate

    body = BodyModel()
    m = resample(load_motion(clip, rest_joints=body.rest_joints()), rate)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sim = simulate(m, kit, body, seed=seed, noise="default", offsets=None, rate=rate)
    return Recording.from_simulation(sim, m)


def reference(model: str, rec: Any, n: int) -> np.ndarray:
    """The model stepping through frames ``k % T`` for ``k < n`` (the emulator's loop), ``(n, 24, 3, 3)``."""
    from wearpose.estimators.base import iter_frames
    from wearpose.stream import estimator_factory

    frames = list(iter_frames(rec))
    est = estimator_factory(model, threads=1)()
    est.reset()
    return np.stack([est.step(frames[k % len(frames)]).local_rot.numpy() for k in range(n)]).astype(np.float32)


def osc_ports(names: tuple[str, ...], base: int = 19000) -> list[str]:
    return [f"{n}={base + i}" for i, n in enumerate(names)]


def get_stats(url: str, tries: int = 6) -> dict[str, Any]:
    """The server's /stats; a busy server (estimator backlog on a loaded machine) may answer
    late: up to ``tries`` attempts of 30 s each."""
    for k in range(tries):
        try:
            with urllib.request.urlopen(url.replace("ws://", "http://") + "/stats", timeout=30) as r:
                return json.loads(r.read())
        except TimeoutError:
            if k == tries - 1:
                raise
    raise AssertionError("unreachable")


async def collect(url: str, poses: dict[int, np.ndarray], ready: asyncio.Event, stop: asyncio.Event) -> None:
    from wearpose.stream import StreamClient

    def on_pose(t: float, p: Any) -> None:
        poses[p.seq] = np.asarray(p.local_rot, np.float32).copy()

    async with StreamClient(url, on_pose=on_pose) as c:
        await c.subscribe(None, "binary")
        ready.set()
        await stop.wait()


def run(name: str, rec_path: Path, rec: Any, seconds: float, faults: bool, ref: np.ndarray | None,
        wait_s: float = 600.0) -> dict[str, Any]:
    kit, rate, model, serve_opts, emu_opts = CASES[name]
    if name == "osc":
        ports = osc_ports(rec.names)
        serve_opts = serve_opts + [x for p in ports for x in ("--osc-sensor", p)]
        emu_opts = emu_opts + [x for p in ports for x in ("--osc-sensor", p)]
    if name == "mvn":
        serve_opts = serve_opts + ["--mvn-segments", ",".join(rec.names)]
    if name == "ximu3":
        ports = osc_ports(rec.names, 17000)
        serve_opts = serve_opts + [x for p in ports for x in ("--ximu3-sensor", p)]
        emu_opts = emu_opts + [x for p in ports for x in ("--ximu3-sensor", p)]
    cmd = [sys.executable, "-m", "wearpose.cli", "serve", "--model", model, "--port", "0", "--stride", "1", "--max-lag", "0",
           "--input", name, *serve_opts, "--log-level", "ERROR"]
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    srv = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, cwd=ROOT, env=env)
    line = srv.stdout.readline()
    if " on ws://" not in line:
        srv.kill()
        raise RuntimeError(f"{name}: server did not start: {line!r}")
    url = line.strip().split(" on ")[1].split(" and ")[0]
    poses: dict[int, np.ndarray] = {}
    fault_opts = ["--malformed", "0.01", "--dropout", "0.001", "--seed", "1"] if faults else []

    async def main() -> tuple[dict[str, Any], dict[str, Any]]:
        ready, stop = asyncio.Event(), asyncio.Event()
        task = asyncio.create_task(collect(url, poses, ready, stop))
        await ready.wait()
        emu = await asyncio.create_subprocess_exec(
            sys.executable, "-m", "wearpose.cli", "stream", "emulate", name, str(rec_path), "--duration", str(seconds),
            "--json", *emu_opts, *fault_opts, cwd=ROOT, env=env, stdout=asyncio.subprocess.PIPE,
            stderr=asyncio.subprocess.DEVNULL)
        out, _ = await emu.communicate()
        res = json.loads(out)
        # every received frame estimated (or shed) and its pose delivered, then stop
        t_end = time.time() + wait_s
        while time.time() < t_end:
            st = get_stats(url)["subjects"].get("0", {})
            done = st.get("estimated", 0) + st.get("shed", 0) + st.get("estimator_errors", 0)
            if st and done >= st.get("received", 0) and len(poses) >= st.get("published", 0) and st["queue_now"] == 0:
                await asyncio.sleep(1.0)
                if get_stats(url)["subjects"]["0"]["received"] == st["received"]:
                    break
            await asyncio.sleep(0.5)
        stats = get_stats(url)
        stop.set()
        await task
        return res, stats

    t0 = time.time()
    try:
        emu, stats = asyncio.run(main())
    finally:
        srv.send_signal(signal.SIGINT)
        try:
            srv.wait(30)
        except subprocess.TimeoutExpired:
            srv.kill()
    s = stats["subjects"]["0"]
    n = emu["frames_sent"]
    out = {"input": name, "model": model, "kit": kit, "rate_hz": rate, "faults": faults, "wall_s": round(time.time() - t0, 1),
           "frames_sent": n, "poses_received": len(poses), "all_frames_in_order": sorted(poses) == list(range(n)),
           "server": {k: s.get(k) for k in ("received", "estimated", "lost", "late", "duplicate", "shed", "malformed",
                                            "masked_sensor_samples", "estimator_errors", "server_ms", "compute_ms")},
           "malformed_total": stats["malformed_total"], "input_stats": stats["inputs"][0] if stats["inputs"] else None,
           "injected": {"malformed": emu["malformed_sent"], "dropped_sensor_samples": emu["dropped_sensor_samples"],
                        "recording_masked_samples": emu["recording_masked_samples"]},
           "emulator_send_lag_ms_max": round(emu["send_lag_ms_max"], 1)}
    if ref is not None and poses:
        common = [k for k in sorted(poses) if k < len(ref)]
        out["max_abs_diff_vs_in_process"] = float(np.max(np.abs(np.stack([poses[k] for k in common]) - ref[common])))
        out["compared_frames"] = len(common)
    return out


def table(rows: list[dict[str, Any]]) -> str:
    head = ("| input | model | run | frames sent | poses | lost | shed | in order | max abs diff vs in-process | "
            "malformed injected / counted | masked: injected + recording / server | server ms median / p99 |\n"
            "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |\n")
    lines = []
    for r in rows:
        s = r["server"]
        diff = r.get("max_abs_diff_vs_in_process")
        inj = r["injected"]
        lines.append(f"| {r['input']} | {r['model']} | {'1 % malformed + dropouts' if r['faults'] else 'clean'} | "
                     f"{r['frames_sent']} | {r['poses_received']} | {s['lost']} | {s['shed']} | "
                     f"{r['all_frames_in_order']} | {'-' if diff is None else f'{diff:.2e}'} | "
                     f"{inj['malformed']} / {r['malformed_total']} | "
                     f"{inj['dropped_sensor_samples']} + {inj['recording_masked_samples']} / {s['masked_sensor_samples']} | "
                     f"{s['server_ms']['median']} / {s['server_ms']['p99']} |")
    return head + "\n".join(lines) + "\n"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--inputs", default="lsl,osc,mvn")
    ap.add_argument("--seconds", type=float, default=60.0)
    ap.add_argument("--clip", default="cmu_daz/05/05_01", help="a test-split clip (looped)")
    ap.add_argument("--out", default=str(ROOT / "benchmarks/results/live_inputs.json"))
    ap.add_argument("--merge", action="store_true", help="keep the other rows of --out (their own meta)")
    ap.add_argument("--runs", choices=("both", "clean", "faults"), default="both")
    ap.add_argument("--wait", type=float, default=600.0, help="s to wait after the emulator for queued frames")
    args = ap.parse_args()
    from wearpose.stream.inputs.lsl import write_loopback_config

    tmp = Path(tempfile.mkdtemp(prefix="wearpose-live-"))
    write_loopback_config(tmp / "lsl_api.cfg")  # this process's reference never uses LSL; the children set their own
    rows = []
    started = time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())
    load0 = os.getloadavg()
    refs: dict[tuple[str, float, str], np.ndarray] = {}  # OSC and MVN share kit, rate, model: one reference
    for name in args.inputs.split(","):
        kit, rate, model, _, _ = CASES[name]
        rec = recording(args.clip, kit, rate)
        path = tmp / f"{name}.npz"
        rec.save(path)
        n = int(round(args.seconds * rate))
        if (kit, rate, model) not in refs:
            print(f"{name}: reference ({n} frames of {model}) ...", flush=True)
            refs[(kit, rate, model)] = reference(model, rec, n)
        ref = refs[(kit, rate, model)]
        for faults in {"both": (False, True), "clean": (False,), "faults": (True,)}[args.runs]:
            r = run(name, path, rec, args.seconds, faults, ref, args.wait)
            print(json.dumps({k: v for k, v in r.items() if k != "input_stats"}), flush=True)
            rows.append(r)
    meta = {"started": started, "load_average_start": load0, "load_average_end": os.getloadavg(), "cpu": cpu_model(),
            "clip": args.clip, "seconds": args.seconds, **git_state()}
    out = Path(args.out)
    names = args.inputs.split(",")
    what = (f"started {started}, load average {load0[0]:.1f} at the start and {meta['load_average_end'][0]:.1f} at the "
            f"end (2 cores, shared), commit {meta['commit'][:7]}")
    if args.merge and out.exists():  # the other inputs' rows stay, with their own meta and header text
        old = json.loads(out.read_text())
        new_keys = {(r["input"], r["faults"]) for r in rows}
        kept = [r for r in old["runs"] if (r["input"], r["faults"]) not in new_keys]
        tag = "_".join(names) + ("" if args.runs == "both" else f"_{args.runs}")
        doc = {**old, "runs": kept + rows, f"meta_{tag}": meta}
        old_md = out.with_suffix(".md").read_text()
        intro = old_md[:old_md.index("| input |")].rstrip("\n")
        md = f"{intro}\n{', '.join(names)} {'' if args.runs == 'both' else args.runs + ' '}rows: {what}.\n\n" + table(kept + rows)
    else:
        doc = {"meta": meta, "runs": rows}
        md = (f"# Live inputs end to end (benchmarks/live_inputs.py)\n\n{args.seconds:g} s per run, clip {args.clip}, "
              f"{what}.\n\n" + table(rows))
    out.write_text(json.dumps(doc, indent=1))
    out.with_suffix(".md").write_text(md)
    print(md)


if __name__ == "__main__":
    main()
