"""PIP long-sitting test alone (Fig. 6 / Fig. 9): :func:`wearpose.estimators.pip.evaluate.sitting_drift`
for learned-init / no-init checkpoint pairs, both starts, ``--hours`` of still seated input.

With ``--synthetic N`` also N held-out synthetic sitting clips
(:func:`wearpose.estimators.pip.sitting.heldout_sitting_clip`: the test namespace, never
trained on; random seated postures, 75-100 deg hips, each ending seated) for each model, each
played whole ("clip": from its own first frame, standing or seated) or only its last, seated
second ("seated"), then ``--synthetic-hours`` of still input; the summary gives the mean
upper-leg error and how many clips end within 30 deg of their seated thighs.

With ``--arm-postures`` also the fixed sit-down with the arms swung forward / elbows bent (0/0,
20/45, 40/80 deg, the same posture standing and seated) and one minute of still input, and the
same postures standing still throughout ("standing still", errors against the standing pose):
does the arm posture, rather than the history or the learned initial state, decide "seated"?

``--transitions lean``: the held-out clips and the fixed sit-down sit down / stand up with trunk
lean and the knees forward (:func:`wearpose.estimators.pip.sitting.lean_transition`) instead of
the default slerp; the seated holds are the same frames either way.

Run: ``taskset -c 0 python benchmarks/pip_sitting.py --hours 4.63 --pair LABEL FULL NOINIT [...]
[--synthetic 20 --synthetic-hours 0.5] [--arm-postures]``.
Writes ``benchmarks/results/pip_sitting.json`` (the series every 10 min included).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import torch


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--hours", type=float, default=4.63, help="still input length (PIP Fig. 9: 1M frames = 4.63 h)")
    ap.add_argument("--pair", nargs=3, action="append", required=True, metavar=("LABEL", "FULL", "NOINIT"))
    ap.add_argument("--synthetic", type=int, default=0, help="held-out synthetic sitting clips per model (0 = none)")
    ap.add_argument("--synthetic-hours", type=float, default=0.5, help="still input after each synthetic clip")
    ap.add_argument("--synthetic-starts", nargs="+", default=["clip", "seated"], choices=("clip", "seated"))
    ap.add_argument("--models", nargs="+", default=["learned init", "w/o learned init"],
                    choices=("learned init", "w/o learned init"), help="which model of each pair to run")
    ap.add_argument("--arm-postures", action="store_true", help="the fixed sit-down with three arm postures")
    ap.add_argument("--skip-fixed", action="store_true", help="skip the fixed sit-down of --hours")
    ap.add_argument("--transitions", default="slerp", choices=("slerp", "lean"),
                    help="how the synthetic clips and the fixed sequence sit down (wearpose.estimators.pip.sitting)")
    ap.add_argument("--out", type=Path, default=Path(__file__).parent / "results" / "pip_sitting.json")
    a = ap.parse_args()
    torch.set_num_threads(1)
    from wearpose.body import BodyModel
    from wearpose.estimators.pip.estimator import PipEstimator
    from wearpose.estimators.pip.evaluate import sitting_drift
    from wearpose.estimators.pip.sitting import arms_forward, heldout_sitting_clip, sitting_sequence
    from wearpose.motion import MotionSequence

    body, rows, synth, summary, arms = BodyModel(), [], [], [], []
    clips = [heldout_sitting_clip(i, body, transitions=a.transitions) for i in range(a.synthetic)]
    fixed = sitting_sequence(body, transitions=a.transitions)  # the fixed sit-down, the same for every model
    for label, full, noinit in a.pair:
        for init, path in [(i, p) for i, p in (("learned init", full), ("w/o learned init", noinit)) if i in a.models]:
            est = PipEstimator.load(path, body=body, physics=False)
            for start_label in a.synthetic_starts if clips else ():
                # "clip": the whole clip from its first frame = sitting_drift's "standing" start
                start = "standing" if start_label == "clip" else start_label
                res = [sitting_drift(est, hours=a.synthetic_hours, start=start, seq=c, noise="default") for c in clips]
                for i, s in enumerate(res):
                    synth.append({"model": f"{label}, {init}", "clip": i, "start": start_label,
                                  **{k: s[k] for k in ("upper_leg_error_at_start_deg", "upper_leg_error_at_end_deg",
                                                       "error_at_start_deg", "error_at_end_deg", "drift_total_deg")}})
                ends = [s["upper_leg_error_at_end_deg"] for s in res]
                summary.append({"model": f"{label}, {init}", "checkpoint": path,
                                "start": start_label, "clips": len(res),
                                "upper_leg_error_at_start_deg": sum(s["upper_leg_error_at_start_deg"] for s in res) / len(res),
                                "upper_leg_error_at_end_deg": sum(ends) / len(res),
                                "clips_within_30deg_at_end": sum(e < 30.0 for e in ends),
                                "drift_total_deg_mean": sum(s["drift_total_deg"] for s in res) / len(res)})
                print("synthetic: " + ", ".join(f"{k} {v:.1f}" if isinstance(v, float) else f"{k} {v}"
                                                for k, v in summary[-1].items() if k != "checkpoint"), flush=True)
            for fwd, elbow in ((0.0, 0.0), (20.0, 45.0), (40.0, 80.0)) if a.arm_postures else ():
                seq = sitting_sequence(body, base=arms_forward(fwd, elbow), transitions=a.transitions)
                # the same posture standing still the whole time: errors against the standing pose
                still = MotionSequence(seq.pose[:1].repeat(seq.num_frames, 1, 1, 1), seq.betas,
                                       seq.trans[:1].repeat(seq.num_frames, 1), seq.fps)
                for start, clip in (("standing", seq), ("seated", seq), ("standing still", still)):
                    s = sitting_drift(est, hours=1 / 60, start="standing" if start == "standing still" else start,
                                      seq=clip)
                    arms.append({"model": f"{label}, {init}", "arms_forward_deg": fwd, "elbows_deg": elbow, "start": start,
                                 "upper_leg_error_at_end_deg": s["upper_leg_error_at_end_deg"]})
                    print(f"arms {fwd:g}/{elbow:g} deg, {arms[-1]['model']}, {start}: upper legs "
                          f"{s['upper_leg_error_at_end_deg']:.1f} deg after 1 min", flush=True)
            for start in ("standing", "seated") if not a.skip_fixed else ():
                s = sitting_drift(est, hours=a.hours, start=start, seq=fixed)
                s.update(model=f"{label}, {init}", checkpoint=path)
                rows.append(s)
                print(f"{s['model']} {start}: upper legs {s['upper_leg_error_at_start_deg']:.1f} -> "
                      f"{s['upper_leg_error_at_end_deg']:.1f} deg, all joints {s['error_at_start_deg']:.2f} -> "
                      f"{s['error_at_end_deg']:.2f} deg, drift {s['drift_total_deg']:.2f} deg", flush=True)
    a.out.write_text(json.dumps({"command": "python " + " ".join(sys.argv), "hours": a.hours,
                                 "transitions": a.transitions, "rows": rows,
                                 "synthetic_hours": a.synthetic_hours if clips else None,
                                 "synthetic_summary": summary, "synthetic_rows": synth, "arm_postures": arms,
                                 "time_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}, indent=2))
    print(f"wrote {a.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
