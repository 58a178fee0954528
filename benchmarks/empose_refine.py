"""EM-POSE's measurement-consistency refinement (issue 24, Deliver 4): its effect and its cost.

1. Calibrate the gate on the corpus *validation* split (the training distribution): the
   ``--percentile`` of the shipped model's L_r over the frames of the first ``--val-clips`` val
   clips (:func:`wearpose.estimators.empose.refine.calibrate_threshold`). Nothing is tuned on
   test clips.
2. Evaluate the model without and with ``--steps K`` refinement iterations
   (:func:`wearpose.evaluate.protocols.compare_models`, one simulation per clip shared by every
   row) on the first ``--test-clips`` clips of the corpus test split and on the unseen-motion
   protocol (``--per-family`` clips of each held-out procedural family): MPJPE, PA-MPJPE,
   MPJAE, the fraction of scored frames the gate refines, per motion class.
3. Cost, one thread: the online ``step`` timed frame by frame on the first ``--timing-clips``
   unseen-motion clips, without and with refinement (median ms per frame; the extra on the
   frames the gate refines).

Run::

    python benchmarks/empose_refine.py            # ~10 min on a shared 2-core machine

Writes ``benchmarks/results/empose_refine.md`` and ``.json``.
"""

from __future__ import annotations

import argparse
import json
import platform
import shlex
import statistics
import sys
import time
from pathlib import Path
from typing import Any

import torch

COMPARE = "wearpose.estimators.empose.evaluate:evaluate_models"


def _models(name: str, threshold: float, steps: list[int], gn_steps: list[int], weight: float | None = None,
            centres: tuple[str, ...] = ("learned",), centre_frames: int = 0, centre_every: int = 0) -> dict[str, Any]:
    """The learned model, then one row per L-BFGS iteration count (``refine K``) and per
    Gauss-Newton iteration count and prior centre (``gn K``; ``gn K, recording`` with
    ``refine_centre="recording"``, its turn measured on ``centre_frames`` frames: 0 = the whole
    recording; renewed every ``centre_every`` frames after them), the same gate and prior weight for all."""
    from wearpose.estimators.empose.baselines import load_any
    from wearpose.weights import weight_path

    rows = [("lbfgs", 0, "learned"), *(("lbfgs", k, "learned") for k in steps),
            *(("gn", k, c) for k in gn_steps for c in centres)]
    out = {}
    for solver, k, centre in rows:
        est = load_any(weight_path(name))
        est.set_refine_threshold(threshold)
        est.set_refine_steps(k)
        est.set_refine_solver(solver)
        est.set_refine_centre(centre)
        est.set_refine_centre_frames(centre_frames)
        est.set_refine_centre_every(centre_every)
        if weight is not None:
            est.set_refine_weight(weight)
        label = "learned" if k == 0 else (f"refine {k}" if solver == "lbfgs" else f"gn {k}")
        where = centre if centre == "learned" or not centre_frames else f"{centre}'s first {centre_frames}" + (
            f", every {centre_every}" if centre_every else "")
        out[label if centre == "learned" else f"{label}, {where}"] = est
    return out


def _timing(models: dict[str, Any], store: Any, clips: int) -> dict[str, Any]:
    """Online step times (ms) per model over the first ``clips`` test clips of ``store``, and
    for the refining models the extra on gated frames (median of per-frame differences to the
    learned model on the same frames); with the prior on the recording's first frames also the
    median over the frames that added their solve to the turn and over the others."""
    from wearpose.estimators import iter_frames
    from wearpose.estimators.empose.data import recording_from_clip
    from wearpose.estimators.empose.evaluate import simulate_eval_clip

    first = next(iter(models.values()))
    recs = []
    for cid in store.clips(split="test")[:clips]:
        r = simulate_eval_clip(store.load(cid), first, cid, 0)
        recs.append((r, recording_from_clip(r, first.config)))
    times: dict[str, list[float]] = {}
    gated: dict[str, list[bool]] = {}
    measured: dict[str, list[bool | None]] = {}
    for name, est in models.items():
        times[name], gated[name], measured[name] = [], [], []
        for r, rec in recs:
            est.reset()
            est.set_offsets(r["off_R"], r["off_t"])
            frames = list(iter_frames(rec, est.sensor_names))
            est.step(frames[0])  # the first step traces the online function (~1 s): not timed
            est.reset()
            for f in frames:
                t0 = time.perf_counter()
                out = est.step(f)
                times[name].append((time.perf_counter() - t0) * 1000.0)
                gated[name].append(bool(out.extras.get("refined", False)))
                measured[name].append(out.extras.get("centre_measured"))
    base = times["learned"]
    res: dict[str, Any] = {"frames": len(base), "clips": len(recs), "models": {}}
    for name in models:
        row = {"median_ms": statistics.median(times[name]), "mean_ms": statistics.fmean(times[name]),
               "refined_fraction": sum(gated[name]) / len(gated[name])}
        g = [i for i, x in enumerate(gated[name]) if x]
        if g:
            row["median_ms_refined_frames"] = statistics.median(times[name][i] for i in g)
            row["median_extra_ms_refined_frames"] = statistics.median(times[name][i] - base[i] for i in g)
            row["mean_extra_ms_per_frame"] = statistics.fmean(times[name]) - statistics.fmean(base)
        busy = [t for t, x in zip(times[name], measured[name]) if x is True]
        idle = [t for t, x in zip(times[name], measured[name]) if x is False]
        if busy or idle:  # the prior on the recording's first frames: frames adding their solve, the others
            row.update(frames_measuring_turn=len(busy), median_ms_measuring_turn=statistics.median(busy or [0.0]),
                       median_ms_turned=statistics.median(idle or [0.0]))
        res["models"][name] = row
    return res


def _table(res: dict[str, Any]) -> list[str]:
    lines = ["| model | MPJPE [mm] | PA-MPJPE [mm] | MPJAE [°] | frames refined | estimate time [ms/frame] |",
             "| --- | --- | --- | --- | --- | --- |"]
    for name, m in res["models"].items():
        frac = m.get("refined_fraction")
        lines.append(f"| {name} | {m['mpjpe_mm']:.1f} ± {m['mpjpe_std_mm']:.1f} | {m['pa_mpjpe_mm']:.1f} ± "
                     f"{m['pa_mpjpe_std_mm']:.1f} | {m['mpjae_deg']:.1f} ± {m['mpjae_std_deg']:.1f} | "
                     f"{'-' if frac is None else f'{100 * frac:.1f} %'} | {1000 * m['seconds'] / res['frames']:.2f} |")
    return lines


def _by_class(res: dict[str, Any]) -> list[str]:
    names = list(res["models"])
    lines = ["| class | clips | frames | " + " | ".join(f"MPJPE {n}" for n in names) + " | "
             + " | ".join(f"refined {n}" for n in names[1:]) + " |",
             "| --- | --- | --- | " + " | ".join("---" for _ in range(2 * len(names) - 1)) + " |"]
    first = res["models"][names[0]]["breakdown"]["class"]
    for cls, row in first.items():
        cells = [f"{res['models'][n]['breakdown']['class'][cls]['mpjpe_mm']:.1f}" for n in names]
        cells += [f"{100 * res['models'][n]['breakdown']['class'][cls].get('refined_fraction', 0.0):.0f} %"
                  for n in names[1:]]
        lines.append(f"| {cls} | {row['clips']} | {row['frames']} | " + " | ".join(cells) + " |")
    return lines


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--model", default="empose12_cpu")
    ap.add_argument("--steps", type=int, nargs="*", default=[5, 20], help="L-BFGS iterations, one row each")
    ap.add_argument("--gn-steps", type=int, nargs="*", default=[2, 5], help="Gauss-Newton iterations, one row each")
    ap.add_argument("--gate", choices=("none", "val"), default="none",
                    help="none: refine every frame (the default setting, threshold 0); val: frames over the "
                         "--percentile of the learned L_r on validation clips")
    ap.add_argument("--weight", type=float, default=None, help="the prior weight (default: the config's)")
    ap.add_argument("--centre", nargs="+", choices=("learned", "recording"), default=["learned"],
                    help="the Gauss-Newton rows' prior centres, one row each (recording: offline only and not "
                         "timed unless --centre-frames)")
    ap.add_argument("--centre-frames", type=int, default=0,
                    help="recording centre: measure the turn on the first N valid frames (refine_centre_frames; "
                         "online too, so those rows are timed); 0 = the whole recording")
    ap.add_argument("--centre-every", type=int, default=0,
                    help="with --centre-frames: renew the turn at every K-th valid frame after them "
                         "(refine_centre_every)")
    ap.add_argument("--percentile", type=float, default=95.0)
    ap.add_argument("--val-clips", type=int, default=20)
    ap.add_argument("--test-clips", type=int, default=10)
    ap.add_argument("--per-family", type=int, default=2)
    ap.add_argument("--timing-clips", type=int, default=2)
    ap.add_argument("--calibration-error", type=float, nargs=2, default=[0.0, 0.0], metavar=("DEG", "MM"),
                    help="give the models offsets off the simulated ones by DEG and MM per sensor (a calibration's "
                         "error; the gate is calibrated without it)")
    ap.add_argument("--out", default=str(Path(__file__).parent / "results" / "empose_refine"))
    a = ap.parse_args(argv)
    torch.set_num_threads(1)
    from wearpose.estimators.empose.baselines import load_any
    from wearpose.estimators.empose.refine import calibrate_threshold
    from wearpose.evaluate.protocols import compare_models, unseen_motion_store
    from wearpose.motion import CorpusStore
    from wearpose.weights import weight_path

    corpus = CorpusStore()
    cal = calibrate_threshold(load_any(weight_path(a.model)), corpus, clips=a.val_clips, percentile=a.percentile)
    print(f"gate: L_r > {cal['threshold']:.4g} ({a.percentile:g}th percentile over {cal['frames']} val frames)"
          f"{'' if a.gate == 'val' else ', not used (--gate none: every frame)'}", flush=True)
    threshold = cal["threshold"] if a.gate == "val" else 0.0
    unseen = unseen_motion_store(a.per_family)
    results = {}
    for key, store, clips in (("test", corpus, a.test_clips), ("unseen_motion", unseen, None)):
        models = _models(a.model, threshold, a.steps, a.gn_steps, a.weight, tuple(a.centre), a.centre_frames,
                         a.centre_every)
        results[key] = compare_models(COMPARE, models, "test", clips, store=store,
                                      calibration_error=tuple(a.calibration_error))
        for m in results[key]["models"].values():
            m["checkpoint"] = str(weight_path(a.model))
        print(key, {n: round(m["mpjpe_mm"], 2) for n, m in results[key]["models"].items()}, flush=True)
    # A step refuses the prior on the whole recording; on its first frames it runs online.
    online = _models(a.model, threshold, a.steps, a.gn_steps, a.weight,
                     tuple(a.centre) if a.centre_frames else ("learned",), a.centre_frames, a.centre_every)
    timing = _timing(online, unseen, a.timing_clips)
    command = "python benchmarks/" + " ".join(shlex.quote(x) for x in [Path(__file__).name, *sys.argv[1:]])
    refined = results["unseen_motion"]["models"]
    weight = next(iter(refined.values()))["config"]["refine_weight"]
    md = [f"# EM-POSE measurement-consistency refinement ({a.model})", "",
          f"Produced by `{command}` (`wearpose.estimators.empose.refine`).", "",
          (f"Gate: L_r > **{cal['threshold']:.4g}** (m² + squared Frobenius, summed over the 12 sensors), the "
           f"{a.percentile:g}th percentile of the learned estimate's L_r over {cal['frames']} frames of the first "
           f"{cal['clips']} corpus *validation* clips (median {cal['rec_median']:.4g}, 99th percentile "
           f"{cal['rec_p99']:.4g}); nothing was tuned on the test clips. " if a.gate == "val" else
           f"No gate: every frame is refined (threshold 0; the validation clips' learned L_r has median "
           f"{cal['rec_median']:.4g} and 95th percentile {cal['threshold']:.4g}). ")
          + "Refinement: K iterations on L_r + "
          f"{weight:g} ||u - u_learned||² (6D pose of the 20 estimated joints; shape held), refined frames only, "
          "then the root from the EM source's skin site: `refine K` L-BFGS, `gn K` Levenberg-Marquardt "
          "Gauss-Newton (`refine_solver=gn`); `gn K, recording` the same with the prior centred on the learned pose "
          "turned by the recording's per-joint turn (`refine_centre=recording`; "
          + (f"measured on the first {a.centre_frames} valid frames, `refine_centre_frames={a.centre_frames}`, online "
             "too: a step measures it on those frames and uses it from the last of them on, so its cost table splits "
             "the two)." if a.centre_frames else "offline only, so not in the online cost table)."), "",
          f"## Corpus test split, first {a.test_clips} clips (in-lab)", "", *_table(results["test"]), "",
          f"## Unseen motion ({a.per_family} clips per held-out procedural family)", "",
          *_table(results["unseen_motion"]), "", "By family (frame-weighted means of each clip's figures):", "",
          *_by_class(results["unseen_motion"]), "",
          f"Setting of both: {results['test']['subjects']}; EM noise {results['test']['noise']}; "
          + (f"the models were given offsets {a.calibration_error[0]:g} deg and {a.calibration_error[1]:g} mm off the "
             "simulated ones per sensor (a calibration's error, seeded per clip); " if any(a.calibration_error) else "")
          + "15 major joints, "
          "frames with every sensor valid, mean ± std over frames. Estimate time: offline `estimate`, one thread, "
          "on a shared machine.", "",
          f"## Cost of the online step (one thread, {timing['frames']} frames of the first {timing['clips']} "
          "unseen-motion clips)", "",
          "| model | median [ms/frame] | mean [ms/frame] | frames refined | median on refined frames [ms] | "
          "median extra on refined frames [ms] | mean extra per frame [ms] |",
          "| --- | --- | --- | --- | --- | --- | --- |"]
    for name, r in timing["models"].items():
        g = lambda k: f"{r[k]:.2f}" if k in r else "-"  # noqa: E731
        md.append(f"| {name} | {r['median_ms']:.2f} | {r['mean_ms']:.2f} | {100 * r['refined_fraction']:.0f} % | "
                  f"{g('median_ms_refined_frames')} | {g('median_extra_ms_refined_frames')} | "
                  f"{g('mean_extra_ms_per_frame')} |")
    turning = {n: r for n, r in timing["models"].items() if "frames_measuring_turn" in r}
    if turning:
        md += ["", "With the prior on the recording's first frames, the step on a frame that adds its solve to the turn "
               "(one more Gauss-Newton solve, without the prior) and on the others:", "",
               "| model | frames measuring | median while measuring [ms] | median on the others [ms] |",
               "| --- | --- | --- | --- |",
               *(f"| {n} | {r['frames_measuring_turn']} | {r['median_ms_measuring_turn']:.2f} | "
                 f"{r['median_ms_turned']:.2f} |" for n, r in turning.items())]
    stem = Path(a.out)
    stem.parent.mkdir(parents=True, exist_ok=True)
    stem.with_suffix(".md").write_text("\n".join(md) + "\n")
    stem.with_suffix(".json").write_text(json.dumps(
        {"command": command, "calibration": cal, "results": results, "online_step_cost": timing,
         "machine": {"python": platform.python_version(), "torch": torch.__version__, "threads": 1,
                     "platform": platform.platform()}}, indent=1, default=str) + "\n")
    print(f"wrote {stem.with_suffix('.md')} and .json")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
