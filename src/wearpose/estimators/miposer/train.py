"""Training of the MI-Poser IK network (:func:`train_miposer`) with the generic loop
(:func:`wearpose.estimators.train.train`)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import torch

from wearpose.estimators.checkpoint import save_checkpoint
from wearpose.estimators.empose.data import num_batches
from wearpose.estimators.miposer.config import UPPER_BODY
from wearpose.estimators.miposer.data import MiposerData, build_split
from wearpose.estimators.miposer.model import ik_loss, window_features
from wearpose.estimators.train import TrainSettings, resolve_device, train


class MiposerTask:
    """:class:`~wearpose.estimators.train.TrainTask` for the AvatarPoser-style network.

    Validation: upper-body MPJPE (:data:`UPPER_BODY`, root-aligned, mm) at the last frame of
    non-overlapping windows ending on clip frames (not the T-pose prefix).
    """

    val_metric = "val_mpjpe_upper_mm"

    def __init__(self, est: Any, train_data: MiposerData, val_data: MiposerData | None) -> None:
        self.est, self.cfg = est, est.config
        self.model = est.model
        self.train_data, self.val_data = train_data, val_data
        self._nw = len(train_data.windows(self.cfg.window, self.cfg.stride))

    def num_batches(self) -> int:
        return num_batches(self._nw, self.cfg.batch_size)

    def batches(self, epoch: int, skip: int):
        g = torch.Generator().manual_seed(self.cfg.seed * 100_003 + epoch)
        return self.train_data.iter_batches(self.cfg.window, self.cfg.stride, self.cfg.batch_size, g, skip=skip)

    def _forward(self, b: dict[str, torch.Tensor], device: torch.device, every_frame: bool):
        x, C, _ = window_features(b["R"].to(device), b["p"].to(device), self.est.fps)
        pose6 = b["pose6"].to(device)
        if every_frame:
            k = self.cfg.window // 4  # frames with at least a quarter window of history
            root6, local6 = self.model(x, every_frame=True)
            return ik_loss((root6[:, k:], local6[:, k:]), C, pose6[:, k:], self.est.body, self.cfg)
        return ik_loss(self.model(x), C, pose6[:, -1], self.est.body, self.cfg)

    def loss(self, batch: dict[str, torch.Tensor], device: torch.device):
        loss, parts, _, _ = self._forward(batch, device, self.cfg.dense)
        return loss, parts

    @torch.no_grad()
    def validate(self, device: torch.device) -> dict[str, float]:
        from wearpose.evaluate import mpjpe

        if self.val_data is None:
            return {}
        self.model.eval()
        tot, n, pe = 0.0, 0, []
        for b in self.val_data.iter_batches(self.cfg.window, self.cfg.window // 2, 256, shuffle=False, clip_only=True):
            loss, _, J, Jg = self._forward(b, device, False)
            tot, n = tot + float(loss), n + 1
            pe.append(mpjpe(J, Jg, UPPER_BODY).cpu())
        self.model.train()
        return {"val_loss": tot / max(n, 1), "val_mpjpe_upper_mm": float(torch.cat(pe).mean()) * 1000 if pe else float("nan")}

    def save(self, path: Path, meta: dict[str, Any], train_state: dict[str, Any] | None) -> None:
        save_checkpoint(self.est.checkpoint(meta, train_state), path)


def train_miposer(est: Any, out_dir: str | Path, *, epochs: int | None = None, resume: bool = False,
                  threads: int | None = None, device: str = "auto", limit_train: int | None = None,
                  limit_val: int | None = None, max_steps: int | None = None, checkpoint_every: int = 100,
                  train_command: str = "", quiet: bool = False, store: Any = None,
                  cache_root: str | Path | None = None, console: Any = None) -> dict[str, Any]:
    """Simulate/load the data and train ``est`` (a :class:`MiposerEstimator` or
    :class:`~wearpose.estimators.miposer.baselines.ImuPoserEstimator`) in place.

    Args:
        est: the estimator (its config drives data, model and optimisation; an estimator with
            ``make_task``/``build_data`` brings its own data and task).
        out_dir: run directory (``last.pt``, ``best.pt``, ``log.jsonl``).
        epochs: override ``config.epochs``. limit_train / limit_val: first N clips.
        max_steps: stop after N optimiser steps (tests).
    """
    from rich.console import Console

    console = console or Console(quiet=quiet)
    if threads:
        torch.set_num_threads(int(threads))
    cfg = est.config
    prog = (lambda d, t: console.print(f"  simulated {d}/{t} clips") if (d % 200 == 0 or d == t) else None)  # noqa: E731
    build = getattr(est, "build_data", None) or (lambda split, **kw: build_split(split, cfg, est.body, **kw))
    console.print(f"MI-Poser data: simulating/loading train split ({cfg.kit}, {cfg.rate:g} Hz)")
    tr = build("train", store=store, limit=limit_train, cache_root=cache_root, progress=prog)
    va = build("val", store=store, limit=limit_val if limit_val is not None else (cfg.val_clips or None),
               cache_root=cache_root, progress=prog)
    console.print(f"train: {len(tr.clip_ids)} clips, {tr.num_frames} frames; val: {len(va.clip_ids)} clips; "
                  f"fingerprint {tr.fingerprint[:16]}")
    est.data_fingerprint = tr.fingerprint
    last = Path(out_dir) / "last.pt"
    if resume and last.is_file():
        from wearpose.estimators.checkpoint import load_checkpoint

        prev = load_checkpoint(last)
        prev.check(method=est.name, kit=est.kit_name, body_asset=est.body_asset_id, path=last)
        if prev.config != cfg.to_dict():
            console.print(f"[yellow]warning[/]: resuming {last} with a different config than it was trained with")
        est.train_command = prev.train_command
        est.meta["resumed_with"] = train_command
    elif train_command:
        est.train_command = train_command
    est.meta.update({"train_clips": len(tr.clip_ids), "train_frames": tr.num_frames, "val_clips": len(va.clip_ids)})
    est.to(resolve_device(device))
    task = est.make_task(tr, va) if hasattr(est, "make_task") else MiposerTask(est, tr, va)
    s = TrainSettings(out_dir=Path(out_dir), epochs=epochs or cfg.epochs, lr=cfg.lr, lr_schedule=cfg.lr_schedule,
                      lr_min_factor=cfg.lr_min_factor, grad_clip=cfg.grad_clip, resume=resume, threads=threads,
                      device=device, checkpoint_every=checkpoint_every, max_steps=max_steps, quiet=quiet)
    return train(task, s, console)
