"""PIP Table 2 (ablations) and Table 3-style metrics on our held-out test split, the translation
error vs travelled distance (Fig. 3), and the long-sitting drift test (Fig. 9).

Run::

    python benchmarks/pip_eval.py --full runs/pip_cpu/best.pt --noinit runs/pip_cpu_noinit/best.pt \\
        [--limit N] [--sit-hours H] [--sit-transitions lean]

Rows: ``PIP`` (learned init, physics, dual PD), ``w/o learned init`` (the model trained without
I_PL / I_VA, physics + dual PD), ``single PD`` (physics with one PD controller), ``w/o physics``
(kinematics only, translation by integrating the estimated root velocity), and
``w/o learned init, w/o physics``; a ``ground truth`` line carries the ZMP distance of the
real motion (validates the metric). Physics rows are skipped (and say so) when
:mod:`wearpose.physics` is not available. Protocol: :mod:`wearpose.estimators.pip.evaluate`.
Prints the table and writes ``benchmarks/results/pip_table2.md`` and ``.json``. One torch thread.
"""

from __future__ import annotations

import argparse
import json
import re
import shlex
import sys
import time
from pathlib import Path

import torch

COLUMNS = (("sip_error_deg", "SIP err [deg]"), ("angular_error_deg", "Ang err [deg]"),
           ("positional_error_cm", "Pos err [cm]"), ("mesh_error_cm", "Mesh err [cm]"),
           ("jitter_abs_km_s3", "Jitter abs [km/s^3]"), ("jitter_rel_km_s3", "Jitter rel [km/s^3]"),
           ("zmp_distance_m", "ZMP dist [m]"),
           ("translation_error_cm", "Trans err (mean) [cm]"), ("final_drift_pct", "Final trans err / travelled [%]"))


def _fmt(v) -> str:
    return "-" if v is None else f"{v:.2f}"


def motion_class(clip: str) -> str:
    """Motion class of a corpus clip id: Bandai's motion label (``dataset-2_<motion>_<style>_<n>``),
    else the source and its first folder (``cmu_daz martial``)."""
    parts = clip.split("/")
    if parts[0] == "bandai":
        m = re.match(r"dataset-\d+_([a-z-]+)_", parts[-1])
        return "bandai " + (m.group(1) if m else parts[-1])
    return " ".join(parts[:2])


def class_table(res: dict) -> list[str]:
    """Per motion class: clips, frames, frame-weighted mean translation error [cm] and mean final
    error / travelled [%] (clips travelling > 1 m) of every variant."""
    rows = {n: r["per_clip"] for n, r in res["rows"].items() if r.get("per_clip")}
    if not rows:
        return []
    agg: dict[str, dict[str, list[float]]] = {}
    for n, pcs in rows.items():
        for c in pcs:
            a = agg.setdefault(motion_class(c["clip"]), {}).setdefault(n, [0.0, 0, 0, 0.0, 0])
            a[0] += c["translation_error_cm"] * c["frames"]
            a[1] += c["frames"]
            a[2] += 1
            if c["travelled_m"] > 1.0:
                a[3] += c["final_error_m"] / c["travelled_m"] * 100
                a[4] += 1
    names = list(rows)
    out = ["", "Translation error by motion class (mean [cm] / final error per travelled distance [%]):", "",
           "| class | clips | frames | " + " | ".join(names) + " |", "|---" * (3 + len(names)) + "|"]
    for k in sorted(agg, key=lambda k: -next(iter(agg[k].values()))[1]):
        a = agg[k]
        first = a[names[0]]
        cells = [f"{a[n][0] / a[n][1]:.1f} / " + (f"{a[n][3] / a[n][4]:.0f}" if a[n][4] else "-") for n in names]
        out.append(f"| {k} | {first[2]} | {first[1]} | " + " | ".join(cells) + " |")
    return out


def markdown(res: dict) -> str:
    lines = [f"# PIP ablations (Table 2) on the held-out {res['split']} split", "",
             f"{res['clips']} clips, {res['frames']} frames at 60 fps; {res['protocol']}.", "",
             "| variant | " + " | ".join(h for _, h in COLUMNS) + " | ms/frame |",
             "|---" * (len(COLUMNS) + 2) + "|"]
    for name, row in res["rows"].items():
        lines.append(f"| {name} | " + " | ".join(_fmt(row.get(k)) for k, _ in COLUMNS) + f" | {row['ms_per_frame']:.2f} |")
    gt = res.get("ground_truth") or {}
    if gt.get("zmp_distance_m") is not None:
        lines.append("| ground truth | " + " | ".join(_fmt(gt.get(k)) if k == "zmp_distance_m" else "-" for k, _ in COLUMNS)
                     + " | - |")
    for name, why in res.get("skipped", {}).items():
        lines.append(f"| {name} | skipped: {why} |" + " |" * len(COLUMNS))
    lines += ["", "ZMP distance: mean distance (m) of the fictitious zero-moment point of the motion (Pinocchio, "
              "centroidal momentum rate) to the convex hull of the feet in contact (20 cm squares; foot within 5 cm "
              "of the ground and slower than 0.48 m/s), over the frames with such a foot (share: "
              + ", ".join(f"{n} {r.get('zmp_frames_pct', float('nan')):.0f} %" for n, r in res["rows"].items())
              + (f", ground truth {gt['zmp_frames_pct']:.0f} %" if gt else "") + "); `wearpose.physics.zmp_distance`.",
              "", "Translation error (cm) vs travelled distance (Fig. 3; mean over clips reaching the distance):", "",
              "| variant | " + " | ".join(next(iter(res["rows"].values()))["translation_error_vs_distance_cm"]) + " |",
              "|---" * (1 + len(next(iter(res["rows"].values()))["translation_error_vs_distance_cm"])) + "|"]
    for name, row in res["rows"].items():
        lines.append(f"| {name} | " + " | ".join(_fmt(v) for v in row["translation_error_vs_distance_cm"].values()) + " |")
    first = next(iter(res["rows"].values()))
    lines.append("| clips reaching | " + " | ".join(str(v) for v in first["clips_reaching_m"].values()) + " |")
    lines += class_table(res)
    phys = {n: r for n, r in res["rows"].items() if "qp_ms" in r}
    if phys:
        lines += ["", "Physics: QP solve time and penetration:", "",
                  "| variant | QP median [ms] | QP p99 [ms] | max penetration [cm] | where (clip, frame, SMPL joint) |",
                  "|---|---|---|---|---|"]
        for n, r in phys.items():
            deep = max(r.get("per_clip") or [{}], key=lambda c: c.get("max_penetration_m", -1.0))
            at = deep.get("penetration_at") or {}
            where = f"{deep['clip']}, {at.get('frame')}, {at.get('joint')}" if at else "-"
            lines.append(f"| {n} | {r['qp_ms']['median']:.2f} | {r['qp_ms']['p99']:.2f} | {_fmt(r.get('max_penetration_cm'))} | {where} |")
    if res.get("sitting"):
        lines += ["", "Long sitting (Fig. 6 / Fig. 9; a sit-down, or starting seated, then still seated input, kinematics "
                  "only; angular error vs the seated pose, root-relative, all joints and upper legs; drift = mean joint "
                  "angle between the estimates at the start and the end of the still input):", "",
                  "| model | start | hours | err start [deg] | err end [deg] | upper legs start [deg] | upper legs end [deg] "
                  "| upper legs max [deg] | drift total [deg] | drift/hour [deg] |",
                  "|---|---|---|---|---|---|---|---|---|---|"]
        for s in res["sitting"]:
            start = s["start"] + (" (lean)" if s.get("transitions") == "lean" else "")
            lines.append(f"| {s['model']} | {start} | {s['hours']:g} | {_fmt(s['error_at_start_deg'])} | "
                         f"{_fmt(s['error_at_end_deg'])} | {_fmt(s.get('upper_leg_error_at_start_deg'))} | "
                         f"{_fmt(s.get('upper_leg_error_at_end_deg'))} | {_fmt(s.get('upper_leg_error_max_deg'))} | "
                         f"{_fmt(s['drift_total_deg'])} | {_fmt(s['drift_per_hour_deg'])} |")
    if res.get("note"):
        lines += ["", res["note"]]
    lines += ["", f"Command: `{res['command']}`"]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--full", required=True, help="checkpoint trained with learned init")
    ap.add_argument("--noinit", default=None, help="checkpoint trained without learned init")
    ap.add_argument("--split", default="test")
    ap.add_argument("--limit", type=int, default=None, help="N clips spread over the split")
    ap.add_argument("--noise", default="default", choices=("default", "none"))
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--bodies", default="corpus", choices=("corpus", "heldout"),
                    help="wearers: the clips' own body, or one per clip from the held-out shape stream (issue 23)")
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--sit-hours", type=float, default=1.0, help="length of the still-sitting input (0 = skip)")
    ap.add_argument("--sit-transitions", default="slerp", choices=("slerp", "lean"),
                    help="how the fixed sit-down sits down (wearpose.estimators.pip.sitting.sitting_sequence)")
    ap.add_argument("--sit-extra", nargs=3, action="append", default=[], metavar=("LABEL", "FULL", "NOINIT"),
                    help="another learned-init / no-init checkpoint pair for the sitting test only")
    ap.add_argument("--no-physics", action="store_true", help="kinematics rows only")
    ap.add_argument("--out", default=str(Path(__file__).parent / "results" / "pip_table2"), help="output stem")
    ap.add_argument("--note", default=None)
    a = ap.parse_args(argv)
    torch.set_num_threads(a.threads)
    from wearpose.body import BodyModel
    from wearpose.estimators.pip.estimator import PipEstimator, physics_available
    from wearpose.estimators.pip.evaluate import evaluate_variants, sitting_drift
    from wearpose.estimators.pip.sitting import sitting_sequence

    body = BodyModel()

    def load(path: str, **opt) -> PipEstimator:
        est = PipEstimator.load(path, body=body, **opt)
        est.source = path
        return est

    phys = physics_available() and not a.no_physics
    why = "wearpose.physics not available" if not physics_available() else "--no-physics"
    variants, skipped = {}, {}
    specs = [("PIP", a.full, dict(physics=True, dual_pd=True)), ("w/o learned init", a.noinit, dict(physics=True, dual_pd=True)),
             ("single PD", a.full, dict(physics=True, dual_pd=False)), ("w/o physics", a.full, dict(physics=False)),
             ("w/o learned init, w/o physics", a.noinit, dict(physics=False))]
    for name, path, opt in specs:
        if path is None or not Path(path).is_file():
            skipped[name] = f"no checkpoint {path}"
        elif opt["physics"] and not phys:
            skipped[name] = why
        else:
            variants[name] = load(path, **opt)
    t0 = time.time()

    def prog(d: int, t: int) -> None:
        if d % 5 == 0 or d == t:
            print(f"  {d}/{t} clips ({time.time() - t0:.0f} s)", file=sys.stderr, flush=True)

    res = evaluate_variants(variants, a.split, a.limit, noise=a.noise, seed=a.seed, progress=prog, bodies=a.bodies)
    res["skipped"] = skipped
    sitting = []
    if a.sit_hours > 0:
        pairs = [("learned init", a.full), ("w/o learned init", a.noinit)]
        for label, full, noinit in a.sit_extra:
            pairs += [(f"{label}, learned init", full), (f"{label}, w/o learned init", noinit)]
        seq = sitting_sequence(body, transitions=a.sit_transitions)  # one fixed sit-down for every model
        for model, path in pairs:
            if path is None or not Path(path).is_file():
                continue
            est = load(path, physics=False)
            for start in ("standing", "seated"):
                s = sitting_drift(est, hours=a.sit_hours, start=start, seq=seq)
                s.update(model=model, transitions=a.sit_transitions)
                sitting.append(s)
                print(f"  sitting {model} {start}: {s}", file=sys.stderr, flush=True)
    res["sitting"] = sitting
    res.update(command="python " + shlex.join([sys.argv[0], *(argv if argv is not None else sys.argv[1:])]),
               wall_seconds=time.time() - t0, time_utc=time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
               load_average=list(__import__("os").getloadavg()))
    if a.note:
        res["note"] = a.note
    md = markdown(res)
    out = Path(a.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.with_suffix(".md").write_text(md)
    out.with_suffix(".json").write_text(json.dumps(res, indent=2))
    print(md)
    print(f"wrote {out.with_suffix('.md')} and {out.with_suffix('.json')}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
