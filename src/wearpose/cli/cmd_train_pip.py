"""``wearpose train pip``: train PIP's kinematics module on simulated IMUs from the corpus."""

from __future__ import annotations

import shlex
import sys
from pathlib import Path
from typing import Any, Optional

import typer

from wearpose.cli.app import _emit, console
from wearpose.cli.cmd_train import clip_limit, train_app


@train_app.command("pip")
def train_pip_cmd(
    config: str = typer.Option("cpu", help="Preset: tiny (smoke test: 8 training clips unless --limit, under a minute), cpu (CPU-sized), paper (PIP appendix)."),
    epochs: Optional[int] = typer.Option(None, help="Override the preset's number of epochs."),
    out: Optional[Path] = typer.Option(None, help="Run directory (default runs/pip_<config>[_noinit])."),
    resume: bool = typer.Option(False, "--resume", help="Continue from <out>/last.pt."),
    threads: Optional[int] = typer.Option(None, min=1, help="torch CPU threads (default: torch's choice)."),
    device: str = typer.Option("auto", help="auto (CUDA when available), cpu or cuda[:i]."),
    hidden: Optional[int] = typer.Option(None, min=1, help="Override LSTM width."),
    batch_size: Optional[int] = typer.Option(None, min=1, help="Override the batch size."),
    learned_init: bool = typer.Option(True, "--learned-init/--no-learned-init",
                                      help="Learned RNN initialisation I_PL / I_VA (off: Table 2 ablation)."),
    limit: Optional[int] = typer.Option(None, min=1, help="Use only N training clips spread over the split (quick runs)."),
    sitting_clips: Optional[int] = typer.Option(None, help="Add N synthetic sitting clips to train (N/10 to val)."),
    balanced_sitting: bool = typer.Option(False, "--balanced-sitting",
                                          help="Synthetic sitting clips stand as long as they sit (3-20 s holds)."),
    sitting_transitions: Optional[str] = typer.Option(None, help="How the synthetic sitting clips sit down / stand up: "
                                                                 "slerp (no lean) or lean (trunk lean, knees forward)."),
    sitting_hanging_arms: Optional[float] = typer.Option(None, min=0.0, max=1.0,
                                                         help="Fraction of the synthetic sitting clips whose arms "
                                                              "hang nearly straight."),
    mirror: bool = typer.Option(False, "--mirror", help="Add the left/right mirror image of every training clip."),
    speed_copies: int = typer.Option(0, min=0, help="Add N copies of every training clip played 0.8-1.25x as fast "
                                                     "(PipConfig.aug_speed_range)."),
    seq_len: Optional[int] = typer.Option(None, min=2, help="Override the training window length, frames."),
    window_stride: Optional[int] = typer.Option(None, min=1, help="Override the stride between windows, frames."),
    min_window: Optional[int] = typer.Option(None, min=0, help="Clips of at least N frames but shorter than the window "
                                                                "train as one padded window (0: left out)."),
    sitting_window: Optional[int] = typer.Option(None, min=0, help="Windows of N frames (every N/2) for the synthetic "
                                                                    "sitting clips (0: as the corpus clips)."),
    lr: Optional[float] = typer.Option(None, help="Override the learning rate."),
    init_from: Optional[Path] = typer.Option(None, help="Start from this checkpoint's weights (fine-tuning; fresh optimiser)."),
    checkpoint_every: int = typer.Option(100, min=1, help="Save last.pt every N optimiser steps (and every epoch)."),
    as_json: bool = typer.Option(False, "--json", help="Print the result as JSON."),
) -> None:
    """Train PIP's kinematics RNNs (P_L, P_A, R_A, V_A, C_F, I_PL, I_VA) on virtual IMUs (kit imu6).

    Example: wearpose train pip --config cpu --threads 1 --out runs/pip_cpu

    Fine-tune with synthetic sitting: wearpose train pip --config cpu --threads 1 --init-from
    runs/pip_cpu/best.pt --sitting-clips 150 --epochs 2 --lr 3e-4 --out runs/pip_cpu_sit

    Augmented data (3x the corpus: mirrored copies and one speed-changed copy of every clip):
    wearpose train pip --config cpu --threads 1 --mirror --speed-copies 1 --out runs/pip_aug

    Long windows (20 s, short clips padded; 200 frames for the sitting clips) and sit-downs with
    trunk lean, as the shipped pip_cpu: wearpose train pip --config cpu --threads 1 --mirror
    --speed-copies 1 --sitting-clips 150 --balanced-sitting --sitting-transitions lean --seq-len 1200
    --window-stride 600 --min-window 60 --sitting-window 200 --out runs/pip_lean
    """
    from wearpose.estimators.pip import PipConfig, PipEstimator, train_pip
    from wearpose.estimators.pip.sitting import SIT_HOLD_S

    cfg = PipConfig.preset(config).override(hidden=hidden, batch_size=batch_size, learned_init=learned_init,
                                            sitting_clips=sitting_clips, lr=lr, aug_mirror=mirror or None,
                                            aug_speed_copies=speed_copies or None,
                                            sitting_stand_s=SIT_HOLD_S if balanced_sitting else None,
                                            seq_len=seq_len, window_stride=window_stride, min_window=min_window,
                                            sitting_window=sitting_window, sitting_transitions=sitting_transitions,
                                            sitting_hanging_arms=sitting_hanging_arms)
    if hidden is not None:
        cfg = cfg.override(init_widths=(hidden, 2 * hidden))
    out = out or Path("runs") / f"pip_{config}{'' if learned_init else '_noinit'}"
    est = PipEstimator(cfg, physics=False)
    if init_from is not None and not resume:
        from wearpose.estimators.checkpoint import load_checkpoint

        ck = load_checkpoint(init_from)
        ck.check(method="pip", path=init_from)
        est.model.load_state_dict(ck.weights)  # same architecture required (strict)
        est.meta["init_from"] = str(init_from)
    command = "wearpose " + " ".join(shlex.quote(a) for a in sys.argv[1:])
    res = train_pip(est, out, epochs=epochs, resume=resume, threads=threads, device=device,
                    limit_train=clip_limit(config, limit),
                    checkpoint_every=checkpoint_every, train_command=command, quiet=as_json,
                    console=None if as_json else console)
    res = {"method": "pip", "config": cfg.to_dict(), **res}

    def render(r: dict[str, Any]) -> None:
        console.print(f"done: best val joint error {r['best']:.1f} mm; checkpoints in {r['out_dir']}")

    _emit(res, as_json, render)
