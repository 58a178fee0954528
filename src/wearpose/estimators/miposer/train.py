"""Training of the MI-Poser IK network (:func:`train_miposer`) with the generic loop
(:func:`wearpose.estimators.train.train`)."""

from __future__ import annotations

from pathlib import Path
from typing import Any, Iterator

import torch

from wearpose.estimators.miposer.config import UPPER_BODY
from wearpose.estimators.miposer.data import build_split
from wearpose.estimators.miposer.model import ik_loss, window_features
from wearpose.estimators.train import WindowTask, train_estimator
from wearpose.evaluate.metrics import mpjpe


class MiposerTask(WindowTask):
    """:class:`~wearpose.estimators.train.TrainTask` for the AvatarPoser-style network.

    Validation: upper-body MPJPE (:data:`UPPER_BODY`, root-aligned, mm) at the last frame of
    non-overlapping windows ending on clip frames (not the T-pose prefix).
    """

    val_metric = "val_mpjpe_upper_mm"

    def window(self) -> tuple[int, int]:
        return self.cfg.window, self.cfg.stride

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

    def val_batches(self) -> Iterator[dict[str, torch.Tensor]]:
        """The validation windows: every half window, ending on clip frames, 256 a batch."""
        return self.val_data.iter_batches(self.cfg.window, self.cfg.window // 2, 256, shuffle=False, clip_only=True)

    @torch.no_grad()
    def validate(self, device: torch.device) -> dict[str, float]:
        if self.val_data is None:
            return {}
        self.model.eval()
        tot, n, pe = 0.0, 0, []
        for b in self.val_batches():
            loss, _, J, Jg = self._forward(b, device, False)
            tot, n = tot + float(loss), n + 1
            pe.append(mpjpe(J, Jg, UPPER_BODY).cpu())
        self.model.train()
        return {"val_loss": tot / max(n, 1), "val_mpjpe_upper_mm": float(torch.cat(pe).mean()) * 1000 if pe else float("nan")}


def train_miposer(est: Any, out_dir: str | Path, **run: Any) -> dict[str, Any]:
    """Simulate/load the data and train ``est`` (a :class:`MiposerEstimator` or
    :class:`~wearpose.estimators.miposer.baselines.ImuPoserEstimator`) in place.

    Args:
        est: the estimator (its config drives data, model and optimisation; an estimator with
            ``make_task``/``build_data`` brings its own data and task).
        out_dir: run directory (``last.pt``, ``best.pt``, ``log.jsonl``).
        run: the run options of :func:`~wearpose.estimators.train.train_estimator`: ``epochs``
            (override ``config.epochs``), ``limit_train`` / ``limit_val`` (first N clips; default
            all / ``config.val_clips``), ``resume``, ``threads``, ``device``, ``max_steps``,
            ``checkpoint_every``, ``train_command``, ``quiet``, ``store``, ``cache_root``, ``console``.
    """
    build = getattr(est, "build_data", None) or (lambda split, **kw: build_split(split, est.config, est.body, **kw))
    make_task = getattr(est, "make_task", None) or (lambda tr, va: MiposerTask(est, tr, va))
    return train_estimator(est, out_dir, build, make_task, label="MI-Poser", val_frames=False, **run)
