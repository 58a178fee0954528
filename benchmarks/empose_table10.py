"""EM-POSE Table 10 on our held-out test split: the two-stage model against the LGD-RNN on frames
with dropped sensors.

Run::

    python benchmarks/empose_table10.py --ckpt "LGD-RNN=src/wearpose/weights/empose12_cpu.pt" \\
        --ckpt "2-stage=runs/twostage12_cpu/best.pt" [--limit N]

Simulates every clip of the split as Table 2 does (default EM noise, held-out random subject
offsets), removes 1-2 sensors over random 0.5-1.5 s spans
(:func:`wearpose.estimators.empose.evaluate.drop_sensors`), runs every model on the whole
recording and scores every frame, split into all / avail. / miss. (and exactly 1 / 2 missing).
``--zeros NAME`` gives the model ``NAME`` every missing sample as a valid all-zero measurement
instead (what some EM SDKs deliver; list the same checkpoint twice under two names to have both
rows); such rows are a secondary scenario, in italics, never bold. Writes ``benchmarks/results/empose_table10.md`` and ``.json``. One torch thread by default.
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


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--ckpt", action="append", required=True, metavar="NAME=PATH")
    ap.add_argument("--zeros", action="append", default=[], metavar="NAME",
                    help="model NAME (of --ckpt) gets missing samples as valid zeros")
    ap.add_argument("--split", default="test")
    ap.add_argument("--limit", type=int, default=None)
    ap.add_argument("--noise", default="default", choices=("default", "none"))
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--out", default=str(Path(__file__).parent / "results" / "empose_table10"))
    ap.add_argument("--note", default=None, help="a paragraph appended to the markdown (NOTE in the printed command)")
    ap.add_argument("--span", type=int, nargs=2, default=None, metavar=("MIN", "MAX"),
                    help="frames per removal span (default 15 45, i.e. 0.5-1.5 s at 30 Hz)")
    a = ap.parse_args(argv)
    torch.set_num_threads(a.threads)
    from wearpose.estimators.empose.evaluate import PAPER_TABLE10_12, evaluate_dropped, table10_markdown

    ckpts = {}
    for spec in a.ckpt:
        name, sep, path = spec.partition("=")
        if not sep or not Path(path).is_file():
            ap.error(f"--ckpt {spec!r}: expected NAME=PATH of an existing checkpoint")
        ckpts[name] = path
    t0 = time.time()

    def prog(d: int, t: int) -> None:
        if d % 20 == 0 or d == t:
            print(f"  {d}/{t} clips ({time.time() - t0:.0f} s)", file=sys.stderr, flush=True)

    for z in a.zeros:
        if z not in ckpts:
            ap.error(f"--zeros {z!r}: not a --ckpt name ({', '.join(ckpts)})")
    kw = {"span": tuple(a.span)} if a.span else {}
    kw["zeros"] = tuple(a.zeros)
    res = evaluate_dropped(ckpts, a.split, a.limit, noise=a.noise, seed=a.seed, progress=prog, **kw)
    args = list(argv if argv is not None else sys.argv[1:])
    # The note is printed under the table; the command shows a placeholder instead of repeating it.
    shown = [("NOTE" if i and args[i - 1] == "--note" else x) for i, x in enumerate(args)]
    res["command"] = "python " + shlex.join([sys.argv[0], *shown])
    if a.note:
        res["note"] = a.note
    res["wall_seconds"] = time.time() - t0
    res["time_utc"] = time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())
    res["paper_table10_12"] = PAPER_TABLE10_12
    res["machine"] = {"python": platform.python_version(), "torch": torch.__version__, "threads": torch.get_num_threads()}
    tab = table10_markdown(res)
    c = res["frame_counts"]
    md = ["# EM-POSE Table 10 on simulated data (12 sensors, dropped sensors)", "",
          f"Produced by `{res['command']}` (`wearpose.estimators.empose.evaluate.evaluate_dropped`).", "", tab, "",
          f"Split `{res['split']}` ({res['clips']} clips, {c['all']} frames: {c['avail']} with every sensor, "
          f"{c['miss']} with at least one missing), kit `{res['kit']}` at {res['rate_hz']:g} Hz, EM noise `{res['noise']}`, "
          f"{res['subjects']}; sensors removed over random spans of {res['drops']['span_frames'][0]}-"
          f"{res['drops']['span_frames'][1]} frames, 1 or 2 sensors per span, gaps of {res['drops']['gap_frames'][0]}-"
          f"{res['drops']['gap_frames'][1]} frames; every frame scored (the LGD-RNN holds a dropped sensor at its last "
          "value); 15 major joints; mean ± std over frames."
          + (f" Rows in italics ({', '.join(a.zeros)}): a secondary scenario, not the basis of any claim: the model "
             "gets each missing sample as a valid all-zero measurement (what some EM SDKs deliver; cf. the paper's "
             "Fig. 12) instead of a marked gap." if a.zeros else ""), "", "## Models", "",
          "| Model | method | checkpoint | epoch | val MPJPE [mm] | parameters | estimate time [s] |",
          "| --- | --- | --- | --- | --- | --- | --- |"]
    for n, m in res["models"].items():
        v = m.get("val_mpjpe_mm")
        md.append(f"| {n} | {m['method']} | `{m['checkpoint']}` | {m.get('epoch')} | {'' if v is None else f'{v:.2f}'} | "
                  f"{m['parameters']} | {m['seconds']:.1f} |")
    md += ["", "Training commands:", ""] + [f"- {n}: `{m.get('train_command') or '?'}`" for n, m in res["models"].items()]
    md += ["", "For context, the paper's Table 10 (12 sensors, real data, GPU-trained; not comparable number for number):",
           "", "| Frames | Model | MPJPE [mm] | PA-MPJPE [mm] | MPJAE [°] |", "| --- | --- | --- | --- | --- |"]
    for s, rows in PAPER_TABLE10_12.items():
        for n, vals in rows.items():
            md.append(f"| {s} | {n} 12 | " + " | ".join(f"{m} ± {sd}" for m, sd in vals) + " |")
    if a.note:
        md += ["", a.note]
    out = Path(a.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.with_suffix(".md").write_text("\n".join(md) + "\n", encoding="utf-8")
    out.with_suffix(".json").write_text(json.dumps(res, indent=2, default=str) + "\n", encoding="utf-8")
    print(tab)
    print(f"\nwrote {out.with_suffix('.md')} and {out.with_suffix('.json')}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
