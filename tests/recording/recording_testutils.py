"""Small synthetic recordings for the recording tests (imported by the test modules)."""

from __future__ import annotations

import numpy as np
import torch

from wearpose.geometry import axis_angle_to_matrix
from wearpose.recording import Recording, SensorInfo, SensorStream
from wearpose.recording.types import known_sites


def _site(name: str) -> str | None:
    """The sensor's name as its body site when it is one ("left_forearm"), else no site."""
    return name if name in known_sites() else None


def rotations(n: int, seed: int = 0, speed: float = 0.05) -> np.ndarray:
    """``(n, 3, 3)`` smoothly varying rotations (float64)."""
    rng = np.random.default_rng(seed)
    aa = np.cumsum(rng.normal(scale=speed, size=(n, 3)), axis=0)
    return axis_angle_to_matrix(torch.from_numpy(aa)).numpy()


def imu_stream(name: str = "left_forearm", n: int = 120, rate: float = 60.0, seed: int = 0, t0: float = 0.0,
               drop: tuple[int, ...] = (), **info_kw) -> SensorStream:
    rng = np.random.default_rng(seed)
    ts = t0 + np.arange(n) / rate
    valid = np.ones(n, bool)
    valid[list(drop)] = False
    info = SensorInfo(name=name, kind="imu", site=_site(name), rate=rate, **info_kw)
    return SensorStream(info, ts, valid, orientation=rotations(n, seed).astype(np.float32),
                        acceleration=rng.normal(scale=2.0, size=(n, 3)).astype(np.float32),
                        angular_velocity=rng.normal(size=(n, 3)).astype(np.float32))


def em_stream(name: str = "right_forearm", n: int = 120, rate: float = 60.0, seed: int = 1, t0: float = 0.0,
              drop: tuple[int, ...] = ()) -> SensorStream:
    rng = np.random.default_rng(seed)
    ts = t0 + np.arange(n) / rate
    valid = np.ones(n, bool)
    valid[list(drop)] = False
    pos = np.array([0.3, 0.5, 0.1]) + np.cumsum(rng.normal(scale=0.005, size=(n, 3)), axis=0)
    info = SensorInfo(name=name, kind="em6dof", site=_site(name), rate=rate, source="src0", source_site="lower_back")
    return SensorStream(info, ts, valid, position=pos.astype(np.float32), orientation=rotations(n, seed).astype(np.float32))


def two_sensor_recording(n: int = 120, with_gt: bool = False) -> Recording:
    gt = None
    if with_gt:
        from wearpose.motion import MotionSequence

        rng = np.random.default_rng(5)
        pose = axis_angle_to_matrix(torch.from_numpy(rng.normal(scale=0.3, size=(n // 2, 24, 3)))).float()
        gt = MotionSequence(pose, torch.zeros(10), torch.from_numpy(rng.normal(size=(n // 2, 3))).float(), 30.0,
                            {"source_format": "test"})
    return Recording([imu_stream(n=n, drop=(5, 6)), em_stream(n=n, drop=(10,))], gt, 0.5,
                     {"id": "s01", "height_m": 1.75, "sex": "f"}, {"source": "unit test", "licence": "CC0"})
