"""Training (:func:`train_empose`) and evaluation (:func:`evaluate_empose`) of the LGD-RNN."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import torch

from wearpose.estimators.empose.data import EmposeData, build_split, recording_from_clip, simulate_clip
from wearpose.estimators.seeding import clip_seed
from wearpose.estimators.empose.estimator import EmposeEstimator
from wearpose.estimators.empose.model import lgd_loss, sensor_features
from wearpose.estimators.train import WindowTask, train_estimator
from wearpose.body.skeleton import MAJOR_JOINTS
from wearpose.evaluate.metrics import mpjae, mpjpe, pa_mpjpe
from wearpose.motion import CorpusStore


class EmposeTask(WindowTask):
    """:class:`~wearpose.estimators.train.TrainTask` for the LGD-RNN (windows of ``seq_len``
    frames every ``window_stride``)."""

    val_metric = "val_mpjpe_mm"

    def window(self) -> tuple[int, int]:
        return self.cfg.seq_len, self.cfg.window_stride

    def _forward(self, b: dict[str, torch.Tensor], device: torch.device, train: bool):
        b = {k: v.to(device) for k, v in b.items()}
        x = sensor_features(b["position"], b["orientation"])
        outs, _ = self.model(x, b["position"], b["orientation"], b["off_R"], b["off_t"], self.est.sensors, train=train)
        return outs, b

    def loss(self, batch: dict[str, torch.Tensor], device: torch.device):
        outs, b = self._forward(batch, device, True)
        return lgd_loss(outs, b["pose"], b["betas"], b["joints"], self.cfg)

    @torch.no_grad()
    def validate(self, device: torch.device) -> dict[str, float]:

        if self.val_data is None:
            return {}
        self.model.eval()
        tot, n, pe, ae, pe0 = 0.0, 0, [], [], []
        for b in self.val_data.iter_batches(self.cfg.seq_len, self.cfg.seq_len, max(self.cfg.batch_size, 32), shuffle=False):
            outs, b = self._forward(b, device, False)
            loss, _ = lgd_loss(outs, b["pose"], b["betas"], b["joints"], self.cfg)
            tot, n = tot + float(loss), n + 1
            ok = b["valid"].all(-1)
            pe.append(mpjpe(outs[-1]["joints"], b["joints"], MAJOR_JOINTS)[ok])
            pe0.append(mpjpe(outs[0]["joints"], b["joints"], MAJOR_JOINTS)[ok])
            ae.append(mpjae(outs[-1]["local_rot"], b["pose"])[ok])
        self.model.train()
        cat = lambda xs: torch.cat(xs) if xs else torch.zeros(0)  # noqa: E731
        return {"val_loss": tot / max(n, 1), "val_mpjpe_mm": float(cat(pe).mean()) * 1000,
                "val_mpjpe_rnn_mm": float(cat(pe0).mean()) * 1000, "val_mpjae_deg": math.degrees(float(cat(ae).mean()))}


def train_empose(est: EmposeEstimator, out_dir: str | Path, **run: Any) -> dict[str, Any]:
    """Simulate/load the training data and train ``est`` in place.

    Args:
        est: the estimator (its config drives data, model and optimisation; an estimator with
            ``make_task`` (the Table 2 baselines, the two-stage model) brings its own task).
        out_dir: run directory (``last.pt``, ``best.pt``, ``log.jsonl``).
        run: the run options of :func:`~wearpose.estimators.train.train_estimator`: ``epochs``
            (override ``config.epochs``), ``limit_train`` / ``limit_val`` (first N clips of the
            split; default all / ``config.val_clips``), ``resume``, ``threads``, ``device``,
            ``max_steps``, ``checkpoint_every``, ``train_command``, ``quiet``, ``store``,
            ``cache_root``, ``console``.
    """
    cfg = est.config

    def make_task(tr: EmposeData, va: EmposeData) -> Any:
        if getattr(cfg, "init", "rnn") == "mean":
            est.model.set_mean_start(tr.pose6)  # "no RNN" ablation (a resumed run loads its own weights over it)
        return est.make_task(tr, va) if hasattr(est, "make_task") else EmposeTask(est, tr, va)

    return train_estimator(est, out_dir, lambda split, **kw: build_split(split, cfg, est.body, **kw), make_task,
                           label="EM-POSE", **run)


def evaluate_empose(checkpoint: str | Path | EmposeEstimator, split: str = "test", limit: int | None = None, *,
                    noise: str = "default", seed: int = 0, store: Any = None) -> dict[str, Any]:
    """MPJPE / PA-MPJPE / MPJAE (15 major joints, mean +- std over frames) on simulated recordings.

    Each clip of ``split`` (sorted ids, first ``limit``) is resampled to the checkpoint's rate
    and simulated with the ``noise`` EM error model and a held-out random subject (offsets
    seeded in an evaluation namespace, never drawn for training). The recording carries those
    offsets (the calibrated ``O_p`` EM-POSE assumes). Only frames where every sensor is valid
    count (EM-POSE Sec. 6.2). Ground truth: the clip's pose with the root in the EM source
    frame, like the estimate. Units: mm and degrees.
    """

    est = checkpoint if isinstance(checkpoint, EmposeEstimator) else EmposeEstimator.load(checkpoint)
    store = store or CorpusStore()
    ids = store.clips(split=split)[: limit or None]
    pe, pa, ae = [], [], []
    frames = 0
    for cid in ids:
        r = simulate_clip(store.load(cid), est.config, est.body, clip_seed(cid, seed, "eval"), noise=noise, offsets="random")
        track = est.estimate(recording_from_clip(r, est.config))
        with torch.no_grad():
            pj = est.body(track.local_rot, track.betas, None, return_vertices=False).joints
        ok = track.valid
        frames += int(ok.sum())
        pe.append(mpjpe(pj, r["joints"], MAJOR_JOINTS)[ok])
        pa.append(pa_mpjpe(pj, r["joints"], MAJOR_JOINTS)[ok])
        ae.append(mpjae(track.local_rot, r["pose"])[ok])
    def ms(xs: list[torch.Tensor], k: float) -> tuple[float, float]:
        x = torch.cat(xs) * k if xs else torch.zeros(0)
        return (float(x.mean()), float(x.std())) if x.numel() else (math.nan, math.nan)
    (m1, s1), (m2, s2), (m3, s3) = ms(pe, 1000.0), ms(pa, 1000.0), ms(ae, 180.0 / math.pi)
    return {"split": split, "clips": len(ids), "frames": frames, "noise": noise, "kit": est.kit_name,
            "mpjpe_mm": m1, "mpjpe_std_mm": s1, "pa_mpjpe_mm": m2, "pa_mpjpe_std_mm": s2,
            "mpjae_deg": m3, "mpjae_std_deg": s3, "joints": "15 major (DIP/EM-POSE)",
            "data_fingerprint": est.data_fingerprint}
