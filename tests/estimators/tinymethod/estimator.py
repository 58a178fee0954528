"""The tiny test method's config and estimator (see the package doc)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import torch
from torch import nn

from wearpose.body import BodyModel
from wearpose.errors import ConfigError
from wearpose.estimators.base import Estimator, PoseFrame, PoseTrack, SensorFrame
from wearpose.estimators.checkpoint import NetworkCheckpointing
from wearpose.estimators.inputs import InputSpec, OnlineInput, prepare
from wearpose.estimators.registry import register_estimator
from wearpose.estimators.trainconfig import TrainConfig
from wearpose.geometry import rot6d_to_matrix
from wearpose.sensors import get_kit
from wearpose.estimators.seeding import init_seed, seeded


@dataclass(frozen=True, kw_only=True)
class TinyConfig(TrainConfig):
    """The shared training fields (:class:`~wearpose.estimators.trainconfig.TrainConfig`, three
    defaults restated), the kit and rate, the network width, the epochs, and ``max_frames`` per
    clip (so a test trains in seconds)."""

    kit: str = "imu6"
    rate: float = 60.0
    hidden: int = 32
    epochs: int = 2
    max_frames: int = 120
    val_clips: int = 1
    lr: float = 3e-3
    batch_size: int = 64

    @classmethod
    def preset(cls, name: str) -> TinyConfig:
        if name != "tiny":
            raise ConfigError(f"TinyConfig: unknown preset {name!r}; expected tiny")
        return cls()


class TinyNet(nn.Module):
    """``(N, S*9)`` flattened sensor orientations -> ``(N, 24, 6)`` local rotations in 6D."""

    def __init__(self, inputs: int, hidden: int) -> None:
        super().__init__()
        self.net = nn.Sequential(nn.Linear(inputs, hidden), nn.ReLU(), nn.Linear(hidden, 24 * 6))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.net(x).reshape(-1, 24, 6)


@register_estimator("tiny")
class TinyEstimator(NetworkCheckpointing, Estimator):
    """Per frame: the kit's six IMU orientations ``R_WS`` -> 24 local joint rotations. Masked
    samples are held at the sensor's last valid one (``inputs.prepare``, online
    ``inputs.OnlineInput``); a frame is valid
    when every sensor is. Poses are in the IMU world (``extras["frame"] == "world"``), no
    translation."""

    name = "tiny"

    def __init__(self, config: TinyConfig | None = None, body: BodyModel | None = None) -> None:
        self.config = config or TinyConfig()
        self.body = body or BodyModel()
        self.kit_name = self.config.kit
        self.sensor_names = tuple(get_kit(self.kit_name).sensor_names)
        self.body_asset_id = self.body.asset_id
        self.fps = float(self.config.rate)
        self.spec = InputSpec.from_kit("tiny", self.kit_name, ("orientation",), rates={"imu": self.fps})
        with seeded(init_seed(self.config.seed)):  # initial weights: a function of the seed
            self.model = TinyNet(9 * len(self.sensor_names), self.config.hidden)
        self.data_fingerprint, self.train_command, self.meta = "", "", {}
        self.reset()

    def fit(self, *args: Any, **kwargs: Any) -> Any:
        raise ConfigError("train the tiny method with `wearpose train tiny`")

    @classmethod
    def from_checkpoint(cls, ckpt: Any, *, kit: str | None = None, body: Any = None,
                        device: str | torch.device = "cpu", path: str | Path = "<checkpoint>") -> TinyEstimator:
        body = cls.check_checkpoint(ckpt, kit=kit, body=body, path=path)
        return cls(TinyConfig.from_dict(ckpt.config), body=body).restore(ckpt)

    @torch.no_grad()
    def rotations(self, orientation: torch.Tensor) -> torch.Tensor:
        """``(T, S, 3, 3)`` sensor orientations -> ``(T, 24, 3, 3)`` local joint rotations."""
        self.model.eval()
        return rot6d_to_matrix(self.model(orientation.reshape(orientation.shape[0], -1)))

    def estimate(self, recording: Any) -> PoseTrack:
        x = prepare(recording, self.spec)
        rot = self.rotations(x.channels["orientation"])
        return PoseTrack(rot, torch.zeros(10), None, x.valid.all(1), self.fps,
                         extras={"frame": "world", "method": self.name})

    def reset(self) -> None:
        self._input = OnlineInput(self.sensor_names, ("orientation",), who="tiny")

    def step(self, frame: SensorFrame) -> PoseFrame:
        (R,), valid = self._input(frame)
        return PoseFrame(self.rotations(R[None])[0], torch.zeros(10), None, bool(valid.all()),
                         frame.timestamp, extras={"frame": "world"})
