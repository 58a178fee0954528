"""PIP physics module driven by ground-truth kinematics of held-out walking clips.

Run: ``python benchmarks/physics.py [--plots] [--clips ID ...] [--max-clips N] [--split test|val]
[--k-res K]``.

For every walking clip of the corpus TEST split (description ``walk``; the turning walks are
left out) the optimizer tracks the clip's own motion at 60 fps: reference pose = ground truth,
reference joint velocities = central differences of the ground-truth joints, foot contact
"probabilities" = the {0, 1} labels of :func:`wearpose.physics.kinematic_reference` (foot joint
slower than 0.48 m/s and within 10 cm of its lowest height). It reports, per clip and averaged:

- ``grf_over_weight``: mean over frames of the summed vertical GRF of both feet / (m g)
  (issue #5 acceptance: within 15 %);
- ``max_penetration_m``: deepest contact-candidate joint below the ground (target < 1 cm);
- alternation: ``stance_agreement`` = fraction of the ground truth's single-support frames in
  which the foot carrying more vertical force is the ground truth's stance foot, and the rate of
  load switches between the feet (per s) against the ground truth's stance switches;
- ``trans_err_mean_m`` / ``trans_err_final_m`` vs ground truth and the distance travelled;
- ``joint_err_cm``: root-relative joint position error against the ground truth;
- timing: QP solve (proxsuite) and whole step (wall and thread CPU time), median and p99
  (first 5 frames excluded), and a histogram of the QP's CPU time per clip;
- with ``--departures``: each departure from the paper's text (``LITERAL``) switched back to the
  literal reading, on a standing T-pose (2 s) and the longest clip;
- the single-PD ablation on the longest clip (translation error with ``dual_pd=False``) and the
  sensitivity to the residual weight ``k_res`` (0.3 and 1.0 against the paper's 0.1).

``--plots`` also writes ``docs/img/pip_grf_walk.png`` (GRF of both feet vs time on the longest
walking clip) and ``docs/img/pip_arm_torque_wave.png`` (shoulder/elbow torques while waving,
test clip ``wave-right-hand``). Results: ``benchmarks/results/physics.json``. The machine's
load average is recorded: timings on a loaded machine are inflated.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np
import torch
from rich.console import Console
from rich.table import Table

from wearpose.body import JOINT_INDEX, BodyModel
from wearpose.motion import CorpusStore
from wearpose.physics import PhysicsCharacter, PhysicsConfig, PhysicsOptimizer, kinematic_reference

G = 9.81
ROOT = Path(__file__).resolve().parent.parent
WAVE_CLIP = "bandai/bandai-B/dataset-2_wave-right-hand_feminine_001"


def walking_clips(store: CorpusStore, split: str = "test") -> list[str]:
    """Clips of ``split`` described as plain walking (no turns), longest first."""
    ids = [c for c in store.clips(split=split) if str(store.entry(c).get("description", "")).split(" ")[0] == "walk"]
    return sorted(ids, key=lambda c: -float(store.entry(c)["seconds"]))


def run_clip(store: CorpusStore, body: BodyModel, clip: str, cfg: PhysicsConfig) -> tuple[dict, dict, object]:
    seq = store.load(clip)
    ref = kinematic_reference(seq, body, fps=cfg.fps)
    char = PhysicsCharacter.from_body(body, seq.betas)
    opt = PhysicsOptimizer(char, cfg)
    out = opt.run(ref.pose, ref.joint_vel, ref.contact, ref.trans[0])
    mg = char.mass_kg * G
    fy = out["grf"][..., 1].double().numpy()  # (T, 2)
    lab = ref.contact.numpy() > 0.5
    single = lab.sum(1) == 1
    dominant = fy.argmax(1)
    stance = lab.argmax(1)
    loaded = fy.sum(1) > 0.05 * mg

    def switches(x: np.ndarray) -> float:
        return float((np.diff(x) != 0).sum() / (len(x) / cfg.fps)) if len(x) > 1 else float("nan")

    err = (out["trans"] - ref.trans).norm(dim=-1).numpy()
    travelled = float((ref.trans[1:, [0, 2]] - ref.trans[:-1, [0, 2]]).norm(dim=-1).sum())
    jrel = (out["joints"] - out["joints"][:, :1]) - (ref.joints - ref.joints[:, :1])
    qp, st, cpu = out["qp_ms"].numpy()[5:], out["step_ms"].numpy()[5:], out["step_cpu_ms"].numpy()[5:]
    qpc = out["qp_cpu_ms"].numpy()[5:]
    res = {
        "clip": clip, "seconds": len(fy) / cfg.fps, "frames": len(fy), "mass_kg": char.mass_kg,
        "grf_over_weight": float(fy.sum(1).mean() / mg),
        "max_penetration_m": float(out["penetration_m"].max()),
        "stance_agreement": float((dominant[single & loaded] == stance[single & loaded]).mean())
        if (single & loaded).any() else float("nan"),
        "load_switches_per_s": switches(dominant[loaded]), "gt_stance_switches_per_s": switches(stance[single]),
        "frames_without_foot_contact": float((~out["contacts"].numpy().any(1)).mean()),
        "trans_err_mean_m": float(err.mean()), "trans_err_final_m": float(err[-1]), "travelled_m": travelled,
        "joint_err_cm": float(jrel.norm(dim=-1).mean() * 100),
        "residual_force_mean_n": float(out["residual"][:, :3].norm(dim=-1).mean()),
        "qp_ms_median": float(np.median(qp)), "qp_ms_p99": float(np.percentile(qp, 99)),
        "step_ms_median": float(np.median(st)), "step_ms_p99": float(np.percentile(st, 99)),
        "qp_cpu_ms_median": float(np.median(qpc)), "qp_cpu_ms_p99": float(np.percentile(qpc, 99)),
        "qp_cpu_ms_hist": {f"{a:g}-{b:g}": int(((qpc >= a) & (qpc < b)).sum())
                           for a, b in ((0, 0.25), (0.25, 0.5), (0.5, 1), (1, 2), (2, 5), (5, 1e9))},
        "step_cpu_ms_median": float(np.median(cpu)), "step_cpu_ms_p99": float(np.percentile(cpu, 99)),
    }
    return res, out, ref


def standing(body: BodyModel, cfg: PhysicsConfig, seconds: float = 2.0) -> dict:
    """Static T-pose, both feet held (probability 1), zero reference velocities."""
    char = PhysicsCharacter.from_body(body, torch.zeros(body.num_betas))
    T = int(seconds * cfg.fps)
    eye = torch.eye(3).expand(T, 24, 3, 3)
    out = PhysicsOptimizer(char, cfg).run(eye, torch.zeros(T, 24, 3), torch.ones(T, 2), torch.zeros(3))
    fy = out["grf"][..., 1].double().sum(1).numpy()
    return {"grf_over_weight": float(fy[10:].mean() / (char.mass_kg * G)),
            "drift_m": float(out["trans"][-1].norm()), "residual_force_mean_n": float(out["residual"][:, :3].norm(dim=-1).mean())}


#: The paper's literal reading of each PhysicsConfig departure (docs/physics.md).
LITERAL = {"weights_in_norm": False, "min_contact_weight": 0.005, "ground_bound": False, "contact_no_lift": False,
           "foot_contact_requires_prob": False, "guard_all_candidates": False, "foot_square_shift": 0.0}


def plot_grf(out: dict, ref, mass_kg: float, clip: str, path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = np.arange(len(out["grf"])) / ref.fps
    fy = out["grf"][..., 1].numpy()
    mg = mass_kg * G
    fig, ax = plt.subplots(figsize=(9, 3.6), dpi=100)
    lab = ref.contact.numpy() > 0.5
    for k, (col, name) in enumerate((("tab:blue", "left"), ("tab:red", "right"))):
        ax.fill_between(t, 0, -0.06 * mg * (k + 1), where=lab[:, k], color=col, alpha=0.25, step="mid", lw=0)
        ax.plot(t, fy[:, k], color=col, lw=1.2, label=f"{name} foot")
    ax.plot(t, fy.sum(1), color="0.45", lw=0.8, ls="--", zorder=1, label="sum")
    ax.axhline(mg, color="k", ls="--", lw=0.8, label=f"body weight ({mass_kg:.1f} kg)")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("vertical GRF (N)")
    ax.set_title(f"PIP physics on ground-truth kinematics: {clip.split('/')[-1]} (test split)\n"
                 "bands below 0: ground-truth foot contact labels (left, right)", fontsize=9)
    ax.legend(fontsize=8, ncol=4, loc="upper right")
    ax.set_ylim(-0.15 * mg, 2.2 * mg)
    peak = fy.max()
    if peak > 2.2 * mg:
        ax.text(0.01, 0.97, f"touch-down peaks clipped (max {peak:.0f} N)", transform=ax.transAxes, fontsize=8, va="top")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    plt.close(fig)


def plot_wave(out: dict, fps: float, clip: str, path: Path) -> dict:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = np.arange(len(out["torques"])) / fps
    tq = out["torques"].norm(dim=-1).numpy()
    fig, ax = plt.subplots(figsize=(9, 3.4), dpi=100)
    series = {}
    for name, col, ls in (("right_shoulder", "tab:red", "-"), ("right_elbow", "tab:red", ":"),
                          ("left_shoulder", "tab:blue", "-"), ("left_elbow", "tab:blue", ":")):
        y = tq[:, JOINT_INDEX[name]]
        series[name] = {"median_nm": float(np.median(y)), "max_nm": float(y.max())}
        ax.plot(t, y, color=col, ls=ls, lw=1.1, label=name.replace("_", " "))
    ax.set_xlabel("time (s)")
    ax.set_ylabel("|joint torque| (N m)")
    ax.set_title(f"Arm torques while waving: {clip.split('/')[-1]} (test split, ground-truth kinematics)", fontsize=9)
    ax.legend(fontsize=8, ncol=4)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return series


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--clips", nargs="*", help="clip ids (default: every plain walking clip of the test split)")
    ap.add_argument("--split", default="test", help="corpus split of the walking clips (test; val for tuning)")
    ap.add_argument("--k-res", type=float, default=None, help="residual weight for every run (default: the paper's 0.1)")
    ap.add_argument("--set", action="append", default=[], metavar="FIELD=JSON",
                    help="PhysicsConfig override for every run, e.g. --set weights_in_norm=false (repeatable)")
    ap.add_argument("--max-clips", type=int, default=0, help="only the N longest walking clips (0 = all)")
    ap.add_argument("--plots", action="store_true", help="write docs/img/pip_grf_walk.png and pip_arm_torque_wave.png")
    ap.add_argument("--departures", action="store_true",
                    help="also run each departure from the paper's text at its literal value (standing + longest clip)")
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "physics.json")
    args = ap.parse_args()
    torch.set_num_threads(1)
    store = CorpusStore()
    body = BodyModel()
    clips = args.clips or walking_clips(store, args.split)
    if args.max_clips:
        clips = clips[:args.max_clips]
    overrides = {k: json.loads(v) for k, v in (item.split("=", 1) for item in args.set)}
    if args.k_res is not None:
        overrides["k_res"] = args.k_res
    cfg = PhysicsConfig(**overrides)
    rows = []
    first = None
    for clip in clips:
        t0 = time.perf_counter()
        res, out, ref = run_clip(store, body, clip, cfg)
        res["wall_s"] = time.perf_counter() - t0
        rows.append(res)
        if first is None:
            first = (res, out, ref)
        print(f"{clip}: GRF/weight {res['grf_over_weight']:.3f}, step median {res['step_ms_median']:.2f} ms", file=sys.stderr)
    longest = rows[0]
    single, _, _ = run_clip(store, body, longest["clip"], dataclasses.replace(cfg, dual_pd=False))
    # Sensitivity to the residual weight (paper: k_res = 0.1), longest clip.
    k_res_rows = {str(k): run_clip(store, body, longest["clip"], dataclasses.replace(cfg, k_res=k))[0] for k in (0.3, 1.0)}
    keys = ("grf_over_weight", "max_penetration_m", "stance_agreement", "load_switches_per_s", "gt_stance_switches_per_s",
            "trans_err_mean_m", "trans_err_final_m", "travelled_m", "joint_err_cm", "residual_force_mean_n",
            "frames_without_foot_contact")
    qp_all = np.array([r["qp_ms_median"] for r in rows])
    summary = {k: float(np.nanmean([r[k] for r in rows])) for k in keys}
    summary["max_penetration_m"] = float(max(r["max_penetration_m"] for r in rows))
    summary["grf_over_weight_min"] = float(min(r["grf_over_weight"] for r in rows))
    summary["grf_over_weight_max"] = float(max(r["grf_over_weight"] for r in rows))
    summary["qp_ms_median_of_clip_medians"] = float(np.median(qp_all))
    summary["qp_cpu_ms_median_of_clip_medians"] = float(np.median([r["qp_cpu_ms_median"] for r in rows]))
    summary["qp_cpu_ms_p99_max"] = float(max(r["qp_cpu_ms_p99"] for r in rows))
    summary["step_ms_median_of_clip_medians"] = float(np.median([r["step_ms_median"] for r in rows]))
    summary["step_ms_p99_max"] = float(max(r["step_ms_p99"] for r in rows))
    summary["step_cpu_ms_median_of_clip_medians"] = float(np.median([r["step_cpu_ms_median"] for r in rows]))
    summary["step_cpu_ms_p99_max"] = float(max(r["step_cpu_ms_p99"] for r in rows))
    result = {
        "command": " ".join(["python", "benchmarks/physics.py", *sys.argv[1:]]),
        "split": args.split if not args.clips else "given clips", "clips": len(rows), "seconds": float(sum(r["seconds"] for r in rows)),
        "overrides": overrides,
        "config": {k: getattr(cfg, k) for k in ("fps", "dual_pd", "kp_theta", "kd_theta", "kp_r", "kd_r", "k_lambda",
                                                "k_res", "k_tau", "mu", "sigma", "square_size", "weights_in_norm",
                                                "min_contact_weight", "foot_contact_requires_prob", "ground_bound",
                                                "guard_all_candidates", "foot_square_shift")},
        "targets": {"grf_over_weight": "within 0.15 of 1", "max_penetration_m": "< 0.01", "step_ms_median": "<= 5 (whole PIP)"},
        "longest_clip": longest, "longest_clip_single_pd": single,
        "longest_clip_k_res": k_res_rows, "mean_over_clips": summary, "per_clip": rows,
        "machine": {"platform": platform.platform(), "load_average_1m": os.getloadavg()[0], "cpus": os.cpu_count()},
    }
    if args.departures:
        dep = {"default": {"standing": standing(body, cfg), "walk": longest}}
        for k, val in LITERAL.items():
            c2 = dataclasses.replace(cfg, **{k: val})
            walk = run_clip(store, body, longest["clip"], c2)[0]
            dep[f"{k}={val}"] = {"standing": standing(body, c2), "walk": walk}
            print(f"{k}={val}: standing GRF/weight {dep[f'{k}={val}']['standing']['grf_over_weight']:.3f}, "
                  f"walk GRF/weight {walk['grf_over_weight']:.3f}, joint err {walk['joint_err_cm']:.1f} cm", file=sys.stderr)
        result["departures"] = dep
    if args.plots:
        res, out, ref = first
        plot_grf(out, ref, res["mass_kg"], res["clip"], ROOT / "docs" / "img" / "pip_grf_walk.png")
        if WAVE_CLIP in store.entries:
            wres, wout, wref = run_clip(store, body, WAVE_CLIP, cfg)
            result["wave"] = {"clip": WAVE_CLIP, "grf_over_weight": wres["grf_over_weight"],
                              "torques": plot_wave(wout, wref.fps, WAVE_CLIP, ROOT / "docs" / "img" / "pip_arm_torque_wave.png")}
    tab = Table(title=f"PIP physics on ground-truth {args.split}-split walking ({len(rows)} clips, {result['seconds']:.0f} s)")
    for c in ("", "GRF/weight", "max pen. cm", "stance agree", "trans err mean/final m", "travelled m", "joint err cm",
              "QP ms med/p99", "QP CPU ms med/p99", "step ms med/p99", "step CPU ms med/p99"):
        tab.add_column(c)
    named = [("longest (dual PD)", longest), ("longest (single PD)", single)]
    named += [(f"longest (k_res={k})", r) for k, r in k_res_rows.items()]
    for name, r in named:
        tab.add_row(name, f"{r['grf_over_weight']:.3f}", f"{r['max_penetration_m'] * 100:.2f}", f"{r['stance_agreement']:.2f}",
                    f"{r['trans_err_mean_m']:.3f} / {r['trans_err_final_m']:.3f}", f"{r['travelled_m']:.1f}",
                    f"{r['joint_err_cm']:.1f}", f"{r['qp_ms_median']:.2f} / {r['qp_ms_p99']:.2f}",
                    f"{r['qp_cpu_ms_median']:.2f} / {r['qp_cpu_ms_p99']:.2f}",
                    f"{r['step_ms_median']:.2f} / {r['step_ms_p99']:.2f}",
                    f"{r['step_cpu_ms_median']:.2f} / {r['step_cpu_ms_p99']:.2f}")
    s = summary
    tab.add_row("mean of clips", f"{s['grf_over_weight']:.3f}", f"{s['max_penetration_m'] * 100:.2f} (max)",
                f"{s['stance_agreement']:.2f}", f"{s['trans_err_mean_m']:.3f} / {s['trans_err_final_m']:.3f}",
                f"{s['travelled_m']:.1f}", f"{s['joint_err_cm']:.1f}", f"{s['qp_ms_median_of_clip_medians']:.2f} / -",
                f"{s['qp_cpu_ms_median_of_clip_medians']:.2f} / {s['qp_cpu_ms_p99_max']:.2f} (max)",
                f"{s['step_ms_median_of_clip_medians']:.2f} / {s['step_ms_p99_max']:.2f} (max)",
                f"{s['step_cpu_ms_median_of_clip_medians']:.2f} / {s['step_cpu_ms_p99_max']:.2f} (max)")
    Console().print(tab)
    Console().print(f"load average {result['machine']['load_average_1m']:.1f} on {result['machine']['cpus']} CPUs")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
