"""Convention checks on simulated corpus clips: false positives, detection rates, the cue each
kit relies on, and the time to check a 1-hour recording.

Run: ``python benchmarks/convention_checks.py [--clips 40] [--kits em12,em6,imu6,mimu6,miposer]``.
Prints tables and writes ``benchmarks/results/convention_checks.{md,json}``.

Workload: ``--clips`` clips from each source of the corpus (``cmu_daz``, ``bandai``; drawn with
``random.Random(1)`` from ``manifest.csv`` of :func:`wearpose.motion.data_dir`), simulated with
every kit on the embedded body (clip seed, random EM offsets), noise-free and with the default
noise. Each recording is checked (:func:`wearpose.recording.check_recording`, what
``load_recording`` runs) as simulated and in every correct declared form (``declared_as``: gyro
in deg/s; raw sensor-frame readings in g; raw sensor-frame readings in m/s^2 in a Z-up world;
world-frame readings with gravity, in m/s^2 and in g): any issue is a false positive. Then the
mistakes: quaternions written (x, y, z, w) (as simulated, and with raw sensor-frame readings:
the gravity cue), gyro in deg/s declared rad/s, raw readings in g declared m/s^2 (sensor and
world frame), free acceleration in g declared m/s^2 (not detectable: reported as such). A
mistake counts as caught when the first issue is on the right field (what the file reader
reports). The 1-hour figure: 12 IMUs at 60 Hz (orientation, acceleration with a minute at
rest, gyro), :func:`check_recording` alone, best of 3.
"""

from __future__ import annotations

import argparse
import collections
import csv
import dataclasses
import json
import platform
import random
import time
import warnings
from pathlib import Path
from typing import Any, Callable

import numpy as np
import torch

from wearpose.body import BodyModel
from wearpose.geometry import matrix_to_quat, quat_to_matrix
from wearpose.motion import data_dir, load_motion
from wearpose.recording import Recording, SensorInfo, SensorStream, check_recording
from wearpose.sensors import simulate

CUES = (("gyro", "integrated angular"), ("gravity", "from world up"), ("lever", "rigid lever"))


def _rebuild(rec: Recording, fn: Callable[[SensorStream], tuple[SensorInfo, dict[str, np.ndarray]]]) -> Recording:
    streams = []
    for s in rec.sensors:
        info, channels = fn(s)
        streams.append(SensorStream(info, s.timestamps, s.valid, **channels))
    return Recording(streams)


def _w_last(s: SensorStream) -> tuple[SensorInfo, dict[str, np.ndarray]]:
    """The stream as a reader sees it when the writer put (x, y, z, w) in the file."""
    ch = {k: v.copy() for k, v in s.channels().items()}
    if "orientation" in ch:
        R = np.where(s.valid[:, None, None], ch["orientation"], np.eye(3, dtype=ch["orientation"].dtype))
        q = matrix_to_quat(torch.from_numpy(R.astype(np.float64))).numpy()[:, [1, 2, 3, 0]]
        ch["orientation"] = quat_to_matrix(torch.from_numpy(np.ascontiguousarray(q))).numpy().astype(R.dtype)
    return s.info, ch


def _undeclared(**changes: str) -> Callable[[SensorStream], tuple[SensorInfo, dict[str, np.ndarray]]]:
    def fn(s: SensorStream) -> tuple[SensorInfo, dict[str, np.ndarray]]:
        upd = {k: v for k, v in changes.items()
               if (k.startswith("acc") and s.acceleration is not None) or (k == "gyro_unit" and s.angular_velocity is not None)}
        return dataclasses.replace(s.info, **upd), {k: v.copy() for k, v in s.channels().items()}
    return fn


def _variants(rec: Recording) -> tuple[dict[str, Recording], dict[str, tuple[Recording, str]]]:
    """(correct variants, mistakes with the field that must be reported first)."""
    gyro = any(s.angular_velocity is not None for s in rec.sensors)
    acc = any(s.acceleration is not None for s in rec.sensors)
    correct = {"as simulated": rec}
    wrong: dict[str, tuple[Recording, str]] = {"(x, y, z, w) quaternions": (_rebuild(rec, _w_last), "orientation")}
    if gyro:
        correct["gyro deg/s"] = rec.declared_as(gyro_unit="deg/s")
        deg = rec.declared_as(gyro_unit="deg/s")
        wrong["deg/s declared rad/s"] = (_rebuild(deg, _undeclared(gyro_unit="rad/s")), "angular_velocity")
    if acc:
        raw = rec.declared_as(acc_frame="sensor", acc_gravity="included")
        correct.update({
            "raw sensor-frame, g": rec.declared_as(acc_unit="g", acc_frame="sensor", acc_gravity="included"),
            "raw sensor-frame, m/s^2, Z up": rec.declared_as(acc_frame="sensor", acc_gravity="included", world_up="z_up"),
            "world-frame with gravity, m/s^2": rec.declared_as(acc_gravity="included"),
            "world-frame with gravity, g": rec.declared_as(acc_unit="g", acc_gravity="included"),
        })
        wrong["(x, y, z, w), raw sensor-frame readings"] = (_rebuild(raw, _w_last), "orientation")
        for frame in ("sensor", "world"):
            g = rec.declared_as(acc_unit="g", acc_frame=frame, acc_gravity="included")
            wrong[f"raw {frame}-frame g declared m/s^2"] = (_rebuild(g, _undeclared(acc_unit="m/s2")), "acceleration")
        wrong["free acceleration in g declared m/s^2"] = (_rebuild(rec.declared_as(acc_unit="g"), _undeclared(acc_unit="m/s2")),
                                                         "acceleration")
    return correct, wrong


def _clips(n: int) -> list[dict[str, str]]:
    root = data_dir()
    rows = list(csv.DictReader(open(root / "manifest.csv")))
    rng = random.Random(1)
    out = []
    for source in ("cmu_daz", "bandai"):
        pool = [r for r in rows if r["source"] == source]
        out += rng.sample(pool, min(n, len(pool)))
    for r in out:
        r["file"] = str(root / Path(r["path"]).relative_to("data")) if r["path"].startswith("data/") else str(root / r["path"])
    return out


def _hour_timing() -> float:
    rate, n = 60.0, 3600 * 60
    t = np.arange(n) / rate
    w = np.stack([np.sin(0.7 * t), np.cos(1.3 * t), 0.5 * np.sin(0.2 * t)], axis=1) * 2.0
    half = 0.5 * np.cumsum(np.linalg.norm(w, axis=1))[:, None] / rate
    q = np.concatenate([np.cos(half), np.sin(half) * w / np.linalg.norm(w, axis=1, keepdims=True)], axis=1)
    R = quat_to_matrix(torch.from_numpy(q)).numpy().astype(np.float32)
    acc = np.random.default_rng(0).normal(size=(n, 3)).astype(np.float32)
    acc[:3600] = 0.001 * np.random.default_rng(1).normal(size=(3600, 3))
    streams = []
    for j in range(12):
        s = object.__new__(SensorStream)  # valid by construction: time the checks, not the constructor
        s.info, s.timestamps, s.valid = SensorInfo(f"s{j}", "imu", rate=rate), t, np.ones(n, bool)
        s.position, s.orientation, s.acceleration, s.angular_velocity, s.magnetic_field = None, R, acc, w.astype(np.float32), None
        streams.append(s)
    best = float("inf")
    for _ in range(3):
        t0 = time.perf_counter()
        check_recording(streams)
        best = min(best, time.perf_counter() - t0)
    return best


def main() -> None:
    here = Path(__file__).resolve().parent
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--clips", type=int, default=40, help="clips per corpus source")
    ap.add_argument("--kits", default="em12,em6,imu6,mimu6,miposer")
    ap.add_argument("--out", type=Path, default=here / "results")
    a = ap.parse_args()
    torch.set_num_threads(1)
    body = BodyModel()
    clips = _clips(a.clips)
    fp: dict[tuple[str, str], list[int]] = collections.defaultdict(lambda: [0, 0])
    caught: dict[tuple[str, str], list[int]] = collections.defaultdict(lambda: [0, 0])
    cues: dict[str, collections.Counter] = collections.defaultdict(collections.Counter)
    false_positives: list[dict[str, Any]] = []
    for i, clip in enumerate(clips):
        motion = load_motion(clip["file"])
        for kit in a.kits.split(","):
            for noise in ("none", "default"):
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    res = simulate(motion, kit, body, seed=i, noise=noise, offsets="random")
                rec = Recording.from_simulation(res, None, source_pose=False)
                correct, wrong = _variants(rec)
                for name, r in correct.items():
                    issues = check_recording(r.sensors)
                    fp[(kit, name)][0] += bool(issues)
                    fp[(kit, name)][1] += 1
                    if issues:
                        false_positives.append({"clip": clip["path"], "kit": kit, "noise": noise, "variant": name,
                                                "issue": dataclasses.asdict(issues[0])})
                for name, (r, field) in wrong.items():
                    issues = check_recording(r.sensors)
                    hit = bool(issues) and issues[0].field == field
                    caught[(kit, name)][0] += hit
                    caught[(kit, name)][1] += 1
                    if hit and field == "orientation" and name == "(x, y, z, w) quaternions":
                        for issue in issues:
                            if issue.field == "orientation":
                                cues[kit]["+".join(c for c, text in CUES if text in issue.problem)] += 1
        print(f"{i + 1}/{len(clips)} {clip['path']}", flush=True)
    hour = _hour_timing()
    result = {
        "clips": [c["path"] for c in clips], "noise": ["none", "default"], "machine": platform.platform(),
        "false_positives": {f"{k} | {v}": {"refused": n, "files": m} for (k, v), (n, m) in sorted(fp.items())},
        "detection": {f"{k} | {v}": {"caught": n, "files": m} for (k, v), (n, m) in sorted(caught.items())},
        "cues_of_flagged_sensors": {k: dict(v) for k, v in sorted(cues.items())},
        "false_positive_examples": false_positives[:20],
        "check_1h_12_imus_60hz_s": round(hour, 3),
    }
    a.out.mkdir(parents=True, exist_ok=True)
    (a.out / "convention_checks.json").write_text(json.dumps(result, indent=1) + "\n")
    lines = [f"# Convention checks on {len(clips)} corpus clips x {{none, default}} noise", "",
             "| kit | correct data refused (all declared forms) | (x, y, z, w) caught | with raw readings | deg/s caught | g caught (sensor / world frame) | free acc. in g | cues (flagged sensors) |",
             "| --- | --- | --- | --- | --- | --- | --- | --- |"]

    def frac(d: dict, k: str, v: str) -> str:
        n, m = d.get((k, v), (0, 0))
        return f"{n}/{m}" if m else "--"

    for kit in a.kits.split(","):
        refused = sum(fp[(kit, v)][0] for v in {v for (k, v) in fp if k == kit})
        total = sum(fp[(kit, v)][1] for v in {v for (k, v) in fp if k == kit})
        lines.append(f"| {kit} | {refused}/{total} | {frac(caught, kit, '(x, y, z, w) quaternions')} | "
                     f"{frac(caught, kit, '(x, y, z, w), raw sensor-frame readings')} | {frac(caught, kit, 'deg/s declared rad/s')} | "
                     f"{frac(caught, kit, 'raw sensor-frame g declared m/s^2')} / {frac(caught, kit, 'raw world-frame g declared m/s^2')} | "
                     f"{frac(caught, kit, 'free acceleration in g declared m/s^2')} | "
                     f"{', '.join(f'{c} {n}' for c, n in cues[kit].most_common())} |")
    lines += ["", f"check_recording of 1 h x 12 IMUs at 60 Hz: {hour:.2f} s (best of 3, one thread)", ""]
    (a.out / "convention_checks.md").write_text("\n".join(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
