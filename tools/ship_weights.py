"""Copy a training checkpoint into the package as shipped weights, with its JSON card.

    python tools/ship_weights.py runs/empose12_cpu/best.pt empose12_cpu \\
        --eval benchmarks/results/empose_table2.json --eval-row LGD-RNN

The optimiser state is dropped (weights + config + kit + body asset + data fingerprint + train
command stay). The card records the training command, data (split, clip count, sources,
licences and the corpus record from the prepared store), validation figures from the checkpoint, test figures from an
evaluation JSON if given, and the file size. Weights trained on CC BY-NC clips are marked
non-commercial.

``training_data.simulation`` (how the training inputs were made from the train split) comes from
the method, ``get_estimator(method).training_data_description(config)``; ``--simulation``
overrides it and is required when the method gives none. ``--notes`` fills the card's ``notes``.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

import torch

from wearpose.errors import ConfigError
from wearpose.estimators import get_estimator
from wearpose.motion import CorpusStore
from wearpose.weights import WEIGHTS_DIR


def training_simulation(ck: dict[str, Any], simulation: str | None = None) -> str:
    """``simulation`` if given, else the method's description of its training data from the
    checkpoint's ``config`` (ConfigError naming the method and ``--simulation`` when it has none)."""
    if simulation:
        return simulation
    try:
        cls = get_estimator(ck["method"])
    except ConfigError:  # a method outside the registry (e.g. a stand-alone model): same remedy
        cls = None
    text = cls.training_data_description(ck["config"]) if cls is not None else None
    if not text:
        raise ConfigError(f"method {ck['method']!r} does not describe its training data; "
                          f"pass --simulation TEXT (how its training inputs were made from the train split)")
    return text


def build_card(ck: dict[str, Any], name: str, *, size_bytes: int, storage: str, shipped_with: str,
               simulation: str | None = None, notes: str | None = None, store: Any = None) -> dict[str, Any]:
    """The JSON card of checkpoint ``ck`` shipped as ``name``.

    Args:
        ck: the checkpoint dict (``method``, ``kit``, ``sensors``, ``body_asset``, ``config``,
            optional ``train_command``, ``data_fingerprint``, ``meta``).
        size_bytes: size of the shipped ``.pt``; storage: how its floats are stored;
        shipped_with: the command that shipped it.
        simulation: ``training_data.simulation`` overriding the method's description.
        notes: the card's ``notes`` (omitted when None).
        store: a :class:`~wearpose.motion.CorpusStore` (default: the prepared corpus) whose train
            split gives clip counts, sources and licences.

    Raises:
        ConfigError: no ``simulation`` and the method gives no description.
    """
    sim = training_simulation(ck, simulation)
    store = store if store is not None else CorpusStore()
    train = [store.entry(c) for c in store.clips(split="train")]
    licences = sorted({e["licence"] for e in train})
    sources = {s: sum(1 for e in train if e["source"] == s) for s in sorted({e["source"] for e in train})}
    card = {
        "name": name,
        "method": ck["method"],
        "kit": ck["kit"],
        "sensors": ck["sensors"],
        "body_asset": ck["body_asset"],
        "config": ck["config"],
        "train_command": ck.get("train_command", ""),
        "training_data": {"split": "train", "clips": len(train), "clips_per_source": sources,
                          "licences": licences, "data_fingerprint": ck.get("data_fingerprint", ""),
                          # which corpus and version the store holds (name, folder, manifest SHA-1)
                          "corpus": store.provenance().get("corpus"), "simulation": sim},
        "licence": ("non-commercial use only: trained on CC BY-NC 4.0 motion (Bandai Namco) and CMU mocap "
                    "(research terms)") if "CC-BY-NC-4.0" in licences else "see training_data.licences",
        "validation": {k: v for k, v in ck.get("meta", {}).items() if k.startswith("val_") or k == "epoch"},
        "size_bytes": size_bytes,
        "storage": storage,
        "shipped_with": shipped_with,
    }
    recipe = ck.get("meta", {}).get("recipe")
    if recipe is not None:  # `wearpose train --recipe`: the resolved recipe reruns it
        card["recipe"] = recipe
    if notes is not None:
        card["notes"] = notes
    return card


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("checkpoint", type=Path)
    ap.add_argument("name")
    ap.add_argument("--eval", type=Path, help="evaluation JSON (benchmarks/empose_eval.py output)")
    ap.add_argument("--eval-row", default=None, help="row of the evaluation JSON describing these weights")
    ap.add_argument("--half", action="store_true",
                    help="store floating weights as float16 (half the file; loaded back into float32 modules)")
    ap.add_argument("--simulation", default=None, metavar="TEXT",
                    help="training_data.simulation of the card (default: the method's description from the config)")
    ap.add_argument("--notes", default=None, metavar="TEXT", help="the card's notes")
    args = ap.parse_args()
    ck = torch.load(args.checkpoint, map_location="cpu", weights_only=True)
    try:  # before writing anything: a card without its training-data sentence is not shipped
        simulation = training_simulation(ck, args.simulation)
    except ConfigError as e:
        ap.error(str(e))
    ck["train_state"] = None
    if args.half:  # the estimators load state dicts into float32 modules, which casts back
        ck["weights"] = {k: v.half() if v.is_floating_point() else v for k, v in ck["weights"].items()}
    out = WEIGHTS_DIR / f"{args.name}.pt"
    torch.save(ck, out)
    shipped_with = (f"python tools/ship_weights.py {args.checkpoint} {args.name}" + (" --half" if args.half else "")
                    + (f" --eval {args.eval} --eval-row {args.eval_row}" if args.eval else "")
                    + (" --simulation '<training_data.simulation>'" if args.simulation else "")
                    + (" --notes '<notes>'" if args.notes is not None else ""))
    card = build_card(ck, args.name, size_bytes=out.stat().st_size,
                      storage="float16 (loaded as float32)" if args.half else "float32", shipped_with=shipped_with,
                      simulation=simulation, notes=args.notes)
    if args.eval:
        res = json.loads(args.eval.read_text())
        rows = res.get("models", res)
        card["test"] = rows.get(args.eval_row, rows) if args.eval_row else rows
    out.with_suffix(".json").write_text(json.dumps(card, indent=2) + "\n")
    print(f"wrote {out} ({card['size_bytes'] / 1e6:.1f} MB) and {out.with_suffix('.json')}")


if __name__ == "__main__":
    main()
