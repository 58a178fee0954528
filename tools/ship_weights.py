"""Copy a training checkpoint into the package as shipped weights, with its JSON card.

    python tools/ship_weights.py runs/empose12_cpu/best.pt empose12_cpu \\
        --eval benchmarks/results/empose_table2.json --eval-row LGD-RNN

The optimiser state is dropped (weights + config + kit + body asset + data fingerprint + train
command stay). The card records the training command, data (split, clip count, sources and
licences from the prepared store), validation figures from the checkpoint, test figures from an
evaluation JSON if given, and the file size. Weights trained on CC BY-NC clips are marked
non-commercial.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import torch

from wearpose.motion import CorpusStore
from wearpose.weights import WEIGHTS_DIR


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("checkpoint", type=Path)
    ap.add_argument("name")
    ap.add_argument("--eval", type=Path, help="evaluation JSON (benchmarks/empose_eval.py output)")
    ap.add_argument("--eval-row", default=None, help="row of the evaluation JSON describing these weights")
    ap.add_argument("--half", action="store_true",
                    help="store floating weights as float16 (half the file; loaded back into float32 modules)")
    args = ap.parse_args()
    ck = torch.load(args.checkpoint, map_location="cpu", weights_only=True)
    ck["train_state"] = None
    if args.half:  # the estimators load state dicts into float32 modules, which casts back
        ck["weights"] = {k: v.half() if v.is_floating_point() else v for k, v in ck["weights"].items()}
    out = WEIGHTS_DIR / f"{args.name}.pt"
    torch.save(ck, out)
    store = CorpusStore()
    train = [store.entry(c) for c in store.clips(split="train")]
    licences = sorted({e["licence"] for e in train})
    sources = {s: sum(1 for e in train if e["source"] == s) for s in sorted({e["source"] for e in train})}
    card = {
        "name": args.name,
        "method": ck["method"],
        "kit": ck["kit"],
        "sensors": ck["sensors"],
        "body_asset": ck["body_asset"],
        "config": ck["config"],
        "train_command": ck.get("train_command", ""),
        "training_data": {"split": "train", "clips": len(train), "clips_per_source": sources,
                          "licences": licences, "data_fingerprint": ck.get("data_fingerprint", ""),
                          "simulation": "virtual EM sensors (wearpose.sensors.simulate, default noise, random subject offsets per clip)"},
        "licence": ("non-commercial use only: trained on CC BY-NC 4.0 motion (Bandai Namco) and CMU mocap "
                    "(research terms)") if "CC-BY-NC-4.0" in licences else "see training_data.licences",
        "validation": {k: v for k, v in ck.get("meta", {}).items() if k.startswith("val_") or k == "epoch"},
        "size_bytes": out.stat().st_size,
        "storage": "float16 (loaded as float32)" if args.half else "float32",
        "shipped_with": f"python tools/ship_weights.py {args.checkpoint} {args.name}" + (" --half" if args.half else "")
                        + (f" --eval {args.eval} --eval-row {args.eval_row}" if args.eval else ""),
    }
    if args.eval:
        res = json.loads(args.eval.read_text())
        rows = res.get("models", res)
        card["test"] = rows.get(args.eval_row, rows) if args.eval_row else rows
    out.with_suffix(".json").write_text(json.dumps(card, indent=2) + "\n")
    print(f"wrote {out} ({card['size_bytes'] / 1e6:.1f} MB) and {out.with_suffix('.json')}")


if __name__ == "__main__":
    main()
