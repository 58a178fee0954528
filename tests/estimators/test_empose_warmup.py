"""EM-POSE behind the stream server's warm-up (issue 25: the first second of an em12 stream).

The server warms a fresh estimator up on synthetic frames in its loader thread, resets it, then
steps real frames in the subject's own thread. These tests pin that the one-off costs are all
paid in the warm-up: the first real frames (another thread, a dropped sensor, the packet layout)
neither rebuild the TorchScript trace nor make TorchScript's profiling executor optimise again.
They count events (trace identity, the executor's own log), never wall time.
"""

from __future__ import annotations

import threading
from typing import Any

import numpy as np
import pytest
import torch

from wearpose.body import BodyModel
from wearpose.estimators.base import SensorFrame
from wearpose.estimators.empose import EmposeConfig, EmposeEstimator
from wearpose.geometry import axis_angle_to_matrix
from wearpose.stream.packets import Hello, frame_channels
from wearpose.stream.server import _warm_up

#: The profiling executor's log (C++ JIT_LOG, to stderr): one "Optimized Graph" dump per plan it builds.
JIT_LOG = ">>profiling_graph_executor_impl"
OPTIMISED = "Optimized Graph"


def _real_frames(names: list[str], n: int, seed: int = 0) -> list[SensorFrame]:
    """``n`` frames as the server builds them from binary packets: ``(S, 12)`` float32 rows
    (position m, then the row-major orientation), sensor 3 dropped (NaN) from frame 1 on."""
    g = torch.Generator().manual_seed(seed)
    S = len(names)
    frames = []
    for k in range(n):
        R = axis_angle_to_matrix(torch.randn(S, 3, generator=g)).numpy().reshape(S, 9)
        data = np.concatenate([0.3 * torch.randn(S, 3, generator=g).numpy(), R], axis=1).astype(np.float32)
        valid = np.ones(S, bool)
        if k >= 1:
            valid[3] = False
            data[3] = np.nan
        frames.append(SensorFrame(k / 120.0, names, valid, frame_channels(data, valid, ("position", "orientation"))))
    return frames


def _in_thread(fn: Any) -> None:
    """Run ``fn`` in a new thread, as the server runs a subject's steps (errors re-raised here)."""
    err: list[BaseException] = []

    def run() -> None:
        try:
            fn()
        except BaseException as exc:  # noqa: BLE001 - handed to the test thread
            err.append(exc)

    th = threading.Thread(target=run)
    th.start()
    th.join()
    if err:
        raise err[0]


@pytest.fixture()
def jit_log() -> Any:
    """The profiling executor's log switched on for the test (and back off after)."""
    old = torch._C._jit_get_logging_option()
    torch._C._jit_set_logging_option(JIT_LOG)
    yield
    torch._C._jit_set_logging_option(old)


def test_server_warm_up_pays_every_one_off_before_real_frames(body: BodyModel, capfd: Any, jit_log: Any) -> None:
    est = EmposeEstimator(EmposeConfig.preset("tiny", 12), body=body)
    names = list(est.sensor_names)
    hello = Hello(0, names, ("position", "orientation"), 120.0, "binary", {})
    with pytest.warns(UserWarning, match="no subject offsets"):
        _in_thread(lambda: _warm_up(est, hello, 3))  # the server's loader thread
    warm_log = capfd.readouterr().err
    assert est._traced is not None, "the warm-up did not build the traced step"
    assert warm_log.count(OPTIMISED) >= 1, ("the warm-up did not reach the executor's optimised plan (too few steps), or its log is not "
                                         "captured (then the check below would be vacuous)")
    trace = est._traced[1]

    est.reset()  # as the server does before ready
    frames = _real_frames(names, 6)
    poses: list[Any] = []
    _in_thread(lambda: poses.extend(est.step(f) for f in frames))  # the subject's thread
    real_log = capfd.readouterr().err
    assert len(poses) == 6 and [p.valid for p in poses] == [True] + [False] * 5
    assert est._traced[1] is trace, "reset() or the real frames rebuilt the trace"
    assert real_log.count(OPTIMISED) == 0, "the profiling executor optimised again on real frames"
