"""``wearpose train miposer``: train MI-Poser's IK network (or the IMU-only baseline) on simulated
headset + wrist sensors from the corpus."""

from __future__ import annotations

import shlex
import sys
from pathlib import Path
from typing import Any, Optional

import typer

from wearpose.cli.app import _emit, console
from wearpose.cli.cmd_train import clip_limit, train_app


@train_app.command("miposer")
def train_miposer_cmd(
    config: str = typer.Option("cpu", help="Preset: tiny (smoke test: 8 training clips unless --limit, under a minute), cpu (CPU-sized), paper (AvatarPoser / MI-Poser Sec. 4.2)."),
    model: str = typer.Option("avatarposer", help="avatarposer (MI-Poser IK network) or imuposer (IMU-only BiLSTM baseline)."),
    wrists: int = typer.Option(2, help="Wrist sensors: 2 (kit miposer) or 1 (left wrist, smartwatch variant, kit miposer1)."),
    epochs: Optional[int] = typer.Option(None, help="Override the preset's number of epochs."),
    out: Optional[Path] = typer.Option(None, help="Run directory (default runs/miposer<wrists>_<config> or runs/imuposer_<config>)."),
    resume: bool = typer.Option(False, "--resume", help="Continue from <out>/last.pt."),
    threads: Optional[int] = typer.Option(None, min=1, help="torch CPU threads (default: torch's choice)."),
    device: str = typer.Option("auto", help="auto (CUDA when available), cpu or cuda[:i]."),
    batch_size: Optional[int] = typer.Option(None, min=1, help="Override the batch size."),
    limit: Optional[int] = typer.Option(None, min=1, help="Use only the first N training clips (quick runs)."),
    checkpoint_every: int = typer.Option(100, min=1, help="Save last.pt every N optimiser steps (and every epoch)."),
    as_json: bool = typer.Option(False, "--json", help="Print the result as JSON."),
) -> None:
    """Train MI-Poser (AvatarPoser-style IK from head + wrist 6-DoF) or the IMUPoser baseline.

    Example: wearpose train miposer --config cpu --threads 1 --out runs/miposer2_cpu
    """
    from wearpose.estimators.miposer.config import MiposerConfig
    from wearpose.estimators.miposer.train import train_miposer

    if model not in ("avatarposer", "imuposer"):
        raise typer.BadParameter(f"unknown model {model!r}; expected avatarposer or imuposer", param_hint="--model")
    if wrists not in (1, 2):
        raise typer.BadParameter(f"expected 1 or 2, got {wrists}", param_hint="--wrists")
    cfg = MiposerConfig.preset(config, wrists=wrists, model=model).override(batch_size=batch_size)
    if model == "imuposer":
        from wearpose.estimators.miposer.baselines import ImuPoserEstimator

        est: Any = ImuPoserEstimator(cfg)
        out = out or Path("runs") / f"imuposer_{config}"
    else:
        from wearpose.estimators.miposer.estimator import MiposerEstimator

        est = MiposerEstimator(cfg)
        out = out or Path("runs") / f"miposer{wrists}_{config}"
    command = "wearpose " + " ".join(shlex.quote(a) for a in sys.argv[1:])
    res = train_miposer(est, out, epochs=epochs, resume=resume, threads=threads, device=device,
                        limit_train=clip_limit(config, limit),
                        checkpoint_every=checkpoint_every, train_command=command, quiet=as_json,
                        console=None if as_json else console)
    res = {"method": est.name, "model": model, "wrists": wrists, "config": cfg.to_dict(), **res}

    def render(r: dict[str, Any]) -> None:
        console.print(f"done: best val upper-body MPJPE {r['best']:.1f} mm; checkpoints in {r['out_dir']}")

    _emit(res, as_json, render)
