"""``wearpose train birae``: train BiRAE on synthetic MIMU orientations from the corpus."""

from __future__ import annotations

import shlex
import sys
from pathlib import Path
from typing import Any, Optional

import typer

from wearpose.cli.app import _emit, console
from wearpose.cli.cmd_train import train_app


@train_app.command("birae")
def train_birae_cmd(
    rep: str = typer.Option("6param", help="Input representation: 6param, 3param, 3param_rate, zhou6d."),
    config: str = typer.Option("cpu", help="Preset: tiny (smoke test), cpu (CPU-sized), paper (Sec. IV-A/E)."),
    epochs_clean: Optional[int] = typer.Option(None, help="Override the clean-phase epochs."),
    epochs_aug: Optional[int] = typer.Option(None, help="Override the augmented-phase epochs."),
    out: Optional[Path] = typer.Option(None, help="Run directory (default runs/birae_<rep>_<config>)."),
    resume: bool = typer.Option(False, "--resume", help="Continue each phase from its last.pt."),
    threads: Optional[int] = typer.Option(None, min=1, help="torch CPU threads (default: torch's choice)."),
    device: str = typer.Option("cpu", help="cpu, cuda[:i] or auto."),
    hidden: Optional[int] = typer.Option(None, min=1, help="Override the Bi-LSTM width."),
    width: Optional[int] = typer.Option(None, help="Override the input FC width."),
    batch_size: Optional[int] = typer.Option(None, min=1, help="Override the batch size."),
    train_clips: Optional[int] = typer.Option(None, min=1, help="Use only the first N training clips (quick runs)."),
    checkpoint_every: int = typer.Option(50, min=1, help="Save last.pt every N optimiser steps (and every epoch)."),
    init_from: Optional[Path] = typer.Option(None, help="Start from this BiRAE checkpoint's weights (same --rep); "
                                                          "with --epochs-clean 0 it continues in the augmented phase."),
    lr: Optional[float] = typer.Option(None, help="Override the initial learning rate."),
    as_json: bool = typer.Option(False, "--json", help="Print the result as JSON."),
) -> None:
    """Train BiRAE: clean synthetic orientations first, then noise/impulse/yaw-drift augmented.

    Example: wearpose train birae --rep 3param --config cpu --threads 1 --out runs/birae3_cpu
    """
    from wearpose.estimators.birae import REPS, BiraeConfig, BiraeEstimator
    from wearpose.estimators.birae.train import train_birae

    if rep not in REPS:
        raise typer.BadParameter(f"unknown representation {rep!r}; expected one of {', '.join(REPS)}", param_hint="--rep")
    cfg = BiraeConfig.preset(config, rep).override(hidden=hidden, width=width, batch_size=batch_size,
                                                   train_clips=train_clips, lr=lr)
    out = out or Path("runs") / f"birae_{rep}_{config}"
    est = BiraeEstimator(cfg)
    command = "wearpose " + " ".join(shlex.quote(a) for a in sys.argv[1:])
    res = train_birae(est, out, resume=resume, threads=threads, device=device, epochs_clean=epochs_clean,
                      epochs_aug=epochs_aug, checkpoint_every=checkpoint_every, train_command=command, init_from=init_from,
                      quiet=as_json, console=None if as_json else console)
    res = {"method": "birae", "rep": rep, "config": cfg.to_dict(), **res}

    def render(r: dict[str, Any]) -> None:
        console.print(f"done: best val MPJAE {r['best']:.2f} deg; checkpoint {r['best_checkpoint']}")

    _emit(res, as_json, render)
