"""PIP long-sitting test alone (Fig. 6 / Fig. 9): :func:`wearpose.estimators.pip.evaluate.sitting_drift`
for learned-init / no-init checkpoint pairs, both starts, ``--hours`` of still seated input.

Run: ``taskset -c 0 python benchmarks/pip_sitting.py --hours 4.63 --pair LABEL FULL NOINIT [...]``.
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
    ap.add_argument("--out", type=Path, default=Path(__file__).parent / "results" / "pip_sitting.json")
    a = ap.parse_args()
    torch.set_num_threads(1)
    from wearpose.body import BodyModel
    from wearpose.estimators.pip.estimator import PipEstimator
    from wearpose.estimators.pip.evaluate import sitting_drift

    body, rows = BodyModel(), []
    for label, full, noinit in a.pair:
        for init, path in (("learned init", full), ("w/o learned init", noinit)):
            est = PipEstimator.load(path, body=body, physics=False)
            for start in ("standing", "seated"):
                s = sitting_drift(est, hours=a.hours, start=start)
                s.update(model=f"{label}, {init}", checkpoint=path)
                rows.append(s)
                print(f"{s['model']} {start}: upper legs {s['upper_leg_error_at_start_deg']:.1f} -> "
                      f"{s['upper_leg_error_at_end_deg']:.1f} deg, all joints {s['error_at_start_deg']:.2f} -> "
                      f"{s['error_at_end_deg']:.2f} deg, drift {s['drift_total_deg']:.2f} deg", flush=True)
    a.out.write_text(json.dumps({"command": "python " + " ".join(sys.argv), "hours": a.hours, "rows": rows,
                                 "time_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}, indent=2))
    print(f"wrote {a.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
