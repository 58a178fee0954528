"""Noise fitted to IMUs held still: recovers a simulated model, and the x-IMU3 preset is the fit
of the real log (so the preset's figures are reproducible, not typed in)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import torch

from wearpose.errors import ShapeError
from wearpose.sensors.imu import XIMU3_FIT, ImuNoise, bias_process, fit_static_noise


def _still(noise: ImuNoise, n: int, fps: float, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    g = torch.Generator().manual_seed(seed)
    gyro = bias_process(n, (3,), fps, noise.gyro_bias, 0.0, noise.gyro_white, g).numpy()
    acc = np.array([0.0, 9.81, 0.0]) + bias_process(n, (3,), fps, 0.0, 0.0, noise.acc_white, g).numpy()
    return gyro, acc, np.broadcast_to(np.eye(3), (n, 3, 3)).copy()


def test_fit_recovers_white_noise_and_bias_of_a_known_model() -> None:
    truth = ImuNoise(gyro_white=math.radians(0.02), gyro_bias=math.radians(0.1), acc_white=2e-3)
    fit = fit_static_noise([_still(truth, 4000, 50.0, s) for s in range(20)], 50.0)
    assert fit["gyro_white"] == pytest.approx(truth.gyro_white, rel=0.03)
    assert fit["acc_white"] == pytest.approx(truth.acc_white, rel=0.03)
    assert fit["gyro_bias"] == pytest.approx(truth.gyro_bias, rel=0.35)  # 60 draws of the bias
    assert fit["orientation_white"] == 0.0 and fit["samples"] == 4000
    with pytest.raises(ShapeError, match="at least 3 still samples"):
        fit_static_noise([], 50.0)


def test_the_ximu3_preset_is_the_fit_of_the_real_log(real_sensors: Path) -> None:
    from wearpose.calibration import fit_imu_noise
    from wearpose.recording import from_ximu3
    from wearpose.sensors.simulate import _noise_config

    rec = from_ximu3(real_sensors / "ximu3-lower-body")
    fit = fit_imu_noise(rec, (0.0, 1.0), ["left_foot", "right_foot"])  # the feet stand still on the floor
    assert fit["samples"] >= 45
    for k, v in XIMU3_FIT.items():
        assert fit[k] == pytest.approx(v, rel=0.01), k
    preset = _noise_config("ximu3")
    assert preset.imu == ImuNoise.ximu3() and preset.mimu.imu == ImuNoise.ximu3() and preset.em is not None
    assert preset.imu.gyro_white == pytest.approx(fit["gyro_white"], rel=0.01)
