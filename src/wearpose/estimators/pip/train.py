"""Training of the PIP kinematics module (:func:`train_pip`) with the generic loop
:func:`wearpose.estimators.train.train`."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import torch

from wearpose.estimators.empose.train import EmposeTask
from wearpose.estimators.pip.data import PipData, build_split
from wearpose.estimators.pip.model import pip_loss, run_windows
from wearpose.estimators.train import TrainSettings, resolve_device, train


class PipTask(EmposeTask):
    """:class:`~wearpose.estimators.train.TrainTask` for the five-RNN chain (window batching,
    epoch seeding and checkpointing as EM-POSE's task; PIP's loss and validation)."""

    val_metric = "val_joints_mm"

    def loss(self, batch: dict[str, torch.Tensor], device: torch.device):
        b = {k: v.to(device) for k, v in batch.items()}
        out, _ = run_windows(self.model, b)
        return pip_loss(out, b, self.cfg)

    @torch.no_grad()
    def validate(self, device: torch.device) -> dict[str, float]:
        """Validation windows (non-overlapping, from learned initial states): loss, mean joint
        position error of P_A (mm, root frame, 23 joints), root-relative rotation error of R_A
        (deg, 23 joints), contact accuracy (%), root speed error (cm/s)."""
        from wearpose.geometry import geodesic_angle, rot6d_to_matrix

        if self.val_data is None:
            return {}
        self.model.eval()
        tot, n, pe, ae, acc, ve = 0.0, 0, [], [], [], []
        for b in self.val_data.iter_batches(self.cfg.seq_len, self.cfg.seq_len, max(self.cfg.batch_size, 32), shuffle=False):
            b = {k: v.to(device) for k, v in b.items()}
            out, _ = run_windows(self.model, b)
            loss, _ = pip_loss(out, b, self.cfg)
            tot, n = tot + float(loss), n + 1
            B, T = b["x"].shape[:2]
            pe.append((out["joints"] - b["joints"]).view(B, T, -1, 3).norm(dim=-1).mean(-1).flatten())
            ae.append(geodesic_angle(rot6d_to_matrix(out["rot6"].view(B, T, -1, 6)),
                                     rot6d_to_matrix(b["rot6"].view(B, T, -1, 6))).mean(-1).flatten())
            acc.append(((out["contact_logit"] > 0).float() == b["contact"]).float().flatten())
            ve.append((out["vel"] - b["vel"]).view(B, T, -1, 3)[:, :, 0].norm(dim=-1).flatten() * self.cfg.vel_scale)
        self.model.train()
        if n == 0:
            return {}
        return {"val_loss": tot / n, "val_joints_mm": float(torch.cat(pe).mean()) * 1000,
                "val_rot_deg": math.degrees(float(torch.cat(ae).mean())), "val_contact_pct": float(torch.cat(acc).mean()) * 100,
                "val_root_vel_cm_s": float(torch.cat(ve).mean()) * 100}



def train_pip(est: Any, out_dir: str | Path, *, epochs: int | None = None, resume: bool = False,
              threads: int | None = None, device: str = "auto", limit_train: int | None = None,
              limit_val: int | None = None, max_steps: int | None = None, checkpoint_every: int = 100,
              train_command: str = "", quiet: bool = False, store: Any = None,
              cache_root: str | Path | None = None, console: Any = None) -> dict[str, Any]:
    """Simulate/load the training data and train ``est`` (a :class:`PipEstimator`) in place.

    Args:
        est: the estimator (its config drives data, model and optimisation).
        out_dir: run directory (``last.pt``, ``best.pt``, ``log.jsonl``).
        epochs: override ``config.epochs``.
        limit_train / limit_val: N clips of the split spread over it (default
            ``config.max_train_clips`` (0 = all) / ``config.val_clips``).
        max_steps: stop after N optimiser steps (tests).
    """
    from rich.console import Console

    console = console or Console(quiet=quiet)
    if threads:
        torch.set_num_threads(int(threads))
    cfg = est.config
    prog = (lambda d, t: console.print(f"  simulated {d}/{t} clips") if (d % 100 == 0 or d == t) else None)  # noqa: E731
    console.print(f"PIP data: simulating/loading train split ({cfg.kit}, {cfg.rate:g} Hz)")
    tr = build_split("train", cfg, est.body, store=store, limit=limit_train or cfg.max_train_clips or None,
                     cache_root=cache_root, progress=prog)
    va = build_split("val", cfg, est.body, store=store, limit=limit_val if limit_val is not None else (cfg.val_clips or None),
                     cache_root=cache_root, progress=prog)
    console.print(f"train: {len(tr.clip_ids)} clips, {tr.num_frames} frames; val: {len(va.clip_ids)} clips, "
                  f"{va.num_frames} frames; fingerprint {tr.fingerprint[:16]}")
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
    task = PipTask(est, tr, va)
    s = TrainSettings(out_dir=Path(out_dir), epochs=epochs or cfg.epochs, lr=cfg.lr, lr_schedule=cfg.lr_schedule,
                      lr_min_factor=cfg.lr_min_factor, grad_clip=cfg.grad_clip, resume=resume, threads=threads,
                      device=device, checkpoint_every=checkpoint_every, max_steps=max_steps, quiet=quiet)
    return train(task, s, console)
