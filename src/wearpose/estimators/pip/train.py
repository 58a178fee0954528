"""Training of the PIP kinematics module (:func:`train_pip`) with the generic loop
:func:`wearpose.estimators.train.train`."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import torch

from wearpose.estimators.pip.data import build_split
from wearpose.estimators.pip.model import pip_loss, run_windows
from wearpose.estimators.train import WindowTask, train_estimator
from wearpose.geometry import geodesic_angle, rot6d_to_matrix


class PipTask(WindowTask):
    """:class:`~wearpose.estimators.train.TrainTask` for the five-RNN chain (windows of
    ``seq_len`` frames every ``window_stride``; PIP's loss and validation)."""

    val_metric = "val_joints_mm"

    def window(self) -> tuple[int, int]:
        return self.cfg.seq_len, self.cfg.window_stride

    def window_options(self) -> dict[str, Any]:
        return {"min_len": self.cfg.min_window, "sitting_len": self.cfg.sitting_window}

    def loss(self, batch: dict[str, torch.Tensor], device: torch.device):
        b = {k: v.to(device) for k, v in batch.items()}
        out, _ = run_windows(self.model, b)
        return pip_loss(out, b, self.cfg)

    @torch.no_grad()
    def validate(self, device: torch.device) -> dict[str, float]:
        """Validation windows (non-overlapping, ``seq_len`` frames, and the shorter clips as one
        window when ``min_window`` says so; from learned initial states): loss, mean joint
        position error of P_A (mm, root frame, 23 joints), root-relative rotation error of R_A
        (deg, 23 joints), contact accuracy (%), root speed error (cm/s); over valid frames."""
        if self.val_data is None:
            return {}
        self.model.eval()
        tot, n, pe, ae, acc, ve = 0.0, 0, [], [], [], []
        for b in self.val_data.iter_batches(self.cfg.seq_len, self.cfg.seq_len, max(self.cfg.batch_size, 32), shuffle=False,
                                            **self.window_options()):
            b = {k: v.to(device) for k, v in b.items()}
            out, _ = run_windows(self.model, b)
            loss, _ = pip_loss(out, b, self.cfg)
            tot, n = tot + float(loss), n + 1
            B, T = b["x"].shape[:2]
            m = b["mask"]  # (B, T)
            pe.append((out["joints"] - b["joints"]).view(B, T, -1, 3).norm(dim=-1).mean(-1)[m])
            ae.append(geodesic_angle(rot6d_to_matrix(out["rot6"].view(B, T, -1, 6)),
                                     rot6d_to_matrix(b["rot6"].view(B, T, -1, 6))).mean(-1)[m])
            acc.append(((out["contact_logit"] > 0).float() == b["contact"]).float()[m].flatten())
            ve.append((out["vel"] - b["vel"]).view(B, T, -1, 3)[:, :, 0].norm(dim=-1)[m] * self.cfg.vel_scale)
        self.model.train()
        if n == 0:
            return {}
        return {"val_loss": tot / n, "val_joints_mm": float(torch.cat(pe).mean()) * 1000,
                "val_rot_deg": math.degrees(float(torch.cat(ae).mean())), "val_contact_pct": float(torch.cat(acc).mean()) * 100,
                "val_root_vel_cm_s": float(torch.cat(ve).mean()) * 100}


def train_pip(est: Any, out_dir: str | Path, *, limit_train: int | None = None, **run: Any) -> dict[str, Any]:
    """Simulate/load the training data and train ``est`` (a :class:`PipEstimator`) in place.

    Args:
        est: the estimator (its config drives data, model and optimisation).
        out_dir: run directory (``last.pt``, ``best.pt``, ``log.jsonl``).
        limit_train: N clips of the train split spread over it (default ``config.max_train_clips``, 0 = all).
        run: the run options of :func:`~wearpose.estimators.train.train_estimator`: ``epochs``
            (override ``config.epochs``), ``limit_val`` (N validation clips spread over the split;
            default ``config.val_clips``), ``resume``, ``threads``, ``device``, ``max_steps``,
            ``checkpoint_every``, ``train_command``, ``quiet``, ``store``, ``cache_root``, ``console``.
    """
    cfg = est.config
    return train_estimator(est, out_dir, lambda split, **kw: build_split(split, cfg, est.body, **kw),
                           lambda tr, va: PipTask(est, tr, va), label="PIP",
                           limit_train=limit_train or cfg.max_train_clips or None, progress_every=100, **run)
