"""Does a recipe, rerun, reproduce its weights? (issue 24: validation within 2 %)

Rerun a recipe into a fresh folder, then compare the rerun's kept checkpoint with the reference
(the shipped weights of that name, or a checkpoint of an earlier run of a recipe that ships
nothing)::

    wearpose train --recipe miposer_cpu_v2 --out runs/miposer_rerun
    python benchmarks/recipe_reproduction.py miposer_cpu_v2=runs/miposer_rerun/best.pt:miposer_cpu \\
        empose12_bandai=runs/empose12_bandai_rerun/best.pt:runs/empose12_bandai/best.pt

Each ``RECIPE=RERUN:REFERENCE`` (REFERENCE: shipped weights' name or a checkpoint path) gives a
row: the validation figures both checkpoints recorded when they were kept (``meta``: every
``val_*`` number, the epoch), their relative difference, the largest absolute difference between
the two sets of weights (0 = bit-identical; a float16 shipped file is compared after upcasting)
and whether both trained on the same data (data fingerprint). The headline is each method's
checkpoint-selection figure (``wearpose.estimators.recipe.selection_metric``); the row passes when it is within ``--tolerance``
(2 %). Writes ``benchmarks/results/recipe_reproduction.{md,json}``; a rerun of another recipe
replaces that recipe's row and keeps the others.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

import torch

from wearpose.estimators.recipe import reproduction
from wearpose.weights import list_weights, weight_path

RESULTS = Path(__file__).parent / "results"


def _reference(ref: str) -> tuple[Path, str]:
    """The reference checkpoint and how it was named (shipped weights or a path)."""
    if ref in list_weights():
        return weight_path(ref), f"shipped {ref}"
    return Path(ref), ref


def markdown(rows: list[dict[str, Any]], tolerance: float) -> str:
    lines = ["# Recipe reruns against their weights", "",
             f"Each recipe rerun with `wearpose train --recipe NAME` into a fresh folder on this machine (one CPU thread), "
             f"its kept checkpoint compared with the reference. Passes: the headline validation figure within "
             f"{100 * tolerance:g} %. Produced by `python benchmarks/recipe_reproduction.py` (module doc).", "",
             "| recipe | reference | headline | rerun | reference | difference | epoch (rerun / ref.) | max weight diff. | same data | passes |",
             "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    for r in rows:
        h = r["figures"].get(r["headline"], {})
        rel = h.get("relative")
        wd = r["max_abs_weight_difference"]
        lines.append(f"| `{r['recipe']}` | {r['reference']} | {r['headline']} | {h.get('rerun', float('nan')):.4f} | "
                     f"{h.get('reference', float('nan')):.4f} | {'' if rel is None else f'{100 * rel:+.2f} %'} | "
                     f"{r['epoch']['rerun']} / {r['epoch']['reference']} | {'tensor sets differ' if wd is None else f'{wd:.3g}'} | "
                     f"{'yes' if r['same_data'] else 'no'} | {'yes' if r['passes'] else '**no**'} |")
    lines += ["", "Commands:", ""] + [f"- `{r['recipe']}`: `{r['command']}`" for r in rows if r.get("command")]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("pairs", nargs="+", metavar="RECIPE=RERUN:REFERENCE")
    ap.add_argument("--tolerance", type=float, default=0.02)
    ap.add_argument("--out", type=Path, default=RESULTS / "recipe_reproduction.json")
    a = ap.parse_args(argv)
    torch.set_num_threads(1)
    old = json.loads(a.out.read_text())["rows"] if a.out.is_file() else []
    rows = {r["recipe"]: r for r in old}
    for p in a.pairs:
        recipe, _, rest = p.partition("=")
        rerun, _, ref = rest.partition(":")
        if not (recipe and rerun and ref):
            ap.error(f"{p!r}: expected RECIPE=RERUN:REFERENCE")
        path, label = _reference(ref)
        rows[recipe] = {**reproduction(recipe, rerun, path, a.tolerance), "reference": label, "reference_path": str(path),
                        "command": f"python benchmarks/recipe_reproduction.py {p}",
                        "time_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}
    out = sorted(rows.values(), key=lambda r: r["recipe"])
    a.out.parent.mkdir(parents=True, exist_ok=True)
    a.out.write_text(json.dumps({"tolerance": a.tolerance, "rows": out}, indent=1) + "\n")
    md = markdown(out, a.tolerance)
    a.out.with_suffix(".md").write_text(md)
    print(md)
    return 0 if all(r["passes"] for r in out) else 1


if __name__ == "__main__":
    sys.exit(main())
