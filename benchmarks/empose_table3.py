"""EM-POSE Table 3 on our data: the LGD-RNN ablations at one equal training budget.

Rows (``wearpose.estimators.empose.config.TABLE3_ABLATIONS``): "no [R|t]" (identity offsets in
training and in L_r), "no t" (rotation offsets only), "ori only" / "pos only" (one measured
modality as network input and in L_r), "no RNN" (LGD from one learned constant start, frame-wise)
and the full model, each trained from scratch with the ``cpu`` preset for the same number of
epochs (the cosine schedule spans that budget), then evaluated on the same simulated held-out
test recordings (:func:`wearpose.estimators.empose.evaluate.evaluate_models`).

Train one row (one at a time; 1 thread)::

    python benchmarks/empose_table3.py train no_t --epochs 3 --out runs/t3_no_t

(``full`` and ``noRt`` are the same as ``wearpose train empose --config cpu --epochs 3`` with
``--offsets random`` / ``none``; every row is also ``wearpose train empose --ablation <row>``.) Then the table::

    python benchmarks/empose_table3.py table --runs runs/t3 --epochs 3 [--limit N]

reads ``runs/t3_<row>/best.pt`` for every row present and writes
``benchmarks/results/empose_table3.md`` and ``.json``.
"""

from __future__ import annotations

import argparse
import shlex
import sys
import time
from pathlib import Path

import torch


def _command(argv: list[str] | None) -> str:
    return "python " + shlex.join([sys.argv[0], *(argv if argv is not None else sys.argv[1:])])


def cmd_train(a: argparse.Namespace, argv: list[str] | None) -> int:
    from wearpose.estimators.empose import EmposeConfig, EmposeEstimator
    from wearpose.estimators.empose.config import ablation_config
    from wearpose.estimators.empose.train import train_empose

    cfg = ablation_config(EmposeConfig.preset(a.config, a.sensors), a.ablation)
    est = EmposeEstimator(cfg)
    res = train_empose(est, a.out, epochs=a.epochs, resume=a.resume, threads=a.threads, limit_train=a.limit,
                       train_command=_command(argv))
    print(f"done: best val MPJPE {res['best']:.1f} mm; checkpoints in {res['out_dir']}")
    return 0


def cmd_table(a: argparse.Namespace, argv: list[str] | None) -> int:
    from wearpose.estimators.empose.config import TABLE3_ABLATIONS
    from wearpose.estimators.empose.evaluate import PAPER_TABLE3_12, evaluate_models, write_table

    ckpts: dict[str, str] = {}
    for key, (label, _) in TABLE3_ABLATIONS.items():
        path = Path(f"{a.runs}_{key}") / "best.pt"
        if path.is_file():
            ckpts[label] = str(path)
        else:
            print(f"skipping {label}: no checkpoint at {path}", file=sys.stderr)
    if not ckpts:
        raise SystemExit("no Table 3 checkpoint found")
    t0 = time.time()

    def prog(d: int, t: int) -> None:
        if d % 20 == 0 or d == t:
            print(f"  {d}/{t} clips ({time.time() - t0:.0f} s)", file=sys.stderr, flush=True)

    res = evaluate_models(ckpts, a.split, a.limit, seed=a.seed, progress=prog)
    ep = f"{a.epochs} epoch{'s' if a.epochs != 1 else ''}"
    note = (f"Equal budget: every row trained from scratch for {ep} of the `cpu` preset (1143 training clips, "
            f"batch 32, cosine learning rate over the budget, 1 thread), best-validation checkpoint. The shipped "
            f"`empose12_cpu` (Table 2: 15.3 mm) trained 17 epochs, so the 'full' row here is a shorter "
            f"run of the same model; compare rows with each other, not with Table 2.")
    extra = {"command": _command(argv), "wall_seconds": time.time() - t0, "budget_epochs": a.epochs,
             "time_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()), "note": note}
    md, js = write_table(res, a.out, title="EM-POSE Table 3 (ablations) on simulated data (12 sensors)",
                         produced_by=extra["command"], paper=PAPER_TABLE3_12, paper_caption="the paper's Table 3",
                         extra=extra)
    print(md.read_text())
    print(f"wrote {md} and {js}")
    return 0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    tr = sub.add_parser("train", help="train one ablation row")
    tr.add_argument("ablation", help="full, noRt, no_t, ori_only, pos_only or no_rnn")
    tr.add_argument("--epochs", type=int, required=True)
    tr.add_argument("--out", type=Path, required=True)
    tr.add_argument("--config", default="cpu")
    tr.add_argument("--sensors", type=int, default=12)
    tr.add_argument("--threads", type=int, default=1)
    tr.add_argument("--limit", type=int, default=None, help="first N training clips")
    tr.add_argument("--resume", action="store_true")
    tb = sub.add_parser("table", help="evaluate the trained rows and write the table")
    tb.add_argument("--runs", default="runs/t3", help="run directory prefix: <prefix>_<row>/best.pt")
    tb.add_argument("--epochs", type=int, required=True, help="the budget the rows were trained with (for the note)")
    tb.add_argument("--split", default="test")
    tb.add_argument("--limit", type=int, default=None)
    tb.add_argument("--seed", type=int, default=0)
    tb.add_argument("--threads", type=int, default=1)
    tb.add_argument("--out", default=str(Path(__file__).parent / "results" / "empose_table3"))
    a = ap.parse_args(argv)
    torch.set_num_threads(a.threads)
    return cmd_train(a, argv) if a.cmd == "train" else cmd_table(a, argv)


if __name__ == "__main__":
    raise SystemExit(main())
