"""Generic training loop shared by the estimators.

:func:`train` runs a :class:`TrainTask` with Adam, a per-step learning-rate schedule (constant
or cosine), global gradient-norm clipping, validation after every epoch, ``best.pt`` (lowest
validation metric) and ``last.pt`` (every ``checkpoint_every`` steps and every epoch, with the
optimiser state) checkpoints, resume from ``last.pt`` (mid-epoch: the batch order of an epoch
is a function of the seed and the epoch, so the batches already done are skipped), a
JSON-lines log (``log.jsonl``) and rich progress. It runs unchanged on CUDA when available.
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Iterable, Protocol

import torch
from torch import nn

from wearpose.estimators.checkpoint import load_checkpoint


class TrainTask(Protocol):
    """What :func:`train` needs from a method."""

    model: nn.Module
    val_metric: str  #: key of :meth:`validate`'s result to minimise

    def num_batches(self) -> int: ...

    def batches(self, epoch: int, skip: int) -> Iterable[Any]: ...

    def loss(self, batch: Any, device: torch.device) -> tuple[torch.Tensor, dict[str, float]]: ...

    def validate(self, device: torch.device) -> dict[str, float]: ...

    def save(self, path: Path, meta: dict[str, Any], train_state: dict[str, Any] | None) -> None: ...


@dataclass
class TrainSettings:
    """Loop settings. ``threads``: torch CPU threads (None = torch default); ``device``:
    ``"auto"`` (CUDA if available) or a device string; ``max_steps``: stop after this many
    optimiser steps in total (tests); ``log_every``: steps between log lines."""

    out_dir: Path
    epochs: int
    lr: float
    lr_schedule: str = "constant"
    lr_min_factor: float = 0.1
    grad_clip: float = 1.0
    resume: bool = False
    threads: int | None = None
    device: str = "auto"
    checkpoint_every: int = 100
    log_every: int = 20
    max_steps: int | None = None
    quiet: bool = False


def resolve_device(device: str) -> torch.device:
    if device == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    return torch.device(device)


def _lr_at(s: TrainSettings, step: int, total: int) -> float:
    if s.lr_schedule == "cosine" and total > 0:
        f = min(1.0, step / total)
        return s.lr * (s.lr_min_factor + (1 - s.lr_min_factor) * 0.5 * (1 + math.cos(math.pi * f)))
    return s.lr


def train(task: TrainTask, s: TrainSettings, console: Any = None) -> dict[str, Any]:
    """Train ``task.model`` (see module doc). Returns ``{"best": ..., "history": [...],
    "out_dir": ..., "steps": ...}``; the epoch history rows are also in ``log.jsonl``."""
    from rich.console import Console
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn

    console = console or Console(quiet=s.quiet)
    if s.threads:
        torch.set_num_threads(int(s.threads))
    device = resolve_device(s.device)
    out = Path(s.out_dir)
    out.mkdir(parents=True, exist_ok=True)
    task.model.to(device)
    opt = torch.optim.Adam(task.model.parameters(), lr=s.lr)
    nb = task.num_batches()
    total = s.epochs * nb
    epoch, skip, gstep, best, history = 0, 0, 0, math.inf, []
    last = out / "last.pt"
    if s.resume and last.is_file():
        ck = load_checkpoint(last, map_location=device)
        task.model.load_state_dict(ck.weights)
        st = ck.train_state or {}
        if st.get("optimizer"):
            opt.load_state_dict(st["optimizer"])
        epoch, skip, gstep = int(st.get("epoch", 0)), int(st.get("step_in_epoch", 0)), int(st.get("global_step", 0))
        best, history = float(st.get("best", math.inf)), list(st.get("history", []))
        console.print(f"resumed from {last}: epoch {epoch + 1}, batch {skip}/{nb}, step {gstep}")
    log = open(out / "log.jsonl", "a", encoding="utf-8")

    def write(row: dict[str, Any]) -> None:
        log.write(json.dumps(row) + "\n")
        log.flush()

    def state(ep: int, k: int) -> dict[str, Any]:
        return {"epoch": ep, "step_in_epoch": k, "global_step": gstep, "optimizer": opt.state_dict(),
                "best": best, "history": history, "settings": {k2: str(v) for k2, v in asdict(s).items()}}

    write({"type": "start", "time": time.time(), "device": str(device), "threads": torch.get_num_threads(),
           "batches_per_epoch": nb, "epochs": s.epochs, "resume_epoch": epoch, "resume_step": skip})
    stop = False
    with Progress(TextColumn("[bold]epoch {task.fields[ep]}"), BarColumn(), TextColumn("{task.completed}/{task.total}"),
                  TextColumn("loss {task.fields[loss]:.4f}"), TimeElapsedColumn(), TimeRemainingColumn(),
                  console=console, disable=s.quiet) as prog:
        while epoch < s.epochs and not stop:
            bar = prog.add_task("train", total=nb, completed=skip, ep=epoch + 1, loss=float("nan"))
            t0, run, n = time.time(), 0.0, 0
            task.model.train()
            for k, batch in enumerate(task.batches(epoch, skip), start=skip):
                for g in opt.param_groups:
                    g["lr"] = _lr_at(s, gstep, total)
                loss, parts = task.loss(batch, device)
                opt.zero_grad(set_to_none=True)
                loss.backward()
                gnorm = float(torch.nn.utils.clip_grad_norm_(task.model.parameters(), s.grad_clip)
                              if s.grad_clip > 0 else 0.0)
                opt.step()
                gstep += 1
                run, n = run + float(loss.detach()), n + 1
                prog.update(bar, completed=k + 1, loss=run / n)
                if gstep % s.log_every == 0:
                    row = {"type": "step", "epoch": epoch + 1, "batch": k + 1, "step": gstep, "loss": float(loss.detach()),
                           "grad_norm": gnorm, "lr": opt.param_groups[0]["lr"], **parts,
                           "sec_per_step": (time.time() - t0) / n}
                    write(row)
                    if not console.is_terminal:
                        console.print(f"epoch {epoch + 1} batch {k + 1}/{nb} loss {run / n:.5f} "
                                      f"({row['sec_per_step']:.2f} s/step)")
                if gstep % s.checkpoint_every == 0:
                    task.save(last, {"epoch": epoch + 1, "batch": k + 1}, state(epoch, k + 1))
                if s.max_steps is not None and gstep >= s.max_steps:
                    stop = True
                    break
            prog.remove_task(bar)
            if stop and k + 1 < nb:
                task.save(last, {"epoch": epoch + 1, "batch": k + 1}, state(epoch, k + 1))
                break
            tv = time.time()
            val = task.validate(device)
            row = {"type": "epoch", "epoch": epoch + 1, "train_loss": run / max(n, 1), **val,
                   "train_seconds": tv - t0, "val_seconds": time.time() - tv, "steps": gstep,
                   "lr": opt.param_groups[0]["lr"]}
            history.append(row)
            write(row)
            console.print(" ".join(f"{k2}={v:.4g}" if isinstance(v, float) else f"{k2}={v}" for k2, v in row.items()
                                   if k2 != "type"))
            epoch, skip = epoch + 1, 0
            if val.get(task.val_metric, math.inf) < best:
                best = val[task.val_metric]
                task.save(out / "best.pt", {"epoch": epoch, **val}, None)
            task.save(last, {"epoch": epoch, **val}, state(epoch, 0))
    log.close()
    return {"best": best, "history": history, "out_dir": str(out), "steps": gstep}
