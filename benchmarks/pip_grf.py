"""PIP ground reaction forces while walking, with the networks (simulated IMUs -> kinematics ->
physics), on every plain walking clip of a split (issue #5: "over 10 s of walking, the summed
vertical GRF averages within 15 % of body weight").

Run: ``taskset -c 0 python benchmarks/pip_grf.py [--split val|test] [--weights pip_cpu] [--set FIELD=JSON ...]``.

Per clip (60 fps, imu6 simulated with the default noise, seeds of the evaluation namespace, known
initial state): summed vertical GRF of both feet over body weight, the vertical residual root
force over body weight (the two add up to the body weight on average, up to the change of
momentum), frames in which no foot is in contact, deepest penetration, and the share of frames in
which the network calls a foot planted while the simulated foot is above the 3 cm contact
threshold (``planted_but_high``). Tune on ``val``, report ``test``. Writes
``benchmarks/results/pip_grf_<split>.json`` (and ``--plot``: the GRF of the longest clip,
``benchmarks/results/pip_grf_walk.png``).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np
import pinocchio as pin
import torch

RESULTS = Path(__file__).resolve().parent / "results"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--split", default="test")
    ap.add_argument("--weights", default="pip_cpu", help="shipped weights name or checkpoint path")
    ap.add_argument("--max-clips", type=int, default=0)
    ap.add_argument("--set", action="append", default=[], metavar="FIELD=JSON", help="PhysicsConfig override")
    ap.add_argument("--plot", action="store_true")
    ap.add_argument("--out", type=Path, default=None)
    a = ap.parse_args()
    torch.set_num_threads(1)
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from physics import walking_clips

    from wearpose.body import BodyModel
    from wearpose.estimators.seeding import clip_seed
    from wearpose.estimators.pip.data import simulate_clip
    from wearpose.viewer.demos.pip import G, physical_plots
    from wearpose.estimators.pip.estimator import PipEstimator
    from wearpose.estimators.pip.evaluate import _init
    from wearpose.motion import CorpusStore
    from wearpose.physics import PhysicsCharacter, PhysicsConfig, PhysicsOptimizer

    overrides = {k: json.loads(v) for k, v in (s.split("=", 1) for s in a.set)}
    store, body = CorpusStore(), BodyModel()
    path = a.weights if Path(a.weights).is_file() else str(__import__("wearpose.weights", fromlist=["x"]).weight_path(a.weights))
    est = PipEstimator.load(path, body=body, physics=False)
    clips = walking_clips(store, a.split)
    if a.max_clips:
        clips = clips[:a.max_clips]
    rows, t0 = [], time.time()
    for cid in clips:
        r = simulate_clip(store.load(cid), est.config, body, clip_seed(cid, 0, "pip-eval"), noise="default")
        _init(est, r)
        kin = est.estimate_tensors(r["acc"], r["ori"])
        char = PhysicsCharacter.from_body(body, r["betas"])
        opt = PhysicsOptimizer(char, PhysicsConfig(fps=est.fps, **overrides))
        init = est._initial()
        opt.reset(init["pose"], init["trans"])
        mg = char.mass_kg * G
        fy, res_y, nofoot, high, pen, grf, flags, tau = [], [], [], [], [], [], [], []
        feet = list(opt.config.foot_joints)
        for t in range(kin.num_frames):
            q0 = opt.q.copy()
            st = opt.step(kin.local_rot[t], kin.extras["joint_vel"][t], kin.extras["contacts"][t])
            Rr = pin.Quaternion(q0[6], q0[3], q0[4], q0[5]).toRotationMatrix()  # root frame -> world
            res_y.append(float((Rr @ st.residual[:3].double().numpy())[1]) / mg)
            fy.append(float(st.grf[:, 1].sum()) / mg)
            nofoot.append(not bool(st.contacts.any()))
            h = st.joints[feet, 1].numpy() - opt.ground_y
            high.append(bool(((kin.extras["contacts"][t].numpy() > 0.5) & (h >= opt.config.foot_contact_height)).any()))
            pen.append(st.penetration_m)
            grf.append(st.grf)
            flags.append(st.contacts)
            tau.append(st.torques)
        # alternation: in the ground truth's single-support frames (training contact labels), the
        # share of the feet's vertical force on the ground truth's stance foot
        g = torch.stack(grf)[..., 1].numpy()
        lab = r["contact"].numpy() > 0.5
        single = lab.sum(1) == 1
        stance = lab.argmax(1)
        tot = g.sum(1)
        ok = single & (tot > 0.05 * mg)
        share = float(np.mean(g[ok, stance[ok]] / tot[ok])) if ok.any() else float("nan")
        agree = float(np.mean(g[ok].argmax(1) == stance[ok])) if ok.any() else float("nan")
        row = {"clip": cid, "stance_share": share, "stance_agreement": agree, "seconds": kin.num_frames / est.fps, "mass_kg": char.mass_kg,
               "grf_over_weight": float(np.mean(fy)), "residual_y_over_weight": float(np.mean(res_y)),
               "frames_without_foot_contact": float(np.mean(nofoot)), "planted_but_high": float(np.mean(high)),
               "max_penetration_cm": float(np.max(pen)) * 100}
        rows.append(row)
        print(f"{cid}: {row['seconds']:.1f} s, GRF/weight {row['grf_over_weight']:.3f}, residual {row['residual_y_over_weight']:.3f}, "
              f"no foot {row['frames_without_foot_contact'] * 100:.1f} %", file=sys.stderr, flush=True)
        if a.plot and cid == clips[0]:
            from wearpose.estimators.base import PoseTrack

            track = PoseTrack(kin.local_rot, kin.betas, kin.trans, kin.valid, kin.fps,
                              extras={"grf": torch.stack(grf), "torques": torch.stack(tau), "contact_flags": torch.stack(flags)})
            physical_plots(track, char.mass_kg, RESULTS / "pip_grf_walk.png",
                           f"PIP (networks + physics) on held-out {cid}: GRF/weight {row['grf_over_weight'] * 100:.1f} %")
    secs = np.array([r["seconds"] for r in rows])
    summary = {k: float(np.average([r[k] for r in rows], weights=secs)) for k in
               ("grf_over_weight", "residual_y_over_weight", "frames_without_foot_contact", "planted_but_high",
                "stance_share", "stance_agreement")}
    summary["max_penetration_cm"] = max(r["max_penetration_cm"] for r in rows)
    summary["clips_within_15pct"] = int(sum(abs(r["grf_over_weight"] - 1) <= 0.15 for r in rows))
    summary["clips"] = len(rows)
    summary["seconds"] = float(secs.sum())
    res = {"split": a.split, "weights": path, "overrides": overrides, "config": PhysicsConfig(**overrides).__dict__,
           "summary_time_weighted": summary, "per_clip": rows, "command": "python " + " ".join(sys.argv),
           "load_average": list(os.getloadavg()), "wall_s": time.time() - t0,
           "time_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}
    out = a.out or RESULTS / f"pip_grf_{a.split}.json"
    out.write_text(json.dumps(res, indent=2, default=str))
    print(f"{a.split}: {len(rows)} walking clips, {summary['seconds']:.0f} s: GRF/weight {summary['grf_over_weight']:.3f}, "
          f"residual {summary['residual_y_over_weight']:.3f}, no foot {summary['frames_without_foot_contact'] * 100:.1f} %, "
          f"{summary['clips_within_15pct']}/{len(rows)} clips within 15 %, max penetration {summary['max_penetration_cm']:.2f} cm, "
          f"stance foot carries {summary['stance_share'] * 100:.0f} % in single support (loaded foot = stance foot "
          f"{summary['stance_agreement'] * 100:.0f} %)")
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
