"""PIP translation error with and without ``PhysicsConfig.contact_no_lift`` on the 20 test clips of
the previous session's Table 2 (``evaluate_variants(..., "test", 20)``), dual and single PD.

Run: ``taskset -c 0 python benchmarks/pip_dualpd_check.py new|old`` (new: contact_no_lift=True,
the default; old: False). Writes ``benchmarks/results/pip_dualpd_20clips_<new|old>.json``.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import torch

import wearpose.physics.optimizer as O

KEYS = ("translation_error_cm", "final_drift_pct", "jitter_abs_km_s3", "sip_error_deg", "max_penetration_cm")


def main() -> int:
    torch.set_num_threads(1)
    mode = sys.argv[1]
    flag = mode == "new"
    # the estimator builds PhysicsConfig(fps=..., dual_pd=...): switch the field's default here
    orig = O.PhysicsConfig.__init__

    def init(self, *a, **k):  # type: ignore[no-untyped-def]
        k.setdefault("contact_no_lift", flag)
        orig(self, *a, **k)

    O.PhysicsConfig.__init__ = init  # type: ignore[method-assign]
    from wearpose.body import BodyModel
    from wearpose.estimators.pip.estimator import PipEstimator
    from wearpose.estimators.pip.evaluate import evaluate_variants

    body = BodyModel()
    w = "src/wearpose/weights/pip_cpu.pt"
    v = {"PIP": PipEstimator.load(w, body=body, physics=True, dual_pd=True),
         "single PD": PipEstimator.load(w, body=body, physics=True, dual_pd=False)}
    res = evaluate_variants(v, "test", 20)
    out = {n: {k: r[k] for k in KEYS} for n, r in res["rows"].items()}
    print(mode, json.dumps(out))
    path = Path(__file__).parent / "results" / f"pip_dualpd_20clips_{mode}.json"
    path.write_text(json.dumps({"command": f"python benchmarks/pip_dualpd_check.py {mode}", "contact_no_lift": flag,
                                "clips": res["clips"], "frames": res["frames"], "rows": out}, indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
