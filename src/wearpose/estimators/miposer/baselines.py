"""The IMU-only baseline of MI-Poser Sec. 5.2.2: IMUPoser's network (Mollyn et al., CHI 2023,
a two-layer bidirectional LSTM) on three IMUs at MI-Poser's sensor places (head and both wrists).

Sensors: kit ``imu3-head-wrists`` (registered here): 6-axis IMUs on the ``head`` and the two
``*_wrist`` sites at 60 Hz, simulated with ``imu_orientation="segment"`` (the orientation of the
bone the sensor rides on: head, forearms -- what a T-pose sensor-to-segment calibration gives,
the "with sensor-position calibration" setting of Sec. 5.2.2) and the default IMU noise.

Input per frame, in the head's heading frame of that frame (rotated about +Y so the head faces
+Z): each sensor's orientation (6D) and free acceleration (units of g): 27 numbers. Network:
linear embedding, 2-layer BiLSTM (``hidden`` per direction), linear read-out of the root
orientation (6D, heading frame) and 21 local joint rotations (6D) per frame. Loss:
:func:`~wearpose.estimators.miposer.model.ik_loss`, the MI-Poser network's. Offline only
(bidirectional): :meth:`ImuPoserEstimator.step` raises.

No translation is estimated (IMUs give no position); ``trans`` is None.
"""

from __future__ import annotations

import warnings
from pathlib import Path
from typing import Any, Iterator, Mapping

import numpy as np
import torch
from torch import nn

from wearpose.errors import ShapeError
from wearpose.estimators.base import Estimator, PoseFrame, PoseTrack, SensorFrame
from wearpose.estimators.checkpoint import Checkpoint, NetworkCheckpointing, load_checkpoint
from wearpose.estimators.base import OfflineOnlyError
from wearpose.estimators.seeding import clip_seed, init_seed, seeded
from wearpose.estimators.inputs import InputSpec, prepare
from wearpose.estimators.miposer.config import PREDICTED_JOINTS, MiposerConfig
from wearpose.estimators.clipstore import split_source
from wearpose.estimators.miposer.data import DATA_VERSION, MiposerData, cached_split
from wearpose.estimators.miposer.model import decode_pose, heading_frame, ik_loss
from wearpose.estimators.miposer.train import MiposerTask, train_miposer
from wearpose.estimators.registry import register_estimator
from wearpose.geometry import matrix_to_rot6d
from wearpose.motion import resample
from wearpose.sensors import SensorKit, SensorSpec, get_kit, list_kits, register_kit, simulate

KIT = "imu3-head-wrists"
if KIT not in list_kits():
    register_kit(SensorKit(KIT, (SensorSpec("head_imu", "imu", "head", 60.0),
                                 SensorSpec("left_wrist_imu", "imu", "left_wrist", 60.0),
                                 SensorSpec("right_wrist_imu", "imu", "right_wrist", 60.0)),
                           None, "MI-Poser Sec. 5.2.2 IMU-only baseline: head + wrist IMUs (IMUPoser), 60 Hz"))
G = 9.81


def imu_features(R: torch.Tensor, a: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Per-frame input (module doc) from orientations ``R`` ``(..., S, 3, 3)`` (head first) and free
    accelerations ``a`` ``(..., S, 3)`` m/s^2: ``(x (..., 9 S), C (..., 3, 3))`` with ``C`` the
    world -> heading-frame rotation of each frame."""
    C, _ = heading_frame(R[..., 0, :, :], torch.zeros_like(a[..., 0, :]))
    Rc = C.unsqueeze(-3) @ R
    ac = (C.unsqueeze(-3) @ a.unsqueeze(-1)).squeeze(-1) / G
    return torch.cat([matrix_to_rot6d(Rc), ac], -1).flatten(-2), C


class ImuPoserNet(nn.Module):
    """``forward(x (B, T, F)) -> (root6 (B, T, 6), local6 (B, T, 21, 6))`` (module doc)."""

    def __init__(self, cfg: MiposerConfig, sensors: int = 3) -> None:
        super().__init__()
        self.embed = nn.Linear(9 * sensors, cfg.hidden)
        self.lstm = nn.LSTM(cfg.hidden, cfg.hidden, cfg.layers, batch_first=True, bidirectional=True)
        self.out = nn.Linear(2 * cfg.hidden, 6 * PREDICTED_JOINTS)

    def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        h, _ = self.lstm(torch.relu(self.embed(x)))
        y = self.out(h)
        return y[..., :6], y[..., 6:].reshape(*y.shape[:-1], PREDICTED_JOINTS - 1, 6)


def simulate_imu_clip(motion: Any, cfg: MiposerConfig, body: Any, seed: int, noise: str | None = None) -> dict[str, Any]:
    """Simulate the baseline's IMUs on a clip at ``cfg.rate``.

    Returns:
        ``{"R": (T, 3, 3, 3), "a": (T, 3, 3), "valid": (T, 3), "pose": (T, 24, 3, 3), "motion", "sim"}``.
    """
    m = motion if abs(motion.fps - cfg.rate) < 1e-9 else resample(motion, cfg.rate)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sim = simulate(m, KIT, body, seed=seed, noise=noise or cfg.train_noise, imu_orientation="segment", rate=cfg.rate)
    names = get_kit(KIT).sensor_names
    R = torch.stack([sim[n].orientation for n in names], 1).float()
    a = torch.stack([sim[n].acceleration for n in names], 1).float()
    v = torch.stack([sim[n].valid for n in names], 1)
    return {"R": R, "a": torch.nan_to_num(a), "valid": v, "pose": m.pose.float(), "motion": m, "sim": sim}


def build_imu_split(split: str, cfg: MiposerConfig, body: Any, *, store: Any = None, limit: int | None = None,
                    cache_root: str | Path | None = None, progress: Any = None, clip_ids: Any = None) -> MiposerData:
    """Simulate (or load from the cache) one split for the baseline. The returned
    :class:`~wearpose.estimators.miposer.data.MiposerData` holds orientations in ``R`` and free
    accelerations (m/s^2) in ``p``; there is no T-pose prefix (``in_clip`` all True)."""
    settings = {"version": DATA_VERSION, "kit": KIT, "rate": cfg.rate, "noise": cfg.train_noise, "seed": cfg.seed,
                "body_asset": body.asset_id, "imu_orientation": "segment"}
    store, ids, fp, root = split_source(split, settings, "miposer", store=store, limit=limit, cache_root=cache_root,
                                        clip_ids=clip_ids)

    def one(cid: str) -> dict[str, torch.Tensor]:
        r = simulate_imu_clip(store.load(cid), cfg, body, clip_seed(cid, cfg.seed, "imuposer"))
        return {"R": r["R"], "p": r["a"], "valid": r["valid"], "pose6": matrix_to_rot6d(r["pose"][:, :PREDICTED_JOINTS]),
                "in_clip": torch.ones(r["R"].shape[0], dtype=torch.bool)}

    return cached_split(root / f"imu-{split}-{fp[:16]}.pt", ids, one, fp, settings, progress)


class ImuPoserTask(MiposerTask):
    """:class:`~wearpose.estimators.train.TrainTask` of the baseline: MI-Poser's task (windows,
    batches, checkpoints, upper-body MPJPE validation) with every frame of a window supervised
    (the BiLSTM's output at every frame) and validation on non-overlapping windows (every frame)."""

    def _forward(self, b: dict[str, torch.Tensor], device: torch.device, every_frame: bool = True):
        # every_frame is ignored: the bidirectional network is supervised at every frame
        x, C = imu_features(b["R"].to(device), b["p"].to(device))
        root6, local6 = self.model(x)
        return ik_loss((root6.flatten(0, 1), local6.flatten(0, 1)), C.flatten(0, 1), b["pose6"].to(device).flatten(0, 1),
                       self.est.body, self.cfg)

    def val_batches(self) -> Iterator[dict[str, torch.Tensor]]:
        """Non-overlapping validation windows, 64 a batch (the data has no T-pose prefix)."""
        return self.val_data.iter_batches(self.cfg.window, self.cfg.window, 64, shuffle=False)


@register_estimator("imuposer")
class ImuPoserEstimator(NetworkCheckpointing, Estimator):
    """IMU-only head + wrists baseline (module doc). Offline only."""

    name = "imuposer"
    causal = False
    lookahead = 0

    def __init__(self, config: MiposerConfig | None = None, body: Any = None, device: str | torch.device = "cpu") -> None:
        config = config or MiposerConfig.preset("cpu", model="imuposer")
        if config.model != "imuposer":
            raise ShapeError(f"ImuPoserEstimator needs model='imuposer', got {config.model!r}")
        self.init_state(config, body, device, kit=KIT)
        with seeded(init_seed(self.config.seed)):  # initial weights: a function of the seed (issue 24)
            self.model = ImuPoserNet(self.config, len(self.sensor_names)).to(self.device)

    def build_data(self, split: str, **kw: Any) -> MiposerData:
        return build_imu_split(split, self.config, self.body, **kw)

    def make_task(self, tr: MiposerData, va: MiposerData | None) -> ImuPoserTask:
        return ImuPoserTask(self, tr, va)

    @classmethod
    def load(cls, path: str | Path, *, kit: str | None = None, body: Any = None,
             map_location: str | torch.device = "cpu") -> ImuPoserEstimator:
        return cls.from_checkpoint(load_checkpoint(path, map_location), kit=kit, body=body, device=map_location,
                                   path=path)

    @classmethod
    def from_checkpoint(cls, ckpt: Checkpoint, *, kit: str | None = None, body: Any = None,
                        device: str | torch.device = "cpu", path: str | Path = "<checkpoint>") -> ImuPoserEstimator:
        """The estimator of a read checkpoint (:meth:`Estimator.from_checkpoint`)."""
        body = cls.check_checkpoint(ckpt, kit=kit, body=body, path=path)
        est = cls(MiposerConfig.from_dict(ckpt.config), body=body, device=device)
        ckpt.check(sensors=est.sensor_names, path=path)
        return est.restore(ckpt)

    def fit(self, *args: Any, **kwargs: Any) -> Any:
        return train_miposer(self, *args, **kwargs)

    @classmethod
    def training_data_description(cls, config: Mapping[str, Any]) -> str | None:
        """The card sentence (:meth:`Estimator.training_data_description`) of :func:`build_imu_split`
        and the training windows."""
        cfg = MiposerConfig.from_dict(dict(config))
        noise = {"default": "default IMU noise", "none": "no noise"}[cfg.train_noise]
        return (f"kit {cfg.kit} (head + wrist IMUs, wearpose.sensors.simulate, {noise}, imu_orientation='segment' = "
                f"sensor-to-segment calibrated) at {cfg.rate:g} Hz, no T-pose prefix; windows of {cfg.window} frames "
                f"every {cfg.stride}, every frame supervised")

    @torch.no_grad()
    def infer(self, R: torch.Tensor, a: torch.Tensor) -> torch.Tensor:
        """Local rotations ``(T, 24, 3, 3)`` (root in the world) from ``R`` ``(T, 3, 3, 3)``, ``a`` ``(T, 3, 3)``."""
        self.model.eval()
        x, C = imu_features(R.float().to(self.device), a.float().to(self.device))
        root6, local6 = self.model(x[None])
        return decode_pose(root6[0], local6[0], C).cpu()

    def estimate(self, recording: Any) -> PoseTrack:
        """Offline estimate from a recording with the kit's three IMUs (canonical form, 60 Hz)."""
        spec = InputSpec.from_kit("IMUPoser", KIT, ("orientation", "acceleration"),
                                  sensor_names=tuple(self.sensor_names), rates={"imu": self.fps})
        x = prepare(recording, spec, hold=False)  # masked samples as NaN rotations, zero acceleration
        R, a = x.channels["orientation"], torch.nan_to_num(x.channels["acceleration"])
        valid = x.valid.all(1)
        return PoseTrack(self.infer(R, a), torch.zeros(10), None, valid, self.fps,
                         extras={"frame": "world", "method": self.name})

    def reset(self) -> None:
        pass

    def step(self, frame: SensorFrame) -> PoseFrame:
        raise OfflineOnlyError("imuposer is a bidirectional LSTM (offline only): use estimate(recording)")
