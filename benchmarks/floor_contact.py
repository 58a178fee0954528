"""Where each model's estimate stands: its lowest point against the truth's, per floor rule.

Run: ``python benchmarks/floor_contact.py MODEL [NAME=MODEL ...] [--split test] [--every 1]
[--out benchmarks/results/floor_contact_<split>]``. Writes ``<out>.md`` and ``<out>.json``.

Per model (shipped weights, an archived version or a checkpoint file), the clips of the split
(every ``--every``-th, sorted), through :func:`wearpose.evaluate.floor.floor_placement`: each clip
simulated without noise after a marked 1 s T-pose, estimated and placed as ``wearpose
estimate`` does, then per frame after the T-pose ``e`` = the estimate's lowest point minus the
truth's. Rows: the floor rules (the shipped one: contact frames at
``wearpose.estimators.run.CONTACT_SPEED_M_S``; "every frame": the median over all frames, the
rule before); figures in cm and % of frames.
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
import time
from pathlib import Path

import torch

from wearpose.estimators.run import CONTACT_SPEED_M_S, open_model
from wearpose.evaluate.floor import FLOOR_LIMIT_M, TRUTH_OFF_FLOOR_M, floor_placement, rule_name
from wearpose.motion import CorpusStore

ROOT = Path(__file__).resolve().parents[1]


def table(results: dict[str, dict]) -> list[str]:
    lim = f"{FLOOR_LIMIT_M * 100:g} cm"
    lines = [f"| model | floor rule | median abs(e) [cm] | standing, in the floor > {lim} [% of frames] | standing, "
             f"over it > {lim} [%] | under the floor > {lim} [%] | worst standing e [cm] | lowest point [cm] | "
             f"clips with a standing frame off | clips under the floor |",
             "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    for name, r in results.items():
        n = len(r["clip_ids"]) - len(r["excluded"])
        for rule, f in r["rules"].items():
            shipped = " (shipped)" if rule == rule_name(CONTACT_SPEED_M_S) else ""
            lines.append(f"| {name} | {rule}{shipped} | {f['median_abs_cm']:.2f} | {f['standing_sink_pct']:.2f} | "
                         f"{f['standing_float_pct']:.2f} | {f['under_floor_pct']:.2f} | "
                         f"{f['worst_standing_sink_cm']:.1f} .. {f['worst_standing_float_cm']:.1f} | {f['lowest_cm']:.1f} | "
                         f"{f['clips_standing_off']} of {n} | {f['clips_under']} of {n} |")
    return lines


def plot(models: list[str], clip: str, out: Path) -> int:
    """One clip's lowest point per frame: the truth on its floor and each model under the rule
    before (every frame) and the shipped one (contact frames), the 5 cm band shaded."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from wearpose.body import BodyModel
    from wearpose.evaluate.floor import clip_floor

    store, body = CorpusStore(), BodyModel()
    m = store.load(clip)
    fig, axes = plt.subplots(len(models), 1, figsize=(8, 2.6 * len(models)), sharex=True, squeeze=False)
    for ax, spec in zip(axes[:, 0], models):
        name, _, model = spec.rpartition("=")
        source = open_model(model)
        res = clip_floor(source, m, body, rules=(None, CONTACT_SPEED_M_S))
        before, shipped = res["rules"]["every frame"], res["rules"][rule_name(CONTACT_SPEED_M_S)]
        t = torch.arange(len(shipped.e)) / (source.fps or m.fps)  # clip_floor scores at the model's rate
        truth = (shipped.height - shipped.e) * 100
        ax.axhspan(-FLOOR_LIMIT_M * 100, 0, color="0.9")
        ax.axhline(0, color="k", lw=0.8)
        ax.plot(t, truth, color="k", lw=1.2, label="truth")
        ax.plot(t, before.height * 100, color="tab:red", lw=1, label="estimate, floor = median of every frame (before)")
        ax.plot(t, shipped.height * 100, color="tab:blue", lw=1, label="estimate, floor = median of contact frames")
        ax.set_ylabel("lowest point [cm]")
        ax.set_title(f"{name or model}: {clip}", fontsize=9)
    axes[0, 0].legend(fontsize=7, loc="upper right")
    axes[-1, 0].set_xlabel("time [s]")
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    print(f"wrote {out}", file=sys.stderr)
    return 0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("models", nargs="+", help="MODEL or NAME=MODEL (shipped name, archive:NAME, or a .pt file)")
    ap.add_argument("--split", default="test")
    ap.add_argument("--every", type=int, default=1, help="every n-th clip of the sorted split")
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--out", default=None)
    ap.add_argument("--plot", metavar="CLIP", default=None,
                    help="instead: draw CLIP's lowest point over time, truth and each model under each rule, to --out (.png)")
    args = ap.parse_args(argv)
    if args.plot:
        return plot(args.models, args.plot, Path(args.out or ROOT / "docs" / "img" / "floor_contact.png"))
    torch.set_num_threads(args.threads)
    store = CorpusStore()
    clips = sorted(store.clips(split=args.split))[::args.every]
    results, t0 = {}, time.perf_counter()
    for spec in args.models:
        name, _, model = spec.rpartition("=")
        name = name or model
        source = open_model(model)
        results[name] = floor_placement(source, store, args.split, clips,
                                        progress=lambda i, n: print(f"\r{name}: {i}/{n} clips", end="", file=sys.stderr))
        print(file=sys.stderr)
    out = Path(args.out or ROOT / "benchmarks" / "results" / f"floor_contact_{args.split}")
    out.parent.mkdir(parents=True, exist_ok=True)
    cmd = "python benchmarks/floor_contact.py " + " ".join(argv if argv is not None else sys.argv[1:])
    first = next(iter(results.values()))
    md = ["# Where the estimate stands: lowest point against the truth's, per floor rule", "",
          f"Produced by `{cmd}` (`wearpose.evaluate.floor.floor_placement`), {time.strftime('%Y-%m-%d')}, "
          f"{time.perf_counter() - t0:.0f} s.", "",
          f"{args.split} split, every {args.every}. clip: {len(clips)} clips, {first['frames']} frames after the T-pose "
          f"per model; sensors simulated without noise after a marked 1 s T-pose, estimated and placed as "
          f"`wearpose estimate` does. e = the estimate's lowest point minus the truth's (on its own floor), per "
          f"frame; standing frames: the truth's lowest point within 3 cm of its floor; under the floor: the "
          f"estimate's lowest point below -{FLOOR_LIMIT_M * 100:g} cm (`wearpose.evaluate.floor`).", "",
          *table(results), "",
          f"Left out (the truth's own floor, the median lowest point of its contact frames, is more than "
          f"{TRUTH_OFF_FLOOR_M * 100:g} cm off y = 0: uneven terrain, a source under its floor; placing on a flat "
          f"floor cannot be right there): " + (", ".join(f"`{c}`" for c in first["excluded"]) or "none") + ".", "",
          "Clips: " + ", ".join(f"`{c}`" for c in clips)]
    out.with_suffix(".md").write_text("\n".join(md) + "\n", encoding="utf-8")
    blob = {"command": cmd, "models": results, "contact_speed_m_s": CONTACT_SPEED_M_S,
            "machine": {"python": platform.python_version(), "torch": torch.__version__}}
    out.with_suffix(".json").write_text(json.dumps(blob, indent=1) + "\n", encoding="utf-8")
    print("\n".join(table(results)))
    print(f"wrote {out.with_suffix('.md')}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
