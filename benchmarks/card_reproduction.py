"""Do today's code and `wearpose evaluate` reproduce every shipped weight's card? (issue 21)

Run each model's test-split evaluation first, writing ``DIR/<model>.json``::

    wearpose evaluate empose12_cpu --threads 1 --out DIR/empose12_cpu          # and empose6_cpu
    wearpose evaluate pip_cpu --threads 1 --out DIR/pip_cpu                    # and birae6_cpu, birae3_cpu
    wearpose evaluate miposer_cpu --frame-stride 4 --threads 1 --out DIR/miposer_cpu
    wearpose evaluate miposer1_cpu --frame-stride 4 --threads 1 --out DIR/miposer1_cpu
    wearpose evaluate imuposer_cpu --frame-stride 4 --threads 1 --out DIR/imuposer_cpu
    python benchmarks/empose_table10.py --ckpt 2-stage=src/wearpose/weights/empose12_twostage_cpu.pt --out DIR/table10_twostage
    python benchmarks/nbeats_eval.py nbeats_cpu=nbeats_cpu --out DIR/nbeats_cpu

then ``python benchmarks/card_reproduction.py DIR``: a table of each card's headline test figures
beside the re-measured ones (relative difference), written to
``benchmarks/results/card_reproduction.{md,json}``. The two-stage model's card figures are EM-POSE
Table 10's dropped-sensor protocol, so it is compared through that benchmark's output.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from wearpose.weights import card

#: model -> [(label, path in the card's "test" block, path in the evaluation's model entry)].
FIGURES: dict[str, list[tuple[str, tuple[str, ...], tuple[str, ...]]]] = {
    **{m: [("MPJPE mm", ("mpjpe_mm",), ("mpjpe_mm",)), ("PA-MPJPE mm", ("pa_mpjpe_mm",), ("pa_mpjpe_mm",)),
           ("MPJAE deg", ("mpjae_deg",), ("mpjae_deg",))] for m in ("empose12_cpu", "empose6_cpu")},
    "empose12_twostage_cpu": [(f"{s}: MPJPE mm", ("sets", s, "mpjpe_mm"), ("sets", s, "mpjpe_mm"))
                              for s in ("all", "avail", "miss")],
    # MIM's forecaster: its card's test block is nbeats.ship_tested's, the benchmark's "all" the same windows
    "nbeats_cpu": [(f"test {k}", (k,), ("all", k)) for k in ("mae_cm", "mean_err_cm", "err_at_horizon_cm")],
    "pip_cpu": [(k, (k,), ("metrics", k)) for k in (
        "sip_error_deg", "angular_error_deg", "positional_error_cm", "mesh_error_cm", "jitter_abs_km_s3",
        "translation_error_cm")],
    **{m: [(f"clean {k}", ("clean", k), ("metrics", k)) for k in (
        "mpjae_all_deg", "mpjae_distal_deg", "mpjae_tracking_deg", "mpjae_other_deg")]
       for m in ("birae6_cpu", "birae3_cpu")},
    # miposer_cpu's card (version 2, shipped from `wearpose evaluate`'s JSON) has the evaluation's own
    # flat keys; miposer1_cpu's (version 2) and imuposer_cpu's (version 3) keep them under "metrics"
    "miposer_cpu": [(f"{c} upper MPJPE cm", (f"{c}_mpjpe_upper_cm",), ("metrics", f"{c}_mpjpe_upper_cm"))
                    for c in ("calibrated", "uncalibrated")],
    "miposer1_cpu": [(f"{c} upper MPJPE cm", ("metrics", f"{c}_mpjpe_upper_cm"), ("metrics", f"{c}_mpjpe_upper_cm"))
                     for c in ("calibrated", "uncalibrated")],
    "imuposer_cpu": [("upper MPJPE cm", ("metrics", "mpjpe_upper_cm"), ("metrics", "mpjpe_upper_cm"))],
}


def _get(d: dict[str, Any], path: tuple[str, ...]) -> float | None:
    for k in path:
        if not isinstance(d, dict) or k not in d:
            return None
        d = d[k]
    return float(d) if isinstance(d, (int, float)) else None


def _measured(root: Path, model: str) -> tuple[dict[str, Any] | None, str]:
    if model == "empose12_twostage_cpu":
        f = root / "table10_twostage.json"
        return (json.loads(f.read_text())["models"].get("2-stage") if f.is_file() else None), f.name
    f = root / f"{model}.json"
    return (json.loads(f.read_text())["models"].get(model) if f.is_file() else None), f.name


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("dir", type=Path, help="folder with the evaluations' JSON files")
    ap.add_argument("--note", default=None, help="a paragraph appended to the markdown")
    ap.add_argument("--out", type=Path, default=Path(__file__).parent / "results" / "card_reproduction")
    args = ap.parse_args()
    rows = []
    for model, figures in FIGURES.items():
        got, name = _measured(args.dir, model)
        test = card(model).get("test", {})
        for label, cpath, mpath in figures:
            c, m = _get(test, cpath), _get(got or {}, mpath)
            rel = None if c in (None, 0) or m is None else (m - c) / abs(c)
            rows.append({"model": model, "figure": label, "card": c, "measured": m, "relative_difference": rel,
                         "from": name if got else None})
    md = ["# Shipped weights' cards reproduced by today's code", "",
          "`python benchmarks/card_reproduction.py DIR` after the evaluations its docstring lists (full test split, "
          "the cards' frame strides, seed 0).", "",
          "| model | figure | card | measured | difference |", "| --- | --- | ---: | ---: | ---: |"]
    for r in rows:
        fmt = (lambda v: "missing" if v is None else f"{v:.4f}")
        diff = "n/a" if r["relative_difference"] is None else f"{100 * r['relative_difference']:+.3f} %"
        md.append(f"| {r['model']} | {r['figure']} | {fmt(r['card'])} | {fmt(r['measured'])} | {diff} |")
    if args.note:
        md += ["", args.note]
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.with_suffix(".md").write_text("\n".join(md) + "\n")
    args.out.with_suffix(".json").write_text(json.dumps({"rows": rows}, indent=2) + "\n")
    print("\n".join(md))


if __name__ == "__main__":
    main()
