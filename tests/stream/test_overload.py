"""The estimator overload policy: a starved server sheds stale frames (counted, reported, warned)
instead of answering ever later; with ``max_lag_s=None`` every frame is estimated however late."""

from __future__ import annotations

import asyncio

from tests.stream.conftest import EchoEstimator, tiny_recording
from wearpose.stream import StreamServer, replay
from wearpose.stream.security import Limits


def _run(max_lag_s: float | None) -> dict:
    rec = tiny_recording(60)  # 1 s at 60 Hz, sent as fast as possible

    async def main():  # noqa: ANN202
        # 20 ms per step: 60 frames need 1.2 s, so the last ones wait well beyond 0.1 s
        async with StreamServer(lambda: EchoEstimator(delay_s=0.02), port=0, warmup=0,
                                limits=Limits(max_lag_s=max_lag_s)) as srv:
            return await replay(rec, srv.url, realtime=False, drain_timeout=30.0)

    return asyncio.run(asyncio.wait_for(main(), 60))


def test_a_starved_server_sheds_stale_frames_counts_them_and_the_replay_warns() -> None:
    r = _run(0.1)
    shed = r["server_stats"]["shed"]
    assert shed > 0 and r["frames_shed_by_server"] == shed
    assert r["poses_received"] == 60 - shed and r["frames_lost"] == shed  # a shed frame has no pose
    assert r["server_stats"]["estimated"] == 60 - shed
    assert any("shed" in w and "overload policy" in w for w in r["warnings"]), r["warnings"]


def test_without_a_max_lag_every_frame_is_estimated() -> None:
    r = _run(None)
    assert r["server_stats"]["shed"] == 0 and r["frames_lost"] == 0 and r["poses_received"] == 60
    assert not any("shed" in w for w in r["warnings"])
