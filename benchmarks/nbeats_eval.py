"""MIM's N-BEATS wrist forecasters side by side (issue 24: before/after, unseen motion).

Run (CPU, one thread)::

    python benchmarks/nbeats_eval.py v1=src/wearpose/weights/archive/nbeats_cpu_v1.pt v2=nbeats_cpu \\
        --out benchmarks/results/nbeats_test
    python benchmarks/nbeats_eval.py v1=... v2=... --protocol unseen-motion --per-family 3 \\
        --out benchmarks/results/nbeats_unseen_motion

Each model forecasts every window (1 s in, 0.5 s out at 120 Hz, both wrists relative to the
head-worn source, every ``stride`` samples) of the prepared corpus's ``test`` split (per source),
or of the unseen-motion set (``wearpose evaluate --protocol unseen-motion``'s store: procedural
families from the ``eval`` seed namespace, per family), through
:func:`wearpose.interference.nbeats.evaluate_on_store`; the hold-last and constant-velocity
forecasts are the floor any forecaster must beat. Writes ``<out>.{md,json}``.
"""

from __future__ import annotations

import argparse
import json
import platform
import shlex
import sys
import time
from pathlib import Path

import torch

from wearpose.interference.nbeats import evaluate_on_store, load_forecaster
from wearpose.motion import CorpusStore
from wearpose.motion.procedural_store import build_procedural_store, unseen_motion_dir

METRICS = (("mae_cm", "MAE [cm]"), ("mean_err_cm", "mean 3-D error [cm]"), ("err_at_horizon_cm", "error at 0.5 s [cm]"))


def _path(spec: str) -> Path:
    """A checkpoint path, or shipped weights by name."""
    p = Path(spec)
    if p.suffix:
        return p
    from wearpose.weights import weight_path

    return weight_path(spec)


def _table(rows: dict[str, dict[str, float]]) -> list[str]:
    out = ["| forecaster | " + " | ".join(h for _, h in METRICS) + " |", "| --- |" + " ---: |" * len(METRICS)]
    for name, m in rows.items():
        out.append(f"| {name} | " + " | ".join(f"{m[k]:.2f}" for k, _ in METRICS) + " |")
    return out


def _markdown(res: dict, title: str, command: str, seconds: float) -> str:
    models, base = res["models"], res["baselines"]
    first = next(iter(models.values()))
    md = [f"# {title}", "", f"Produced by `{command}` (`wearpose.interference.nbeats.evaluate_on_store`), "
          f"{time.strftime('%Y-%m-%d')}, {seconds:.0f} s.", "",
          f"{res['split']} split of {res['store']}: {res['clips']} clips, {first['all']['windows']} windows "
          "(1 s in, 0.5 s out at 120 Hz; both wrists relative to the head-worn source; ground-truth motion, no "
          "interference, no input noise). MAE per coordinate as MI-Poser reports it.", "",
          *_table({**{n: m["all"] for n, m in models.items()},
                   **{f"({b}, baseline)": v for b, v in base["all"].items()}}), "",
          f"## By {res['group_by']} (MAE [cm]; windows)", "",
          "| " + res["group_by"] + " | windows | " + " | ".join(models) + " | hold | constant velocity |",
          "| --- | ---: |" + " ---: |" * (len(models) + 2)]
    for g in first["groups"]:
        vals = [f"{m['groups'][g]['mae_cm']:.2f}" for m in models.values()]
        b = base["groups"][g]
        md.append(f"| {g} | {first['groups'][g]['windows']} | " + " | ".join(vals)
                  + f" | {b['hold']['mae_cm']:.2f} | {b['constant_velocity']['mae_cm']:.2f} |")
    md += ["", "## Models", "", "| forecaster | checkpoint | epoch | val MAE [cm] | train clips |", "| --- | --- | ---: | ---: | ---: |"]
    for n, info in res["checkpoints"].items():
        md.append(f"| {n} | `{info['path']}` | {info.get('epoch')} | {info.get('val_mae_cm', float('nan')):.3f} | "
                  f"{info.get('train_clips')} |")
    return "\n".join(md) + "\n"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("models", nargs="+", help="NAME=checkpoint path or shipped weights name")
    ap.add_argument("--protocol", choices=("test", "unseen-motion"), default="test")
    ap.add_argument("--per-family", type=int, default=3, help="unseen-motion: clips per family")
    ap.add_argument("--title", default=None)
    ap.add_argument("--out", type=Path, required=True, help="output path without suffix")
    args = ap.parse_args()
    torch.set_num_threads(1)
    t0 = time.time()
    models, info = {}, {}
    for spec in args.models:
        name, _, target = spec.partition("=")
        model, ck = load_forecaster(_path(target))
        models[name] = model
        meta = ck.get("meta") or {}
        info[name] = {"path": target, "epoch": meta.get("epoch"), "val_mae_cm": meta.get("val_mae_cm"),
                      "train_clips": meta.get("train_clips"), "mix": meta.get("mix"), "recipe": (meta.get("recipe") or {}).get("name")}
    if args.protocol == "test":
        store, group, where = CorpusStore(), "source", "the prepared corpus"
    else:
        root = unseen_motion_dir(args.per_family)
        build_procedural_store(root, per_family=args.per_family)
        store, group, where = CorpusStore(root), "subject", f"the unseen-motion set ({args.per_family} clips per family)"
    res = evaluate_on_store(models, store, "test", group_by=group)
    res.update({"store": where, "protocol": args.protocol, "checkpoints": info,
                "provenance": store.provenance()})
    command = "python " + " ".join(shlex.quote(a) for a in ["benchmarks/nbeats_eval.py", *sys.argv[1:]])
    title = args.title or f"N-BEATS wrist forecasters, {args.protocol}"
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.with_suffix(".md").write_text(_markdown(res, title, command, time.time() - t0), encoding="utf-8")
    blob = {**res, "command": command, "machine": {"python": platform.python_version(), "torch": torch.__version__}}
    args.out.with_suffix(".json").write_text(json.dumps(blob, indent=1, default=str) + "\n", encoding="utf-8")
    print(args.out.with_suffix(".md").read_text())


if __name__ == "__main__":
    main()
