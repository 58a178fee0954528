"""Ship a calibrated BiRAE checkpoint as package weights with a complete card.

Run (after ``benchmarks/birae_eval.py ... --sections tables,calibration --save-calibrated``)::

    python benchmarks/birae_ship.py runs/birae6_v3/calibrated.pt birae6_cpu --row 6param --notes "..."

1. ``tools/ship_weights.py <checkpoint> <name>`` writes ``src/wearpose/weights/<name>.pt`` and the
   generic card (command, training data, licence, validation figures, size).
2. The card then gets the BiRAE parts: input representation, the sigma calibration stored in the
   checkpoint, the test figures of ``--row`` from ``benchmarks/results/birae_tables.json`` and
   ``birae_calibration.json`` (which must have evaluated this checkpoint's run), the training
   chain and budget (:func:`wearpose.estimators.birae.evaluate.training_chain`) and every
   command of that chain (``train_commands_all``: commands recorded by the previous card for
   runs still in the chain, else the runs' own commands).
"""

from __future__ import annotations

import argparse
import json
import re
import shlex
import subprocess
import sys
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
RESULTS = Path(__file__).parent / "results"
SIMULATION = ("ideal mimu6 segment orientations by forward kinematics (60 Hz); phase 1 ideal, phase 2 augmented "
              "with 1 deg white noise, impulses (p=0.002, 5 deg), 0.5 deg/s yaw-rate bias "
              "(wearpose.estimators.birae.data)")


def _uses_out(command: str, run: str) -> bool:
    return re.search(rf"--out[ =]{re.escape(run)}(/|\s|$)", command) is not None


def history(chain: list[dict[str, Any]], previous: list[str]) -> list[str]:
    """Every training command of the chain, oldest first (see module doc)."""
    out: list[str] = []
    for c in chain:
        known = [p for p in previous if c["run"] and _uses_out(p, c["run"])]
        if known:
            out += known
            continue
        out.append(c["command"])
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("checkpoint", type=Path, help="calibrated checkpoint (birae_eval.py --save-calibrated)")
    ap.add_argument("name", help="weights name, e.g. birae6_cpu")
    ap.add_argument("--row", required=True, help="row (--ckpt NAME) of the evaluation JSONs describing these weights")
    ap.add_argument("--tables", type=Path, default=RESULTS / "birae_tables.json")
    ap.add_argument("--calibration", type=Path, default=RESULTS / "birae_calibration.json")
    ap.add_argument("--notes", default="")
    a = ap.parse_args(argv)
    import torch

    from wearpose.estimators.birae.evaluate import budget_summary, training_chain
    from wearpose.estimators.checkpoint import load_checkpoint
    from wearpose.weights import WEIGHTS_DIR

    ck = load_checkpoint(a.checkpoint)
    if not ck.meta.get("calibration"):
        ap.error(f"{a.checkpoint}: no sigma calibration in the checkpoint (run birae_eval.py --save-calibrated)")
    tables, cal = json.loads(a.tables.read_text()), json.loads(a.calibration.read_text())
    for path, js in ((a.tables, tables), (a.calibration, cal)):
        src = js.get("checkpoints", {}).get(a.row)
        if src is None or Path(src).resolve().parent != a.checkpoint.resolve().parent:
            ap.error(f"{path}: row {a.row!r} evaluated {src!r}, not the run of {a.checkpoint}")
    old_card = WEIGHTS_DIR / f"{a.name}.json"
    previous = json.loads(old_card.read_text()).get("train_commands_all", []) if old_card.is_file() else []
    subprocess.run([sys.executable, str(ROOT / "tools" / "ship_weights.py"), str(a.checkpoint), a.name], check=True, cwd=ROOT)
    card = json.loads(old_card.read_text())
    chain = training_chain(a.checkpoint)
    card["training_data"]["simulation"] = SIMULATION
    card["rep"] = ck.config["rep"]
    card["calibration"] = ck.meta["calibration"]
    card["sigma_scale"] = ck.meta.get("sigma_scale", 1.0)
    card["test"] = tables["results"][a.row]
    card["test_degradation_pct"] = tables["degradation_pct"][a.row]
    card["test_calibration"] = {k: ({kk: vv for kk, vv in v.items() if kk != "reliability"} if isinstance(v, dict) else v)
                                for k, v in cal["results"][a.row].items() if k != "fit"}
    card["test_command"] = tables["command"] + ("" if cal["command"] == tables["command"] else f"; {cal['command']}")
    card["training_budget"] = {**budget_summary(chain), "chain": chain}
    card["train_commands_all"] = history(chain, previous)
    args = list(argv if argv is not None else sys.argv[1:])
    if "--notes" in args:  # the notes are in the card already
        i = args.index("--notes")
        args[i:i + 2] = ["--notes", "<notes>"]
    card["shipped_with"] = (f"python {shlex.join(['benchmarks/birae_ship.py', *args])}"
                            f" (runs: {card.get('shipped_with', 'tools/ship_weights.py')})")
    if a.notes:
        card["notes"] = a.notes
    else:
        card.pop("notes", None)
    old_card.write_text(json.dumps(card, indent=2, default=float) + "\n")
    w = torch.load(WEIGHTS_DIR / f"{a.name}.pt", map_location="cpu", weights_only=True)
    print(f"{a.name}: rep {card['rep']}, sigma scale {card['sigma_scale']:.3f}, val {card['validation'].get('val_mpjae_deg')}, "
          f"budget {card['training_budget']['text']}; {len(w['weights'])} tensors")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
