"""``wearpose train <method>``: train an estimator on simulated sensors from the prepared corpus.

``train`` is a command group: each method adds its own command to :data:`train_app` from its
own module (``cli/cmd_train_<method>.py``: ``@train_app.command("pip")``), so methods never
edit each other's options. Every ``wearpose train`` command runs unchanged under ``torchrun``
(DistributedDataParallel, see :mod:`wearpose.estimators.train`).
"""

from __future__ import annotations

import shlex
import sys
from pathlib import Path
from typing import Any, Optional

import typer

from wearpose.cli.app import _emit, app, console

train_app = typer.Typer(help="Train an estimator on simulated sensors from the prepared corpus "
                             "(one command per method; each runs unchanged under torchrun).\n\n"
                             "Example: wearpose train empose --config tiny --threads 1 --out runs/empose_tiny",
                        no_args_is_help=True)
app.add_typer(train_app, name="train")

#: ``--config tiny`` is a smoke test: it trains on this many clips unless ``--limit`` says otherwise
#: (on the whole train split its 2 epochs took over 500 s).
TINY_TRAIN_CLIPS = 8


def clip_limit(config: str, limit: int | None) -> int | None:
    """The training-clip limit of a run: ``--limit``, else :data:`TINY_TRAIN_CLIPS` for ``tiny``."""
    return limit if limit is not None or config != "tiny" else TINY_TRAIN_CLIPS


@train_app.command("empose")
def train_empose_cmd(
    sensors: int = typer.Option(12, help="Number of sensors: 12 (kit em12) or 6 (kit em6)."),
    config: str = typer.Option("cpu", help="Preset: tiny (smoke test: 8 training clips unless --limit, under a minute), cpu (CPU-sized), paper (supp. Table 5)."),
    model: str = typer.Option("lgd", help="empose network: lgd (LGD-RNN), a Table 2 baseline: resnet, birnn, or "
                                          "twostage (joint mapper + LGD IK for dropped sensors, supp. Sec. 9)."),
    epochs: Optional[int] = typer.Option(None, help="Override the preset's number of epochs."),
    out: Optional[Path] = typer.Option(None, help="Run directory (default runs/<method><sensors>_<config>)."),
    resume: bool = typer.Option(False, "--resume", help="Continue from <out>/last.pt."),
    threads: Optional[int] = typer.Option(None, min=1, help="torch CPU threads (default: torch's choice)."),
    device: str = typer.Option("auto", help="auto (CUDA when available), cpu or cuda[:i]."),
    hidden: Optional[int] = typer.Option(None, min=1, help="Override LSTM width."),
    width: Optional[int] = typer.Option(None, help="Override the update-MLP width."),
    iterations: Optional[int] = typer.Option(None, help="Override N, the LGD iterations."),
    batch_size: Optional[int] = typer.Option(None, min=1, help="Override the batch size."),
    offsets: Optional[str] = typer.Option(None, help="Subject offsets in training data: random (default) or none "
                                                     "(EM-POSE's 'no [R|t]' ablation)."),
    ablation: Optional[str] = typer.Option(None, help="An EM-POSE Table 3 ablation of the LGD-RNN: noRt, no_t, "
                                                       "ori_only, pos_only, no_rnn (or full)."),
    limit: Optional[int] = typer.Option(None, min=1, help="Use only the first N training clips (quick runs)."),
    checkpoint_every: int = typer.Option(100, min=1, help="Save last.pt every N optimiser steps (and every epoch)."),
    as_json: bool = typer.Option(False, "--json", help="Print the result as JSON."),
) -> None:
    """Train EM-POSE (LGD-RNN or a Table 2 baseline) on virtual EM sensors.

    Example: wearpose train empose --sensors 12 --config cpu --threads 1 --out runs/empose12_cpu
    Table 3 row: wearpose train empose --ablation no_t --epochs 3 --threads 1 --out runs/t3_no_t
    """
    method = "empose"
    from wearpose.estimators.empose.baselines import baseline_config, estimator_class
    from wearpose.estimators.empose.train import train_empose

    if model not in ("lgd", "resnet", "birnn", "twostage"):
        raise typer.BadParameter(f"unknown model {model!r}; expected lgd, resnet, birnn or twostage", param_hint="--model")
    if offsets not in (None, "random", "none"):
        raise typer.BadParameter(f"expected random or none, got {offsets!r}", param_hint="--offsets")
    cfg = baseline_config(config, sensors, model).override(hidden=hidden, width=width, iterations=iterations,
                                                        batch_size=batch_size, offsets=offsets)
    if ablation is not None:
        from wearpose.errors import ConfigError
        from wearpose.estimators.empose.config import ablation_config

        if model != "lgd":
            raise typer.BadParameter(f"ablations are of the LGD-RNN; got --model {model}", param_hint="--ablation")
        try:
            cfg = ablation_config(cfg, ablation)
        except ConfigError as exc:  # names the unknown row and the known ones
            raise typer.BadParameter(str(exc), param_hint="--ablation") from None
    out = out or Path("runs") / f"{method if model == 'lgd' else model}{sensors}_{config}"
    est = estimator_class(model)(cfg)
    command = "wearpose " + " ".join(shlex.quote(a) for a in sys.argv[1:])
    res = train_empose(est, out, epochs=epochs, resume=resume, threads=threads, device=device,
                       limit_train=clip_limit(config, limit),
                       checkpoint_every=checkpoint_every, train_command=command, quiet=as_json, console=None if as_json else console)
    res = {"method": method, "model": model, "sensors": sensors, "config": cfg.to_dict(), **res}

    def render(r: dict[str, Any]) -> None:
        console.print(f"done: best val MPJPE {r['best']:.1f} mm; checkpoints in {r['out_dir']}")

    _emit(res, as_json, render)
