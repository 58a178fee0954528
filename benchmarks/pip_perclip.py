"""Per-clip PIP diagnostics: translation error, final drift and deepest penetration (frame and
joint) of each clip for the physics variants and the kinematic baseline, to find which motions
drive the split averages of ``pip_eval.py``.

Run: ``taskset -c 0 python benchmarks/pip_perclip.py --split val --limit 30 [--set FIELD=JSON ...]
[--variants PIP "single PD" "w/o physics"] [--clips ID ... | --min-travel M] --out NAME``.
``--min-travel 1.0`` evaluates the clips whose ground truth travels at least 1 m on the ground
plane (the rule of ``pip_dualpd_inputs.py``: :func:`wearpose.estimators.pip.evaluate.clip_travel_m`).
Writes ``benchmarks/results/pip_perclip_<NAME>.json`` (per-clip rows and the split summary).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import torch

RESULTS = Path(__file__).resolve().parent / "results"
VARIANTS = {"PIP": dict(physics=True, dual_pd=True), "single PD": dict(physics=True, dual_pd=False),
            "w/o physics": dict(physics=False)}
SUMMARY = ("translation_error_cm", "final_drift_pct", "jitter_abs_km_s3", "sip_error_deg", "mesh_error_cm",
           "max_penetration_cm", "zmp_distance_m")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--split", default="val")
    ap.add_argument("--limit", type=int, default=None)
    ap.add_argument("--clips", nargs="*", default=None, help="only these clip ids (of the split)")
    ap.add_argument("--min-travel", type=float, default=0.0, help="keep clips whose ground truth travels >= this, m")
    ap.add_argument("--weights", default="src/wearpose/weights/pip_cpu.pt")
    ap.add_argument("--variants", nargs="*", default=list(VARIANTS))
    ap.add_argument("--set", action="append", default=[], metavar="FIELD=JSON", help="PhysicsConfig override")
    ap.add_argument("--out", required=True)
    a = ap.parse_args(argv)
    torch.set_num_threads(1)
    from wearpose.body import BodyModel
    from wearpose.estimators.pip.estimator import PipEstimator
    from wearpose.estimators.pip.evaluate import evaluate_variants
    from wearpose.motion import CorpusStore

    overrides = {k: json.loads(v) for k, v in (s.split("=", 1) for s in a.set)}
    body = BodyModel()
    variants = {}
    for name in a.variants:
        est = PipEstimator.load(a.weights, body=body, **VARIANTS[name])
        est.physics_options = dict(overrides)
        variants[name] = est
    store = CorpusStore()
    if a.clips:
        class _Only:  # the store restricted to the given clips
            def clips(self, split: str) -> list[str]:
                return list(a.clips)

            def load(self, cid: str):  # type: ignore[no-untyped-def]
                return store.load(cid)
        use = _Only()
    else:
        use = store
    t0 = time.time()
    res = evaluate_variants(variants, a.split, a.limit, store=use, min_travel=a.min_travel,
                            progress=lambda d, t: print(f"  {d}/{t} ({time.time() - t0:.0f} s)", file=sys.stderr, flush=True))
    out = {"command": "python " + " ".join([sys.argv[0], *(argv if argv is not None else sys.argv[1:])]),
           "split": a.split, "min_travel_m": a.min_travel, "clips": res["clips"], "frames": res["frames"], "overrides": overrides,
           "summary": {n: {k: r.get(k) for k in SUMMARY} for n, r in res["rows"].items()},
           "ground_truth": res.get("ground_truth"),
           "per_clip": {n: r["per_clip"] for n, r in res["rows"].items()}, "wall_seconds": time.time() - t0}
    print(json.dumps({**out["summary"], "ground truth": out["ground_truth"]}, indent=1))
    path = RESULTS / f"pip_perclip_{a.out}.json"
    path.write_text(json.dumps(out, indent=1))
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
