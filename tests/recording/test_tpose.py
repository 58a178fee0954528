"""A calibration T-pose before a simulated motion, marked in the recording's meta."""

from __future__ import annotations

import pytest
import torch

from tests.sensors.sensor_testutils import smooth_motion
from wearpose.body import BodyModel
from wearpose.calibration import calibration_pose
from wearpose.errors import ConfigError, ShapeError
from wearpose.recording import CALIBRATION_WINDOW_KEY, calibration_window, prepend_tpose


class _Rec:
    def __init__(self, meta):
        self.meta = meta


def test_prepend_tpose_holds_the_tpose_inside_the_marked_window() -> None:
    m = smooth_motion(T=40, fps=60.0, seed=1, dtype=torch.float32)
    full, w = prepend_tpose(m, 0.5, blend_s=0.25)
    hold, blend = 30, 15
    assert full.num_frames == m.num_frames + hold + blend and w["prefix_s"] == pytest.approx((hold + blend) / 60)
    assert (w["pose"], w["start_s"], w["stop_s"]) == ("tpose", 0.1, pytest.approx((hold - 1) / 60))
    a, b = int(round(w["start_s"] * 60)), int(round(w["stop_s"] * 60))
    body = full.pose[a:b + 1, 1:]  # every held frame is SMPL's T-pose (the root keeps the clip's heading)
    assert torch.allclose(body, calibration_pose("tpose")[1:].to(body.dtype).expand_as(body), atol=1e-5)
    assert torch.allclose(full.pose[hold + blend:], m.pose)  # then the clip, unchanged
    assert torch.allclose(full.trans[:hold, [0, 2]], m.trans[:1, [0, 2]].expand(hold, 2))
    # it stands on the clip's floor (the median lowest point of its first second), as a wearer
    # does, instead of at the clip's first root height; the blend eases from there into the clip
    body = BodyModel()
    floor = body.lowest_height(m.pose[:60], m.betas, m.trans[:60]).median()
    held = body.lowest_height(full.pose[:hold], full.betas, full.trans[:hold])
    assert float((held - floor).abs().max()) < 1e-5
    steps = full.trans[1:hold + blend + 1, 1] - full.trans[:hold + blend, 1]
    lift = float(full.trans[0, 1] - m.trans[0, 1])
    assert float(steps.abs().max()) <= abs(lift) / blend * 1.6 + 1e-6  # no jump: smoothstep's top slope is 1.5x


def test_prepend_tpose_refuses_a_hold_too_short() -> None:
    m = smooth_motion(T=10, fps=30.0, seed=1, dtype=torch.float32)
    with pytest.raises(ConfigError, match="at least 2 frames"):
        prepend_tpose(m, 0.04)
    with pytest.raises(ConfigError, match="> 0 s"):
        prepend_tpose(m, 0.0)


def test_calibration_window_reads_the_mark_and_refuses_a_malformed_one() -> None:
    assert calibration_window(_Rec({})) is None
    assert calibration_window(_Rec({CALIBRATION_WINDOW_KEY: {"pose": "tpose", "start_s": 0.1, "stop_s": 0.9}})) == (0.1, 0.9)
    for bad in ({"start_s": 1.0, "stop_s": 0.5}, {"pose": "ipose", "start_s": 0, "stop_s": 1}, {"start": 0}, [0, 1]):
        with pytest.raises(ShapeError, match="calibration_window"):
            calibration_window(_Rec({CALIBRATION_WINDOW_KEY: bad}))
