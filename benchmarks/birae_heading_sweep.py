"""How much can a heading error cost each BiRAE model at most? MPJAE under growing per-sensor
heading offsets (the dose-response behind Table 4).

Run: ``taskset -c 1 python benchmarks/birae_heading_sweep.py --ckpt 6param=PATH --ckpt 3param=PATH
[--offsets 0 15 45 90 180] [--split test] [--limit N] [--mc 10] [--out NAME]``.

Each model estimates the ``noise`` scenario of the split (Table 2's "real sensor" level) with every
sensor's world orientation turned about the vertical by its own constant angle ``U(-a, a)``
(seeded per clip; :func:`wearpose.estimators.birae.evaluate.scenario_recordings`), for each ``a`` of
``--offsets``. ``a = 180`` makes every sensor's heading uniformly random: no magnetic disturbance
can destroy more heading information than that, so its degradation bounds what any Table 4
scenario can do to the model. Offline, MC-dropout mean (``--mc``; default the config's M).
Writes ``benchmarks/results/birae_heading_sweep[_NAME].json/.md``.
"""

from __future__ import annotations

import argparse
import json
import shlex
import sys
import time
from pathlib import Path
from typing import Any

import torch

RESULTS = Path(__file__).resolve().parent / "results"
GROUPS = ("distal", "tracking", "other", "all")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--ckpt", action="append", required=True, metavar="NAME=PATH")
    ap.add_argument("--offsets", type=float, nargs="+", default=[0.0, 15.0, 45.0, 90.0, 180.0])
    ap.add_argument("--split", default="test")
    ap.add_argument("--limit", type=int, default=None)
    ap.add_argument("--mc", type=int, default=None)
    ap.add_argument("--out", default=None)
    a = ap.parse_args(argv)
    torch.set_num_threads(1)
    from wearpose.estimators.birae import BiraeEstimator
    from wearpose.estimators.birae.evaluate import evaluate, scenario_recordings

    ests: dict[str, Any] = {}
    paths: dict[str, str] = {}
    for spec in a.ckpt:
        name, sep, path = spec.partition("=")
        if not sep or not Path(path).is_file():
            ap.error(f"--ckpt {spec!r}: expected NAME=PATH to an existing checkpoint")
        ests[name], paths[name] = BiraeEstimator.load(path), path
    t0 = time.time()
    res: dict[str, dict[str, dict[str, float]]] = {n: {} for n in ests}
    for off in a.offsets:
        recs = scenario_recordings(a.split, "noise", 60.0, a.limit, heading_offset_deg=off)
        for n, e in ests.items():
            r = evaluate(e, recs, mc_samples=a.mc)
            res[n][f"{off:g}"] = {g: r[f"mpjae_{g}_deg"] for g in GROUPS} | {"frames": r["frames"]}
            print(f"  {n} offset {off:g} deg: all {r['mpjae_all_deg']:.2f} deg ({time.time() - t0:.0f} s)",
                  file=sys.stderr, flush=True)
    base = f"{a.offsets[0]:g}"
    md = ["# BiRAE: MPJAE under per-sensor heading offsets U(-a, a) (noise scenario)", "",
          f"Split {a.split}, {len(recs)} clips; offline, MC-dropout mean. Cells: all-15 MPJAE in degrees "
          f"(change vs a = {base} deg). a = 180 deg = every sensor's heading uniformly random: an upper bound on "
          "what a heading disturbance can cost the model.", "",
          "| model | " + " | ".join(f"a = {o:g} deg" for o in a.offsets) + " |",
          "| --- |" + " --- |" * len(a.offsets)]
    for n in ests:
        b = res[n][base]["all"]
        md.append(f"| {n} | " + " | ".join(
            f"{res[n][f'{o:g}']['all']:.2f} ({(res[n][f'{o:g}']['all'] / b - 1) * 100:+.1f} %)" for o in a.offsets) + " |")
    md += ["", "Per group at the largest offset (distal / tracking / other, degrees, change vs the first offset):", ""]
    last = f"{a.offsets[-1]:g}"
    for n in ests:
        md.append(f"- {n}: " + ", ".join(
            f"{g} {res[n][base][g]:.2f} -> {res[n][last][g]:.2f} ({(res[n][last][g] / res[n][base][g] - 1) * 100:+.1f} %)"
            for g in GROUPS[:3]))
    cmd = "python " + shlex.join([sys.argv[0], *(argv if argv is not None else sys.argv[1:])])
    md += ["", f"Command: `{cmd}`"]
    stem = "birae_heading_sweep" + (f"_{a.out}" if a.out else "")
    (RESULTS / f"{stem}.md").write_text("\n".join(md) + "\n")
    (RESULTS / f"{stem}.json").write_text(json.dumps(
        {"command": cmd, "split": a.split, "clips": len(recs), "offsets_deg": a.offsets, "mc_samples": a.mc,
         "checkpoints": paths,
         "mpjae_deg": res, "wall_seconds": time.time() - t0}, indent=1))
    print("\n".join(md))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
