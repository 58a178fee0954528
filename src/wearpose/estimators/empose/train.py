"""Training (:func:`train_empose`) and evaluation (:func:`evaluate_empose`) of the LGD-RNN."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import torch

from wearpose.estimators.checkpoint import save_checkpoint
from wearpose.estimators.empose.data import EmposeData, build_split, clip_seed, num_batches, recording_from_clip, simulate_clip
from wearpose.estimators.empose.estimator import EmposeEstimator
from wearpose.estimators.empose.model import lgd_loss, sensor_features
from wearpose.estimators.train import TrainSettings, train


class EmposeTask:
    """:class:`~wearpose.estimators.train.TrainTask` for the LGD-RNN."""

    val_metric = "val_mpjpe_mm"

    def __init__(self, est: EmposeEstimator, train_data: EmposeData, val_data: EmposeData | None) -> None:
        self.est, self.cfg = est, est.config
        self.model = est.model
        self.train_data, self.val_data = train_data, val_data
        self._nw = len(train_data.windows(self.cfg.seq_len, self.cfg.window_stride))

    def num_batches(self) -> int:
        return num_batches(self._nw, self.cfg.batch_size)

    def batches(self, epoch: int, skip: int):
        g = torch.Generator().manual_seed(self.cfg.seed * 100_003 + epoch)
        return self.train_data.iter_batches(self.cfg.seq_len, self.cfg.window_stride, self.cfg.batch_size, g, skip=skip)

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
        from wearpose.body.skeleton import MAJOR_JOINTS
        from wearpose.evaluate import mpjae, mpjpe

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

    def save(self, path: Path, meta: dict[str, Any], train_state: dict[str, Any] | None) -> None:
        save_checkpoint(self.est.checkpoint(meta, train_state), path)


def train_empose(est: EmposeEstimator, out_dir: str | Path, *, epochs: int | None = None, resume: bool = False,
                 threads: int | None = None, device: str = "auto", limit_train: int | None = None,
                 limit_val: int | None = None, max_steps: int | None = None, checkpoint_every: int = 100,
                 train_command: str = "", quiet: bool = False, store: Any = None,
                 cache_root: str | Path | None = None, console: Any = None) -> dict[str, Any]:
    """Simulate/load the training data and train ``est`` in place.

    Args:
        est: the estimator (its config drives data, model and optimisation).
        out_dir: run directory (``last.pt``, ``best.pt``, ``log.jsonl``).
        epochs: override ``config.epochs``.
        limit_train / limit_val: first N clips of the split (default all / ``config.val_clips``).
        max_steps: stop after N optimiser steps (tests).
    """
    from rich.console import Console

    console = console or Console(quiet=quiet)
    if threads:
        torch.set_num_threads(int(threads))
    cfg = est.config
    prog = (lambda d, t: console.print(f"  simulated {d}/{t} clips") if (d % 200 == 0 or d == t) else None)  # noqa: E731
    console.print(f"EM-POSE data: simulating/loading train split ({cfg.kit}, {cfg.rate:g} Hz)")
    tr = build_split("train", cfg, est.body, store=store, limit=limit_train, cache_root=cache_root, progress=prog)
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
        est.train_command = prev.train_command  # the command that started the run
        est.meta["resumed_with"] = train_command
    elif train_command:
        est.train_command = train_command
    est.meta.update({"train_clips": len(tr.clip_ids), "train_frames": tr.num_frames, "val_clips": len(va.clip_ids)})
    from wearpose.estimators.train import resolve_device

    if getattr(cfg, "init", "rnn") == "mean":
        est.model.set_mean_start(tr.pose6)  # "no RNN" ablation (a resumed run loads its own weights over it)
    est.to(resolve_device(device))  # network and body together: L_r runs the body inside the model
    # Estimators with another network (the Table 2 baselines) bring their own task.
    task = est.make_task(tr, va) if hasattr(est, "make_task") else EmposeTask(est, tr, va)
    s = TrainSettings(out_dir=Path(out_dir), epochs=epochs or cfg.epochs, lr=cfg.lr, lr_schedule=cfg.lr_schedule,
                      lr_min_factor=cfg.lr_min_factor, grad_clip=cfg.grad_clip, resume=resume, threads=threads,
                      device=device, checkpoint_every=checkpoint_every, max_steps=max_steps, quiet=quiet)
    return train(task, s, console)


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
    from wearpose.body.skeleton import MAJOR_JOINTS
    from wearpose.evaluate import mpjae, mpjpe, pa_mpjpe
    from wearpose.motion import CorpusStore

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
