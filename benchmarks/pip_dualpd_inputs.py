"""Dual vs single PD translation error by the source of the physics module's inputs: where does
the dual PD controller's advantage go when the kinematics come from the network?

Run: ``taskset -c 0 python benchmarks/pip_dualpd_inputs.py [--split test] [--weights pip_cpu]
[--min-travel 1.0] [--limit N] [--out NAME]``.

Every clip of the split whose ground truth travels at least ``--min-travel`` m is simulated as in
``pip_eval.py`` (imu6, default IMU noise, evaluation seeds, 60 fps, known initial state). The
physics optimizer (default :class:`~wearpose.physics.PhysicsConfig`, dual and single PD) then
tracks four input sets, from the same initial state:

- ``ground truth``: ground-truth pose, world joint velocities (central differences of the
  ground-truth joints) and foot contact labels (:func:`wearpose.physics.kinematic_reference`'s
  rule: foot slower than 0.48 m/s and within 10 cm of its lowest height);
- ``network``: the kinematics network's pose, joint velocities and contact probabilities (what
  ``pip_eval.py`` scores);
- ``network, true velocities``: the network's pose and contacts with the ground-truth joint
  velocities (isolates the velocity estimate);
- ``network pose, true velocities and contacts``: only the pose from the network.

It also reports the network's *speed ratio*: the mean horizontal speed of the estimated root
velocity over the ground truth's (1 = unbiased), per motion class. Writes
``benchmarks/results/pip_dualpd_inputs_<NAME>.json`` and prints a table per motion class.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections import defaultdict
from pathlib import Path
from typing import Any

import torch

RESULTS = Path(__file__).resolve().parent / "results"
sys.path.insert(0, str(RESULTS.parent))
from pip_eval import motion_class  # noqa: E402  (one motion-class rule for the PIP tables)

INPUTS = ("ground truth", "network", "network, true velocities", "network pose, true velocities and contacts")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--split", default="test")
    ap.add_argument("--weights", default="src/wearpose/weights/pip_cpu.pt")
    ap.add_argument("--min-travel", type=float, default=1.0, help="keep clips whose ground truth travels >= this, m")
    ap.add_argument("--limit", type=int, default=0, help="only the first N kept clips (development)")
    ap.add_argument("--out", default=None)
    a = ap.parse_args(argv)
    torch.set_num_threads(1)
    from wearpose.body import BodyModel
    from wearpose.estimators.seeding import clip_seed
    from wearpose.estimators.pip.data import simulate_clip
    from wearpose.estimators.pip.estimator import PipEstimator
    from wearpose.estimators.pip.evaluate import horizontal_path_m
    from wearpose.motion import CorpusStore, MotionSequence
    from wearpose.physics import PhysicsCharacter, PhysicsConfig, PhysicsOptimizer, kinematic_reference

    body = BodyModel()
    est = PipEstimator.load(a.weights, body=body, physics=False)
    store = CorpusStore()
    rows: list[dict[str, Any]] = []
    t0 = time.perf_counter()
    ids = store.clips(split=a.split)
    for cid in ids:
        seq = store.load(cid)
        r = simulate_clip(seq, est.config, body, clip_seed(cid, 0, "pip-eval"))
        gt_trans = r["trans"].float()
        travelled = horizontal_path_m(gt_trans)
        if travelled < a.min_travel:
            continue
        ref = kinematic_reference(MotionSequence(pose=r["pose"].float(), betas=r["betas"].float(), trans=gt_trans,
                                                 fps=est.fps), body, fps=est.fps)
        est.set_initial_state(r["pose"][0], r["vel"][0].view(24, 3) * est.config.vel_scale, r["trans"][0], r["betas"])
        track = est.estimate_tensors(r["acc"], r["ori"])
        net = {"pose": track.local_rot, "vel": track.extras["joint_vel"], "contact": track.extras["contacts"]}
        sources = {"ground truth": (ref.pose, ref.joint_vel, ref.contact),
                   "network": (net["pose"], net["vel"], net["contact"]),
                   "network, true velocities": (net["pose"], ref.joint_vel, net["contact"]),
                   "network pose, true velocities and contacts": (net["pose"], ref.joint_vel, ref.contact)}
        char = PhysicsCharacter.from_body(body, r["betas"].float())
        row: dict[str, Any] = {"clip": cid, "class": motion_class(cid), "frames": int(gt_trans.shape[0]),
                               "travelled_m": travelled}
        est_speed = track.extras["joint_vel"][:, 0][:, [0, 2]].norm(dim=-1).mean()
        row["speed_ratio"] = float(est_speed / ref.joint_vel[:, 0][:, [0, 2]].norm(dim=-1).mean())
        for name, (pose, vel, contact) in sources.items():
            for dual in (True, False):
                opt = PhysicsOptimizer(char, PhysicsConfig(fps=est.fps, dual_pd=dual))
                opt.reset(r["pose"][0].float(), gt_trans[0])
                trans = torch.stack([torch.as_tensor(opt.step(pose[t], vel[t], contact[t]).trans)
                                     for t in range(pose.shape[0])])
                row[f"{name} | {'dual' if dual else 'single'}"] = float((trans - gt_trans).norm(dim=-1).mean()) * 100
        rows.append(row)
        print(f"[{len(rows)}] {cid} {travelled:.1f} m " + " ".join(
            f"{k.split(' | ')[0][:7]}/{k.split(' | ')[1][0]}={v:.0f}" for k, v in row.items() if " | " in k),
            flush=True)
        if a.limit and len(rows) >= a.limit:
            break

    def mean_of(rs: list[dict[str, Any]], key: str) -> float:  # frame-weighted, as pip_eval.py
        return sum(r[key] * r["frames"] for r in rs) / sum(r["frames"] for r in rs)

    keys = [f"{n} | {m}" for n in INPUTS for m in ("dual", "single")]
    groups: dict[str, list[dict[str, Any]]] = defaultdict(list)
    for row in rows:
        groups[row["class"]].append(row)
    groups["all"] = rows
    summary = {g: {"clips": len(rs), "frames": sum(r["frames"] for r in rs), "speed_ratio": mean_of(rs, "speed_ratio"),
                   **{k: mean_of(rs, k) for k in keys}} for g, rs in groups.items()}
    head = "| class | clips | speed ratio | " + " | ".join(f"{n}: dual / single [cm]" for n in INPUTS) + " |"
    print(head)
    print("|" + "---|" * (3 + len(INPUTS)))
    for g, s in sorted(summary.items(), key=lambda kv: (kv[0] == "all", -kv[1]["frames"])):
        print(f"| {g} | {s['clips']} | {s['speed_ratio']:.2f} | " + " | ".join(
            f"{s[f'{n} | dual']:.1f} / {s[f'{n} | single']:.1f}" for n in INPUTS) + " |")
    out = RESULTS / f"pip_dualpd_inputs_{a.out or a.split}.json"
    out.write_text(json.dumps({"command": "python " + " ".join(sys.argv), "split": a.split, "weights": a.weights,
                               "min_travel_m": a.min_travel, "summary": summary, "per_clip": rows,
                               "wall_seconds": time.perf_counter() - t0}, indent=1))
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
