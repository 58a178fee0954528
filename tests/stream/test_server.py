"""The server on loopback: two subjects with faults, late frames, refusals, stats, shutdown."""

from __future__ import annotations

import asyncio
import json
import urllib.request

import numpy as np
import pytest

from tests.stream.conftest import EchoEstimator, tiny_recording
from wearpose.stream import FramePacket, Faults, Hello, StreamClient, StreamError, StreamServer, replay, stack_recording
from wearpose.stream.security import Limits

#: The overload policy (frames that waited > 0.5 s shed) off, for tests that count every frame:
#: on a loaded 2-core test machine the estimator may fall that far behind, and these tests are
#: about transport, reordering and refusals, not overload (tests/stream/test_overload.py is).
NO_SHEDDING = Limits(max_lag_s=None)


def _run(coro):  # noqa: ANN001, ANN202
    return asyncio.run(asyncio.wait_for(coro, 60))


class _Factory:
    def __init__(self, delay_s: float = 0.0) -> None:
        self.made: list[EchoEstimator] = []
        self.delay_s = delay_s

    def __call__(self) -> EchoEstimator:
        self.made.append(EchoEstimator(self.delay_s))
        return self.made[-1]


def test_two_subjects_with_faults_lose_nothing_and_mask_dropouts() -> None:
    fac = _Factory()
    rec0, rec1 = tiny_recording(150, seed=0), tiny_recording(150, seed=1)

    async def main():  # noqa: ANN202
        async with StreamServer(fac, port=0, reorder_window=4, limits=NO_SHEDDING) as srv:
            faults = Faults(malformed=0.05, dropout=0.02, reorder=0.05, seed=3)
            watcher = StreamClient(srv.url)
            await watcher.connect()
            await watcher.subscribe([1])
            r = await asyncio.gather(
                replay(rec0, srv.url, subject=0, fmt="binary", realtime=True, speed=8.0, faults=faults),
                replay(rec1, srv.url, subject=1, fmt="json", realtime=True, speed=8.0,
                       faults=Faults(malformed=0.05, dropout=0.02, reorder=0.05, seed=4)))
            stats = srv.stats()
            await asyncio.sleep(0.05)
            await watcher.close()
            return r, stats, watcher

    (r0, r1), stats, watcher = _run(main())
    for r, rec in ((r0, rec0), (r1, rec1)):
        assert r["frames_sent"] == 150 and r["frames_lost"] == 0 and r["poses_received"] == 150
        s = r["server_stats"]
        assert s["estimated"] == 150 and s["lost"] == 0 and s["late"] == 0
        assert r["injected"]["reordered"] > 0 and r["injected"]["malformed"] > 0
        # every masked sample reached the estimator as masked: injected plus the recording's own
        assert s["masked_sensor_samples"] == r["injected"]["dropped_sensor_samples"] + int((~rec.on_common_grid().valid).sum())
    # malformed messages counted (each is skipped; the streams kept running)
    assert stats["malformed_total"] == r0["injected"]["malformed"] + r1["injected"]["malformed"]
    # one estimator per subject, each saw its frames in order, with the masks as sent
    assert len(fac.made) == 2
    for est in fac.made:
        ts = [t for t, _, _ in est.seen]
        assert ts == sorted(ts) and len(ts) == 150
        assert any(not ok for _, _, ok in est.seen)
    # the subscriber got subject 1's poses only
    got = []
    while not watcher.poses.empty():
        got.append(watcher.poses.get_nowait()[1])
    assert {p.subject for p in got} == {1} and len(got) == 150
    assert got[0].extras["interference"] == [0.0, 0.5, 1.0] and len(got[0].extras["sensor_valid"]) == 3


def test_pose_content_follows_the_input() -> None:
    rec = tiny_recording(30)
    st = stack_recording(rec)

    async def main():  # noqa: ANN202
        async with StreamServer(_Factory(), port=0) as srv, StreamClient(srv.url) as c:
            await c.hello(Hello(5, st.names, st.channels, st.rate, "binary"))
            for k in range(30):
                await c.send_frame(FramePacket(5, k, float(st.timestamps[k]), st.valid[k], st.data[k]))
            await c.bye(5)
            return [c.poses.get_nowait()[1] for _ in range(c.poses.qsize())]

    poses = _run(main())
    assert [p.seq for p in poses] == list(range(30))
    for p in poses:
        k = p.seq
        np.testing.assert_allclose(p.local_rot[0], st.data[k, 0, 3:].reshape(3, 3), atol=1e-6)
        np.testing.assert_allclose(p.trans, st.data[k, :3, :3].mean(0), atol=1e-5)


def test_late_frames_are_dropped_not_invented() -> None:
    rec = tiny_recording(20)
    st = stack_recording(rec)

    async def main():  # noqa: ANN202
        async with StreamServer(_Factory(), port=0, reorder_window=3) as srv, StreamClient(srv.url) as c:
            await c.hello(Hello(0, st.names, st.channels, st.rate, "json"))
            order = [0, 1, 2, 4, 5, 6, 3, 7, 9, 8] + list(range(10, 20)) + [15]  # 3 is too late, 9/8 swap, 15 twice
            for k in order:
                await c.send_frame(FramePacket(0, k, float(st.timestamps[k]), st.valid[k], st.data[k]))
            final = await c.bye(0)
            return final, sorted(c.poses.get_nowait()[1].seq for _ in range(c.poses.qsize()))

    final, seqs = _run(main())
    assert seqs == [k for k in range(20) if k != 3]
    assert (final["lost"], final["late"], final["estimated"], final["received"]) == (1, 2, 19, 21)


def test_refusal_stats_endpoint_and_clean_shutdown() -> None:
    rec = tiny_recording(40)
    st = stack_recording(rec)
    fac = _Factory(delay_s=0.01)

    async def main():  # noqa: ANN202
        srv = await StreamServer(fac, port=0, limits=NO_SHEDDING).start()
        c = await StreamClient(srv.url).connect()
        with pytest.raises(StreamError, match="lacks"):
            await c.hello(Hello(1, ("a", "b"), st.channels, st.rate))  # the estimator needs a, b, c
        await c.hello(Hello(0, st.names, st.channels, st.rate, "binary"))
        for k in range(40):
            await c.send_frame(FramePacket(0, k, float(st.timestamps[k]), st.valid[k], st.data[k]))
        await c.send_raw(b"\x00garbage")
        stats = await c.stats()
        http_stats = await asyncio.to_thread(
            lambda: json.loads(urllib.request.urlopen(f"http://127.0.0.1:{srv.port}/stats", timeout=5).read()))
        await srv.stop()  # with frames still queued (10 ms each): they are estimated, then connections close
        await asyncio.wait_for(c._reader, 5)
        return stats, http_stats, c.poses.qsize(), srv.stats()

    stats, http_stats, n_poses, final = _run(main())
    assert stats["type"] == "stats" and "0" in stats["subjects"]
    assert http_stats["malformed_total"] == 1 and http_stats["refused_total"] == 1
    assert n_poses == 40 and final["finished"]["0"]["estimated"] == 40


def test_null_estimator_passes_any_stream_through() -> None:
    from wearpose.stream import estimator_factory

    rec = tiny_recording(30)

    async def main():  # noqa: ANN202
        async with StreamServer(estimator_factory("null"), port=0, stride="auto") as srv:
            return await replay(rec, srv.url, realtime=False)

    r = _run(main())
    assert r["frames_lost"] == 0 and r["poses_received"] == 30 and r["ready"]["stride"] == 1
    assert r["invalid_pose_frames"] == 5  # frames 10-14 have a dropped sensor


def test_estimator_factory_applies_cost_settings_to_every_estimator() -> None:
    """``wearpose serve --set online=stream``: each subject's estimator is made in BiRAE's
    streaming mode; a setting the estimator lacks fails when the factory is first called."""
    from wearpose.errors import ConfigError
    from wearpose.stream import estimator_factory

    make = estimator_factory("birae3_cpu", settings={"online": "stream", "mc_samples": "0"})
    a, b = make(), make()
    assert a is not b and a.online == b.online == "stream" and a.mc_samples == 0
    assert estimator_factory("birae3_cpu")().online == "window"
    with pytest.raises(ConfigError, match="no setting 'iterations'"):
        estimator_factory("birae3_cpu", settings={"iterations": "4"})()


def test_replay_reports_a_backlog_it_stopped_waiting_for() -> None:
    rec = tiny_recording(40)

    async def main():  # noqa: ANN202
        async with StreamServer(_Factory(delay_s=0.02), port=0) as srv:
            return await replay(rec, srv.url, realtime=False, drain_timeout=0.1)

    r = _run(main())
    assert r["gave_up_waiting"] and r["frames_lost"] > 0
    assert r["poses_received"] + r["frames_lost"] == 40 and r["frames_queued_at_server_at_end"] > 0


def test_auto_stride_counts_skipped_frames_as_decimated_not_lost() -> None:
    rec = tiny_recording(40, rate=120.0)  # the echo estimator runs at 60 Hz: stride 2

    async def main():  # noqa: ANN202
        async with StreamServer(_Factory(), port=0, stride="auto") as srv:
            return await replay(rec, srv.url, realtime=False)

    r = _run(main())
    assert r["ready"]["stride"] == 2 and "trained" not in r["ready"]["note"]
    assert r["frames_expected"] == 20 and r["poses_received"] == 20 and r["frames_lost"] == 0
    assert r["server_stats"]["decimated"] == 20 and r["server_stats"]["lost"] == 0


def test_udp_frames_and_poses() -> None:
    from wearpose.stream.packets import decode_pose, encode_frame_binary

    rec = tiny_recording(30)
    st = stack_recording(rec)

    async def main():  # noqa: ANN202
        async with StreamServer(_Factory(), port=0, udp_port=0) as srv:
            loop = asyncio.get_running_loop()
            inbox: asyncio.Queue = asyncio.Queue()

            class P(asyncio.DatagramProtocol):
                def datagram_received(self, data: bytes, addr) -> None:  # noqa: ANN001
                    inbox.put_nowait(data)

            tr, _ = await loop.create_datagram_endpoint(P, remote_addr=("127.0.0.1", srv.udp_port))
            tr.sendto(Hello(4, st.names, st.channels, st.rate, "binary").to_json().encode())
            ready = json.loads(await asyncio.wait_for(inbox.get(), 30))
            for k in [0, 2, 1] + list(range(3, 30)):  # one swapped pair
                tr.sendto(encode_frame_binary(FramePacket(4, k, float(st.timestamps[k]), st.valid[k], st.data[k])))
            tr.sendto(b"\xff\xfe not a packet")
            tr.sendto(json.dumps({"type": "bye", "subject": 4}).encode())
            msgs = []
            while True:
                data = await asyncio.wait_for(inbox.get(), 30)
                m = decode_pose(data if data[:2] == b"WP" else data.decode())  # UDP text arrives as bytes
                if isinstance(m, dict) and m.get("type") == "bye":
                    break
                msgs.append(m)
            tr.close()
            return ready, msgs, m, srv.malformed

    ready, poses, bye, malformed = _run(main())
    assert ready["type"] == "ready" and [p.seq for p in poses] == list(range(30))
    assert bye["stats"]["estimated"] == 30 and malformed == 1


def test_sequence_numbers_wrap_around_without_loss() -> None:
    rec = tiny_recording(12)
    st = stack_recording(rec)
    start = 2**32 - 6

    async def main():  # noqa: ANN202
        async with StreamServer(_Factory(), port=0) as srv, StreamClient(srv.url) as c:
            await c.hello(Hello(0, st.names, st.channels, st.rate, "binary"))
            order = [0, 1, 2, 3, 4, 6, 5, 7, 8, 9, 10, 11]  # frame 5 (seq 2**32 - 1) arrives after seq 0
            for k in order:
                await c.send_frame(FramePacket(0, (start + k) % 2**32, float(st.timestamps[k]), st.valid[k], st.data[k]))
            final = await c.bye(0)
            return final, [c.poses.get_nowait()[1] for _ in range(c.poses.qsize())]

    final, poses = _run(main())
    assert [p.seq for p in poses] == [(start + k) % 2**32 for k in range(12)]  # in order across the wrap
    assert [p.timestamp for p in poses] == [float(t) for t in st.timestamps[:12]]
    assert (final["lost"], final["late"], final["estimated"]) == (0, 0, 12)


def test_estimator_warmed_up_before_ready_and_stages_timed() -> None:
    from wearpose.stream.server import STAGES

    rec = tiny_recording(30)
    fac = _Factory(delay_s=0.002)

    async def main():  # noqa: ANN202
        async with StreamServer(fac, port=0, warmup=7) as srv:
            return await replay(rec, srv.url, realtime=False)

    r = _run(main())
    est = fac.made[0]
    # 7 synthetic steps before ready, then reset: the estimator saw exactly the 30 real frames
    assert est.steps == 7 + 30 and len(est.seen) == 30 and r["poses_received"] == 30
    st = r["server_stats"]["stages_ms"]
    assert list(st) == list(STAGES)
    assert st["compute"]["median"] >= 2.0  # the 2 ms step
    assert all(v["median"] >= 0 for v in st.values())
    assert r["server_stats"]["compute_ms"]["median"] >= 2.0 and "gc_since_ready" in r["server_stats"]


def test_estimator_errors_are_counted_and_the_stream_goes_on() -> None:
    rec = tiny_recording(20)

    class Flaky(EchoEstimator):
        def step(self, frame):  # noqa: ANN001, ANN202
            pose = super().step(frame)
            n = len(self.seen)
            if n % 5 == 0:
                raise RuntimeError("flaky step")
            if n % 7 == 0:
                pose.local_rot = "not a tensor"  # a bad pose: building its packet fails
            return pose

    async def main():  # noqa: ANN202
        async with StreamServer(Flaky, port=0, warmup=0) as srv:
            return await replay(rec, srv.url, realtime=False)

    r = _run(main())
    s = r["server_stats"]
    bad = {n for n in range(1, 21) if n % 5 == 0 or n % 7 == 0}  # steps 5, 7, 10, 14, 15, 20
    assert s["estimator_errors"] == len(bad) and s["estimated"] == 20 - len(bad)
    assert r["poses_received"] == 20 - len(bad) and r["frames_lost"] == len(bad)


def test_auto_stride_refuses_rates_that_are_not_an_integer_multiple_and_keeps_serving() -> None:
    """stride 'auto' follows recording.decimation_factor: 90 Hz (x1.5) and 30 Hz (upsampling) into the
    60 Hz echo estimator are refused at hello, counted; a 120 Hz subject on the same connection is served."""
    rec = tiny_recording(40, rate=120.0)
    st = stack_recording(rec)

    async def main():  # noqa: ANN202
        async with StreamServer(_Factory(), port=0, stride="auto", warmup=0) as srv, StreamClient(srv.url) as c:
            errors = []
            for subject, rate in ((1, 90.0), (2, 30.0)):
                with pytest.raises(StreamError) as info:
                    await c.hello(Hello(subject, st.names, st.channels, rate))
                errors.append(str(info.value))
            ready = await c.hello(Hello(0, st.names, st.channels, st.rate, "binary"))
            for k in range(40):
                await c.send_frame(FramePacket(0, k, float(st.timestamps[k]), st.valid[k], st.data[k]))
            final = await c.bye(0)
            return errors, ready, final, srv.stats(), sorted(c.poses.get_nowait()[1].seq for _ in range(c.poses.qsize()))

    errors, ready, final, stats, seqs = _run(main())
    for msg, rate, what in zip(errors, ("90", "30"), ("not an integer", "upsampling")):
        assert f"{rate} Hz" in msg and "60 Hz" in msg and what in msg and "--stride N" in msg, msg
    assert stats["refused_total"] == 2 and set(stats["subjects"]) == set()  # neither kept as a subject
    assert ready["stride"] == 2 and final["estimated"] == 20 and final["decimated"] == 20
    assert seqs == list(range(0, 40, 2))


def test_explicit_stride_serves_any_rate_with_a_note() -> None:
    rec = tiny_recording(30, rate=90.0)  # 1.5 x the echo estimator's 60 Hz: 'auto' would refuse it

    async def main():  # noqa: ANN202
        async with StreamServer(_Factory(), port=0, stride=1, warmup=0) as srv:
            return await replay(rec, srv.url, realtime=False), srv.stats()

    r, stats = _run(main())
    assert r["ready"]["stride"] == 1 and "trained at 60 Hz" in r["ready"]["note"]
    assert r["poses_received"] == 30 and stats["refused_total"] == 0


def test_empose_with_refinement_and_no_offsets_is_refused_at_hello() -> None:
    """EM-POSE's refinement fits the pose through the sensors' offsets: a hello without them is
    refused at once, naming the offsets, where a stream gives them and how to turn the refinement
    off (before, the subject was accepted and every frame failed); with them it is served."""
    from wearpose.body import BodyModel
    from wearpose.estimators.empose import EmposeConfig, EmposeEstimator

    body = BodyModel()
    make = lambda: EmposeEstimator(EmposeConfig.preset("tiny", 12).override(refine_steps=1), body=body)  # noqa: E731
    names = make().sensor_names
    S = len(names)
    offsets = {"sensors": list(names), "rotation": np.broadcast_to(np.eye(3), (S, 3, 3)).tolist(),
               "translation_mean_m": np.zeros((S, 3)).tolist()}
    rng = np.random.default_rng(0)

    async def main():  # noqa: ANN202
        async with StreamServer(make, port=0, warmup=0, limits=NO_SHEDDING) as srv, StreamClient(srv.url) as c:
            with pytest.raises(StreamError) as info:
                await c.hello(Hello(1, names, ("position", "orientation"), 30.0))
            refused = srv.stats()
            await c.hello(Hello(2, names, ("position", "orientation"), 30.0, subject_info={"offsets": offsets}))
            for k in range(3):
                data = np.concatenate([0.3 * rng.standard_normal((S, 3)), np.broadcast_to(np.eye(3), (S, 3, 3)).reshape(S, 9)],
                                      1).astype(np.float32)
                await c.send_frame(FramePacket(2, k, k / 30.0, np.ones(S, bool), data))
            return str(info.value), refused, await c.bye(2), srv.stats()

    msg, refused, final, stats = _run(main())
    assert "refine_steps=1" in msg and "offsets" in msg and "subject_info['offsets']" in msg and "refine_steps=0" in msg, msg
    assert refused["refused_total"] == 1 and "1" not in map(str, refused["subjects"])
    assert final["estimated"] == 3 and final.get("estimator_errors", 0) == 0 and stats["refused_total"] == 1


def test_empose_prior_on_the_whole_recording_is_refused_at_hello_and_on_its_first_frames_served() -> None:
    """EM-POSE's refinement with its prior on the whole recording (``refine_centre="recording"``,
    ``refine_centre_frames=0``) needs the recording a stream does not have: the hello is refused
    naming the online form; with the turn measured on the stream's first frames, or renewed on
    every frame, it is served, and the frames after them are estimated too."""
    from wearpose.body import BodyModel
    from wearpose.estimators.empose import EmposeConfig, EmposeEstimator

    body = BodyModel()
    names = EmposeEstimator(EmposeConfig.preset("tiny", 12), body=body).sensor_names
    S = len(names)
    offsets = {"sensors": list(names), "rotation": np.broadcast_to(np.eye(3), (S, 3, 3)).tolist(),
               "translation_mean_m": np.zeros((S, 3)).tolist()}
    rng = np.random.default_rng(1)

    def serve(frames: int, every: int = 0):  # noqa: ANN202
        cfg = EmposeConfig.preset("tiny", 12).override(refine_steps=1, refine_centre="recording",
                                                      refine_centre_frames=frames, refine_centre_every=every)
        make = lambda: EmposeEstimator(cfg, body=body)  # noqa: E731

        async def main():  # noqa: ANN202
            async with StreamServer(make, port=0, warmup=0, limits=NO_SHEDDING) as srv, StreamClient(srv.url) as c:
                try:
                    await c.hello(Hello(1, names, ("position", "orientation"), 30.0, subject_info={"offsets": offsets}))
                except StreamError as exc:
                    return str(exc), None, srv.stats()
                for k in range(4):
                    data = np.concatenate([0.3 * rng.standard_normal((S, 3)),
                                           np.broadcast_to(np.eye(3), (S, 3, 3)).reshape(S, 9)], 1).astype(np.float32)
                    await c.send_frame(FramePacket(1, k, k / 30.0, np.ones(S, bool), data))
                return None, await c.bye(1), srv.stats()

        return _run(main())

    msg, final, stats = serve(0)
    assert msg is not None and "refine_centre_frames" in msg and stats["refused_total"] == 1, msg
    for frames, every in ((2, 0), (1, 1)):  # the first frames' turn; the running turn
        msg, final, stats = serve(frames, every)
        assert msg is None and stats["refused_total"] == 0
        assert final["estimated"] == 4 and final.get("estimator_errors", 0) == 0
