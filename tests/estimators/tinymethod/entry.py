"""The tiny test method's training entry (data, task, run) and evaluation protocol."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping

import torch

from wearpose.estimators.checkpoint import fingerprint, save_checkpoint
from wearpose.estimators.method import TrainRun
from wearpose.estimators.seeding import clip_seed
from wearpose.estimators.train import train_estimator
from wearpose.evaluate.metrics import mpjae
from wearpose.geometry import matrix_to_rot6d
from wearpose.motion import CorpusStore
from wearpose.motion.resample import resample
from wearpose.recording import Recording, recording_from_simulation
from wearpose.sensors import simulate

from tests.estimators.tinymethod.estimator import TinyConfig, TinyEstimator


def simulated(est: TinyEstimator, store: CorpusStore, clip: str, seed: int, noise: str) -> Recording:
    """Clip ``clip`` at the method's rate (its first ``max_frames`` frames), worn as kit imu6."""
    motion = resample(store.load(clip), est.fps).slice(0, est.config.max_frames)
    with torch.no_grad():
        res = simulate(motion, est.kit_name, est.body, seed=seed, noise=noise)
    return recording_from_simulation(res, motion)


@dataclass
class ClipData:
    """Frames of simulated clips: ``x (N, S*9)`` sensor orientations, ``y (N, 24, 6)`` local
    rotations in 6D (the motion is at the sensors' rate, so frame k is sensor sample k)."""

    clip_ids: list[str]
    x: torch.Tensor
    y: torch.Tensor
    fingerprint: str

    @property
    def num_frames(self) -> int:
        return int(self.x.shape[0])


def build(est: TinyEstimator, split: str, *, store: Any = None, limit: int | None = None, cache_root: Any = None,
          progress: Callable[[int, int], None] | None = None) -> ClipData:
    """The first ``limit`` clips of ``split``, simulated without noise (training seeds)."""
    from wearpose.estimators.inputs import prepare

    store = store if isinstance(store, CorpusStore) else CorpusStore(store)
    ids = store.clips(split=split)[: limit or None]
    xs, ys = [], []
    for k, cid in enumerate(ids):
        rec = simulated(est, store, cid, clip_seed(cid, est.config.seed, "tiny-train"), "none")
        xs.append(prepare(rec, est.spec).channels["orientation"].flatten(1))
        ys.append(matrix_to_rot6d(rec.ground_truth.pose.float()))
        if progress:
            progress(k + 1, len(ids))
    return ClipData(list(ids), torch.cat(xs), torch.cat(ys), fingerprint(ids, {"kit": est.kit_name, "rate": est.fps}))


class TinyTask:
    """:class:`~wearpose.estimators.train.TrainTask`: shuffled frames, MSE on 6D; validation MPJAE (deg)."""

    val_metric = "val_mpjae_deg"

    def __init__(self, est: TinyEstimator, train: ClipData, val: ClipData) -> None:
        self.est, self.model, self.train, self.val = est, est.model, train, val
        self.bs = est.config.batch_size

    def num_batches(self) -> int:
        return math.ceil(self.train.num_frames / self.bs)

    def batches(self, epoch: int, skip: int) -> Iterable[dict[str, torch.Tensor]]:
        order = torch.randperm(self.train.num_frames, generator=torch.Generator().manual_seed(self.est.config.seed + epoch))
        for b in range(skip, self.num_batches()):
            i = order[b * self.bs:(b + 1) * self.bs]
            yield {"x": self.train.x[i], "y": self.train.y[i]}

    def loss(self, batch: dict[str, torch.Tensor], device: torch.device) -> tuple[torch.Tensor, dict[str, float]]:
        loss = torch.nn.functional.mse_loss(self.model(batch["x"].to(device)), batch["y"].to(device))
        return loss, {"mse": float(loss.detach())}

    @torch.no_grad()
    def validate(self, device: torch.device) -> dict[str, float]:
        from wearpose.geometry import rot6d_to_matrix

        self.model.eval()
        pred = rot6d_to_matrix(self.model(self.val.x.to(device))).cpu()
        self.model.train()
        return {"val_mpjae_deg": float(mpjae(pred, rot6d_to_matrix(self.val.y)).mean()) * 180 / math.pi}

    def save(self, path: Path, meta: dict[str, Any], train_state: dict[str, Any] | None) -> None:
        save_checkpoint(self.est.checkpoint(meta, train_state), path)


def train_from_options(opts: Mapping[str, Any], run: TrainRun) -> dict[str, Any]:
    """``wearpose train tiny``: the preset overridden by ``--hidden``, trained with the shared loop."""
    est = TinyEstimator(TinyConfig.preset(run.config).override(hidden=opts["hidden"]))
    res = train_estimator(est, run.out or Path("runs") / "tiny", lambda split, **kw: build(est, split, **kw),
                          lambda tr, va: TinyTask(est, tr, va), label="tiny", **run.loop())
    return {"method": "tiny", "config": est.config.to_dict(), **res}


def protocol(est: TinyEstimator, store: CorpusStore, split: str, clips: int | None, seed: int, noise: str,
             progress: Callable[[int, int], None] | None, frame_stride: int = 1) -> dict[str, Any]:
    """``wearpose evaluate``: the first ``clips`` clips of ``split`` simulated with ``noise``
    (evaluation seeds), estimated offline; MPJAE on the 15 major joints over valid frames."""
    ids = store.clips(split=split)[: clips or None]
    errs = []
    for k, cid in enumerate(ids):
        rec = simulated(est, store, cid, clip_seed(cid, seed, "tiny-eval"), noise)
        track = est.estimate(rec)
        e = mpjae(track.local_rot, rec.ground_truth.pose.float())[track.valid]
        errs.append(e[::frame_stride])
        if progress:
            progress(k + 1, len(ids))
    e = torch.cat(errs)
    return {"frames": int(e.numel()), "clip_ids": list(ids), "metrics": {"mpjae_deg": float(e.mean()) * 180 / math.pi},
            "protocol": "first max_frames frames of each clip, simulated imu6, MPJAE (15 major joints)",
            "detail": {"per_clip_frames": [int(x.numel()) for x in errs]}}
