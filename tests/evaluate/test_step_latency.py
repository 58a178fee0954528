"""wearpose.evaluate.latency.step_latency / cost_settings on a tiny stand-in estimator."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest

from wearpose.errors import ConfigError
from wearpose.estimators.base import OfflineOnlyError

from wearpose.evaluate.latency import apply_settings, cost_settings, step_latency
from wearpose.estimators.run import ModelSource
from wearpose.recording import Recording, SensorInfo, SensorStream


@dataclass
class _Cfg:
    iterations: int = 3
    hidden: int = 8
    lr: float = 1e-3  # not a cost setting


class _Counting:
    """Steps counted; ``fps`` 60; the window and config like a real estimator's."""

    name, fps, sensor_names, has_weights = "counting", 60.0, ("a",), False

    def __init__(self) -> None:
        self.config, self.window, self.steps, self.resets = _Cfg(), (4, 2), 0, 0

    def reset(self) -> None:
        self.resets += 1

    def set_window(self, past: int, future: int) -> None:
        self.window = (past, future)

    def step(self, frame):
        self.steps += 1
        return _Pose({"stage_ms": 2.0, "label": "x"})


@dataclass
class _Pose:
    extras: dict


def _rec(n: int) -> Recording:
    info = SensorInfo(name="a", kind="imu", site="pelvis", rate=60.0)
    eye = np.broadcast_to(np.eye(3, dtype=np.float32), (n, 3, 3)).copy()
    s = SensorStream(info, np.arange(n) / 60.0, np.ones(n, bool), orientation=eye,
                     acceleration=np.zeros((n, 3), np.float32))
    return Recording([s])


def test_cost_settings_take_attributes_then_config_and_skip_the_rest() -> None:
    assert cost_settings(_Counting()) == {"iterations": 3, "window": [4, 2], "hidden": 8}


def test_step_latency_times_frames_after_the_warmup(monkeypatch) -> None:
    est = _Counting()
    src = ModelSource(name="counting", method="counting")
    monkeypatch.setattr(ModelSource, "make", lambda self: est)
    res = step_latency(src, _rec(20), frames=5, warmup=3)
    assert est.steps == 8 and est.resets == 1
    assert res["frames"] == 5 and res["online_ms"]["calls"] == 5 and res["warmup"] == 3
    assert res["rate_hz"] == 60.0 and abs(res["frame_period_ms"] - 1000 / 60) < 1e-9
    assert res["settings"]["iterations"] == 3 and res["note"] is None
    # the estimator's own stage timings (ms in extras), the same statistics; other extras ignored
    assert res["stages_ms"] == {"stage_ms": {"median_ms": 2.0, "p99_ms": 2.0, "max_ms": 2.0, "calls": 5}}


def test_a_short_recording_says_how_many_steps_it_gave(monkeypatch) -> None:
    est = _Counting()
    monkeypatch.setattr(ModelSource, "make", lambda self: est)
    res = step_latency(ModelSource(name="c", method="c"), _rec(6), frames=50, warmup=2)
    assert res["frames"] == 4 and est.steps == 6


def test_an_offline_only_estimator_is_refused_naming_the_model(monkeypatch) -> None:
    class _Offline(_Counting):
        def step(self, frame) -> None:
            raise OfflineOnlyError("bidirectional: use estimate(recording)")

    monkeypatch.setattr(ModelSource, "make", lambda self: _Offline())
    with pytest.raises(ConfigError, match="bi has no online step: bidirectional"):
        step_latency(ModelSource(name="bi", method="c"), _rec(6), frames=2, warmup=0)


def test_settings_go_through_the_setter_or_the_attribute_and_unknown_ones_are_refused() -> None:
    est = _Counting()
    est.mc_samples = 10
    apply_settings(est, {"window": "8,3", "mc_samples": "0"})
    assert est.window == (8, 3) and est.mc_samples == 0
    with pytest.raises(ConfigError, match="no setting 'lr'.*it has: mc_samples, window"):
        apply_settings(est, {"lr": "0.1"})
    with pytest.raises(ConfigError, match="no setting 'iterations'"):  # in the config only: not changeable here
        apply_settings(est, {"iterations": "4"})
