"""The replay report's split of the first frames' time by stage (``_stages``)."""

from __future__ import annotations

import pytest

from wearpose.stream.replay import _stages


def test_first_frames_are_split_by_stage_and_name_the_slowest() -> None:
    seqs = [0, 2, 4, 239, 240, 500]  # 120 Hz: the first two seconds are seq < 240
    e2e = [10.0, 80.0, 6.0, 5.0, 200.0, 5.0]
    srv = [8.0, 75.0, 5.0, 4.0, 190.0, 4.0]
    comp = [7.0, 5.0, 4.0, 3.0, 180.0, 3.0]
    st = _stages(seqs, e2e, srv, comp, limit=240.0)
    assert st["frames"] == 4  # seq 240 and 500 are after the first two seconds
    assert st["latency_ms"]["max"] == 80.0 and st["latency_ms"]["n"] == 4
    assert st["slowest"] == {"seq": 2, "latency_ms": 80.0, "compute_ms": 5.0, "queue_ms": 70.0, "transport_ms": 5.0}
    assert st["queue_ms"]["max"] == pytest.approx(70.0)
    assert st["compute_ms"]["median"] == pytest.approx(4.5)


def test_no_frame_in_the_window_says_so() -> None:
    assert _stages([300, 301], [1.0, 1.0], [1.0, 1.0], [1.0, 1.0], limit=240.0) == {"frames": 0}
