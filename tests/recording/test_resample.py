"""Integer-factor decimation of a recording; the validity mask is carried per kept sample."""

from __future__ import annotations

import numpy as np
import pytest

from wearpose.recording import Recording, RecordingError, SensorInfo, SensorStream, decimate, decimation_factor


def _rec(rate: float = 120.0, n: int = 24) -> Recording:
    t = np.arange(n) / rate
    valid = np.ones(n, bool)
    valid[[4, 5, 9]] = False  # 4 is kept at factor 4, 5 and 9 are skipped
    pos = np.stack([t, np.zeros(n), np.zeros(n)], 1).astype(np.float32)
    pos[~valid] = np.nan
    ori = np.tile(np.eye(3, dtype=np.float32), (n, 1, 1))
    ori[~valid] = np.nan
    em = SensorStream(SensorInfo("a", "em6dof", rate=rate), t, valid, position=pos, orientation=ori)
    return Recording([em], meta={"x": 1})


def test_decimate_keeps_every_kth_sample_and_its_mask() -> None:
    rec = _rec()
    out = decimate(rec, 30.0)
    s, src = out.sensor("a"), rec.sensor("a")
    assert s.info.rate == 30.0 and s.num_frames == 6
    np.testing.assert_array_equal(s.timestamps, src.timestamps[::4])
    np.testing.assert_array_equal(s.valid, [True, False, True, True, True, True])  # sample 4 dropped; 5, 9 skipped
    assert np.isnan(s.position[1]).all()  # a dropped frame stays dropped, never filled from a neighbour
    np.testing.assert_array_equal(s.position[s.valid], src.position[::4][s.valid])
    assert out.meta["resampled"] == {"a": {"from_hz": 120.0, "factor": 4}} and out.meta["x"] == 1
    assert rec.sensor("a").num_frames == 24  # the input is untouched
    assert decimate(rec, 120.0).sensor("a").num_frames == 24 and "resampled" not in decimate(rec, 120.0).meta


def test_non_integer_and_upsampling_are_refused() -> None:
    assert decimation_factor(120.0, 30.0) == 4 and decimation_factor(59.94, 29.97) == 2
    with pytest.raises(RecordingError, match=r"a factor of 1\.5, not an integer.*never interpolates"):
        decimate(_rec(45.0), 30.0)
    with pytest.raises(RecordingError, match="upsampling"):
        decimate(_rec(30.0), 60.0)
    with pytest.raises(RecordingError, match="sensor 'a'"):
        decimate(_rec(100.0), 30.0)


def test_a_decimated_recording_saves_and_loads(tmp_path) -> None:
    from wearpose.recording import load_recording

    out = decimate(_rec(), 30.0)
    back = load_recording(out.save(tmp_path / "r.npz"))
    assert back.sensor("a").info.rate == 30.0 and back.meta["resampled"]["a"]["factor"] == 4
