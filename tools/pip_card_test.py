"""Fill a shipped PIP card's ``test`` block from the Table 2 and walking-GRF benchmark JSONs.

    python tools/pip_card_test.py pip_cpu benchmarks/results/pip_table2_arms.json \\
        benchmarks/results/pip_grf_test_arms.json

``tools/ship_weights.py`` takes one evaluation row; a PIP card reports the "PIP" row of
``benchmarks/pip_eval.py`` (physics, dual PD, learned init) and the walking ground reaction
force of ``benchmarks/pip_grf.py``, so this fills both (the scalar metrics only; the per-clip
rows stay in the JSONs). The Table 2 row and the GRF run must have been measured with the
checkpoint the card was shipped from (its ``shipped_with`` command), else the script refuses.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from wearpose.weights import WEIGHTS_DIR

KEYS = ("sip_error_deg", "angular_error_deg", "positional_error_cm", "mesh_error_cm", "jitter_abs_km_s3",
        "jitter_rel_km_s3", "translation_error_cm", "final_drift_pct", "max_penetration_cm", "zmp_distance_m")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("name", help="shipped weights name (src/wearpose/weights/<name>.json)")
    ap.add_argument("table2", type=Path, help="benchmarks/pip_eval.py JSON")
    ap.add_argument("grf", type=Path, help="benchmarks/pip_grf.py JSON (test split)")
    ap.add_argument("--row", default="PIP")
    a = ap.parse_args()
    card_path = WEIGHTS_DIR / f"{a.name}.json"
    card = json.loads(card_path.read_text())
    t2 = json.loads(a.table2.read_text())
    row = t2["rows"][a.row]
    source = card["shipped_with"].split()[2]  # "python tools/ship_weights.py <checkpoint> <name> ..."
    grf = json.loads(a.grf.read_text())
    for path, used in ((a.table2, row.get("checkpoint")), (a.grf, grf.get("weights"))):
        if used != source:
            raise SystemExit(f"{path}: measured with {used!r}, but {card_path} was shipped from {source!r}")
    if grf.get("split") != "test":
        raise SystemExit(f"{a.grf}: split {grf.get('split')!r}, expected the test split")
    g = grf["summary_time_weighted"]
    card["test"] = {**{k: row[k] for k in KEYS}, "split": t2["split"], "clips": t2["clips"], "frames": t2["frames"],
                    "row": f"{a.row} (physics, dual PD, learned init)" if a.row == "PIP" else a.row,
                    "protocol": t2["protocol"], "source": str(a.table2),
                    "walking_grf_over_weight": g["grf_over_weight"],
                    "walking_grf_clips_within_15pct": f"{g['clips_within_15pct']}/{g['clips']}",
                    "walking_grf_source": f"{a.grf} ({g['clips']} test walking clips)"}
    card_path.write_text(json.dumps(card, indent=2) + "\n")
    print(f"wrote the test block of {card_path}")


if __name__ == "__main__":
    main()
