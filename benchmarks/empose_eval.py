"""EM-POSE Table 2 on our held-out test split: LGD-RNN against the ResNet and BiRNN baselines.

Run::

    python benchmarks/empose_eval.py --ckpt ResNet=runs/resnet12_cpu/best.pt \\
        --ckpt BiRNN=runs/birnn12_cpu/best.pt --ckpt "LGD-RNN=runs/empose12_cpu/best.pt" [--limit N]

Evaluates every checkpoint on the same simulated recordings of the corpus split (default
``test``; default EM noise; held-out random subject offsets; fixed seed; see
:mod:`wearpose.estimators.empose.evaluate`), prints the table and writes
``benchmarks/results/empose_table2.md`` and ``.json`` (``--out`` to change the stem). One torch
thread by default (``--threads``).
"""

from __future__ import annotations

import argparse
import shlex
import sys
import time
from pathlib import Path

import torch


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--ckpt", action="append", required=True, metavar="NAME=PATH",
                    help="a model row: display name and checkpoint path (repeat; rows in this order)")
    ap.add_argument("--split", default="test")
    ap.add_argument("--limit", type=int, default=None, help="first N clips of the split")
    ap.add_argument("--noise", default="default", choices=("default", "none"))
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--out", default=str(Path(__file__).parent / "results" / "empose_table2"),
                    help="output stem (.md and .json are written)")
    ap.add_argument("--note", default=None, help="a sentence appended to the markdown")
    a = ap.parse_args(argv)
    torch.set_num_threads(a.threads)
    from wearpose.estimators.empose.evaluate import evaluate_models, table2_markdown, write_table2

    ckpts: dict[str, str] = {}
    for spec in a.ckpt:
        name, sep, path = spec.partition("=")
        if not sep or not name or not path:
            ap.error(f"--ckpt {spec!r}: expected NAME=PATH")
        if not Path(path).is_file():
            print(f"skipping {name}: no checkpoint at {path}", file=sys.stderr)
            continue
        ckpts[name] = path
    if not ckpts:
        ap.error("no existing checkpoint given")
    t0 = time.time()

    def prog(d: int, t: int) -> None:
        if d % 20 == 0 or d == t:
            print(f"  {d}/{t} clips ({time.time() - t0:.0f} s)", file=sys.stderr, flush=True)

    res = evaluate_models(ckpts, a.split, a.limit, noise=a.noise, seed=a.seed, progress=prog)
    extra = {"command": "python " + shlex.join([sys.argv[0], *(argv if argv is not None else sys.argv[1:])]),
             "wall_seconds": time.time() - t0, "time_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}
    if a.note:
        extra["note"] = a.note
    md, js = write_table2(res, a.out, extra)
    print(table2_markdown(res))
    print(f"\nwrote {md} and {js}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
