"""A tiny EM recording and a fast, checkable estimator for the server tests."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
import torch

from wearpose.estimators.base import Estimator, PoseFrame, SensorFrame
from wearpose.geometry import axis_angle_to_matrix
from wearpose.recording import Recording, SensorInfo

NAMES = ("a", "b", "c", "d")


class EchoEstimator(Estimator):
    """Root rotation = sensor ``a``'s orientation, root translation = the mean of the *valid*
    positions; ``valid`` only when every sensor is. Records what it saw, so a test can check
    masking and order (frames are estimated in sequence order, masked samples arrive as NaN)."""

    name = "echo"
    sensor_names = ("a", "b", "c")  # a subset: the server must pick these by name
    kit_name = "test"
    body_asset_id = "none"
    fps = 60.0

    def __init__(self, delay_s: float = 0.0) -> None:
        self.seen: list[tuple[float, np.ndarray, bool]] = []
        self.delay_s = delay_s
        self.steps = 0  # every step since construction (reset does not clear it)

    def fit(self, *a: Any, **k: Any) -> Any: ...
    def save(self, path: Any) -> Any: ...

    @classmethod
    def load(cls, path: Any, **k: Any) -> EchoEstimator:
        return cls()

    def estimate(self, recording: Any) -> Any: ...

    def reset(self) -> None:
        self.seen.clear()

    def step(self, frame: SensorFrame) -> PoseFrame:
        self.steps += 1
        if self.delay_s:
            import time

            time.sleep(self.delay_s)
        idx = [frame.names.index(n) for n in self.sensor_names]
        v = np.asarray(frame.valid)[idx]
        pos = frame.channels["position"][idx]
        # masked samples must arrive as NaN, never as made-up numbers
        assert np.isnan(pos[~v]).all()
        self.seen.append((frame.timestamp, v.copy(), bool(v.all())))
        rot = torch.eye(3).repeat(24, 1, 1)
        if v[0]:
            rot[0] = torch.as_tensor(frame.channels["orientation"][idx[0]])
        trans = torch.as_tensor(np.nanmean(pos[v], 0) if v.any() else np.zeros(3), dtype=torch.float32)
        return PoseFrame(rot, torch.zeros(10), trans, bool(v.all()), frame.timestamp,
                         extras={"frame": "test", "interference": [0.0, 0.5, 1.0]})


def tiny_recording(T: int = 120, rate: float = 60.0, seed: int = 0) -> Recording:
    """4 EM sensors moving smoothly, sensor ``d`` dropped on frames 10-14."""
    g = torch.Generator().manual_seed(seed)
    t = np.arange(T) / rate
    S = len(NAMES)
    pos = np.stack([np.stack([np.sin(t + j), np.cos(t + j), 0.1 * t], 1) for j in range(S)], 1).astype(np.float32)
    aa = torch.randn(S, 3, generator=g) * 0.3
    rot = axis_angle_to_matrix(aa[None] * torch.as_tensor(t, dtype=torch.float32)[:, None, None]).numpy()
    valid = np.ones((T, S), bool)
    valid[10:15, 3] = False
    pos[~valid] = np.nan
    rot[~valid] = np.nan
    infos = [SensorInfo(n, "em6dof", rate=rate) for n in NAMES]
    return Recording.from_stacked(infos, t, {"position": pos, "orientation": rot}, valid)


@pytest.fixture
def recording() -> Recording:
    return tiny_recording()


#: SessionID of the test liblsl configuration: an outlet reports it, which proves the file was read.
LSL_TEST_SESSION = "wearpose-tests"


@pytest.fixture(scope="session", autouse=True)
def lsl_loopback(tmp_path_factory: pytest.TempPathFactory) -> str:
    """Every stream test's LSL traffic stays on this machine: ``LSLAPICFG`` points at a generated
    liblsl configuration (``ResolveScope = machine``, ``KnownPeers = {127.0.0.1}``, IPv6 off),
    set before any test touches pylsl (liblsl reads it at its first call)."""
    import os

    from wearpose.stream.inputs.lsl import LOOPBACK_CONFIG

    p = tmp_path_factory.mktemp("lsl") / "lsl_api.cfg"
    p.write_text(LOOPBACK_CONFIG + f"SessionID = {LSL_TEST_SESSION}\n")
    os.environ["LSLAPICFG"] = str(p)
    return str(p)
