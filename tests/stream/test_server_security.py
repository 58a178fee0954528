"""The streaming server under hostile clients, on loopback: a foreign Origin, missing tokens,
another connection's bye / frames / hello, oversize and too many messages, subscription limits,
a slow subscriber; and clients that stop at once when the server ends their subject."""

from __future__ import annotations

import asyncio
import http.client
import json
import time

import pytest

from tests.stream.conftest import EchoEstimator, tiny_recording
from wearpose.stream import FramePacket, Hello, StreamClient, StreamError, StreamServer, replay, stack_recording
from wearpose.stream.packets import encode_frame_binary
from wearpose.stream.security import Limits
from wearpose.stream.server import _Subscriber

EVIL = "http://evil.example.com"


def _run(coro):  # noqa: ANN001, ANN202
    return asyncio.run(asyncio.wait_for(coro, 30))


def _get(port: int, path: str = "/stats", **headers: str) -> tuple[int, list[str], bytes]:
    """A plain HTTP GET to the server: status, its Content-Type headers, body."""
    conn = http.client.HTTPConnection("127.0.0.1", port, timeout=5)
    conn.request("GET", path, headers=headers)
    resp = conn.getresponse()
    out = resp.status, resp.msg.get_all("Content-Type") or [], resp.read()
    conn.close()
    return out


async def _aget(port: int, path: str = "/stats", **headers: str) -> tuple[int, list[str], bytes]:
    return await asyncio.to_thread(_get, port, path, **headers)


def test_foreign_origin_cannot_connect_without_the_token_and_is_counted() -> None:
    async def main():  # noqa: ANN202
        async with StreamServer(EchoEstimator, port=0, warmup=0) as srv:
            errors = []
            for token in (None, "not-the-token-0123456789", srv.token):  # with the token: still not allowed
                with pytest.raises(StreamError) as info:
                    await StreamClient(srv.url, origin=EVIL, token=token).connect()
                errors.append(str(info.value))
            status, _, body = await _aget(srv.port, Origin=EVIL)  # /stats too
            return errors, status, body, srv.stats()

    errors, status, body, stats = _run(main())
    assert all("HTTP 403" in e and "is not allowed" in e and "--allow-origin" in e for e in errors), errors
    assert status == 403 and b"subjects" not in body
    assert stats["security"]["origin"] == 4 and stats["connections"] == 0


def test_allowed_and_same_host_origins_connect() -> None:
    rec = tiny_recording(20)

    async def main():  # noqa: ANN202
        async with StreamServer(EchoEstimator, port=0, warmup=0, allow_origins=["http://dash.example:3000"]) as srv:
            same = StreamClient(srv.url, origin=f"http://localhost:{srv.port}")  # port 0: the bound port counts
            r = await replay(rec, srv.url, realtime=False, client=await same.connect())
            await same.close()
            with pytest.raises(StreamError, match="HTTP 401.*requires its access token"):
                await StreamClient(srv.url, origin="http://dash.example:3000").connect()
            dash = await StreamClient(srv.url, origin="http://dash.example:3000", token=srv.token).connect()
            reply = await dash.subscribe()
            await dash.close()
            return r, reply, srv.stats()

    r, reply, stats = _run(main())
    assert r["poses_received"] == 20 and r["frames_lost"] == 0
    assert reply["type"] == "subscribed" and reply["policy"] == "drop-oldest"
    assert stats["security"]["token"] == 1 and stats["security"]["origin"] == 0
    assert "http://dash.example:3000" in stats["security"]["allowed_origins"]


def test_require_token_on_loopback() -> None:
    async def main():  # noqa: ANN202
        async with StreamServer(EchoEstimator, port=0, warmup=0, require_token=True, token="my-token-0123456789") as srv:
            with pytest.raises(StreamError, match="HTTP 401.*pass --token"):
                await StreamClient(srv.url).connect()
            with pytest.raises(StreamError, match="HTTP 401.*not the server's"):
                await StreamClient(srv.url, token="another-token-0123456").connect()
            no_token = await _aget(srv.port)
            with_token = await _aget(srv.port, "/stats?token=my-token-0123456789")
            async with StreamClient(srv.url, token="my-token-0123456789") as c:
                stats = await c.stats()
            return no_token[0], with_token[0], stats

    no_token, with_token, stats = _run(main())
    assert (no_token, with_token) == (401, 200)
    assert stats["security"]["token"] == 3 and stats["security"]["token_required"] is True


def test_stats_has_one_content_type_and_refuses_a_rebinding_host() -> None:
    async def main():  # noqa: ANN202
        async with StreamServer(EchoEstimator, port=0) as srv:
            ok = await _aget(srv.port)
            rebound = await _aget(srv.port, Host=f"evil.example.com:{srv.port}")
            return ok, rebound, srv.stats()

    (status, ctype, body), rebound, stats = _run(main())
    assert status == 200 and ctype == ["application/json"] and json.loads(body)["type"] == "stats"
    assert rebound[0] == 403 and stats["security"]["host"] == 1


def test_another_connections_bye_frames_and_hello_are_refused_and_the_owner_loses_nothing() -> None:
    """The issue's attack: a second connection ends subject 0 with {"type": "bye", "subject": 0},
    floods frames for it and re-opens it. Every one is refused, counted and answered; the owner
    streams on with 0 frames lost."""
    rec = tiny_recording(120)
    st = stack_recording(rec)

    async def main():  # noqa: ANN202
        async with StreamServer(EchoEstimator, port=0, warmup=0) as srv:
            owner = asyncio.create_task(replay(rec, srv.url, subject=0, realtime=True, speed=2.0))  # 1 s
            while "0" not in srv.stats()["subjects"] or not srv.subjects[0].ready.is_set():
                await asyncio.sleep(0.01)
            sent, t0 = 0, time.perf_counter()
            async with StreamClient(srv.url) as evil:
                with pytest.raises(StreamError, match="opened by another connection"):
                    await evil.bye(0)
                with pytest.raises(StreamError, match="opened by another connection"):
                    await evil.hello(Hello(0, st.names, st.channels, st.rate, "binary"))
                sent += 2
                for k in range(40):  # frames for subject 0: binary and JSON, plausible sequence numbers
                    pkt = FramePacket(0, 1000 + k, 0.0, st.valid[k], st.data[k])
                    await evil.send_raw(encode_frame_binary(pkt))
                    await evil.send_raw(json.dumps({"type": "frame", "v": 1, "subject": 0, "seq": 2000 + k, "t": 0.0,
                                                    "valid": [0] * len(st.names),
                                                    **{c: [None] * len(st.names) for c in st.channels}}))
                    sent += 2
                await asyncio.sleep(0.2)
                answers = [m for m in evil.messages if m.get("code") == "not_owner"]
                took = time.perf_counter() - t0
            return await owner, srv.stats(), sent, answers, took

    r, stats, sent, answers, took = _run(main())
    assert r["frames_sent"] == 120 and r["poses_received"] == 120 and r["frames_lost"] == 0
    s = r["server_stats"]
    assert s["estimated"] == 120 and s["received"] == 120 and s["refused_foreign"] == sent == 82
    assert stats["security"]["not_owner"] == sent and stats["malformed_total"] == 0
    # every refusal answered, but at most 10 error replies a second per connection
    assert 10 <= len(answers) <= 10 + 10 * took + 1 and stats["security"]["errors_suppressed"] == sent - len(answers)


def test_oversize_message_closes_only_its_connection() -> None:
    rec = tiny_recording(20)

    async def main():  # noqa: ANN202
        async with StreamServer(EchoEstimator, port=0, warmup=0, limits=Limits(message_bytes=4096)) as srv:
            big = await StreamClient(srv.url).connect()
            await big.send_raw(b"WP" + bytes(5000))
            await asyncio.wait_for(big._reader, 5)  # the server closed it
            code = big._ws.close_code
            r = await replay(rec, srv.url, realtime=False)  # others are unaffected
            return code, r, srv.stats()

    code, r, stats = _run(main())
    assert code == 1009 and stats["security"]["oversize"] == 1
    assert r["poses_received"] == 20 and r["frames_lost"] == 0


def test_rate_limit_drops_counts_and_tells() -> None:
    rec = tiny_recording(100)
    st = stack_recording(rec)

    async def main():  # noqa: ANN202
        limits = Limits(rate=5.0, burst=10)
        async with StreamServer(EchoEstimator, port=0, warmup=0, limits=limits) as srv, StreamClient(srv.url) as c:
            await c.hello(Hello(0, st.names, st.channels, st.rate, "binary"))
            for k in range(100):  # as fast as possible: far above 50 messages/s
                await c.send_raw(encode_frame_binary(FramePacket(0, k, float(st.timestamps[k]), st.valid[k], st.data[k])))
            await asyncio.sleep(0.4)  # the bucket refills (5 a second): bye gets through
            final = await c.bye(0)
            return final, srv.stats(), [m for m in c.messages if m.get("code") == "rate_limited"]

    final, stats, notices = _run(main())
    dropped = stats["security"]["rate_limited"]
    # 9 of the burst left after the hello, plus 5 a second while sending: ~90 dropped, each counted
    assert 70 <= dropped <= 91 and final["received"] == 100 - dropped
    assert 1 <= len(notices) <= 2 and "5 messages/s" in notices[0]["error"]  # told once a second, not per message


def test_subscription_subject_and_subscriber_limits() -> None:
    rec = tiny_recording(20)
    st = stack_recording(rec)

    async def main():  # noqa: ANN202
        limits = Limits(subscriptions=3, subscribers=1, subjects=1)
        async with StreamServer(EchoEstimator, port=0, warmup=0, limits=limits) as srv:
            a, b = await StreamClient(srv.url).connect(), await StreamClient(srv.url).connect()
            with pytest.raises(StreamError, match="4 subject ids, at most 3"):
                await a.subscribe([1, 2, 3, 4])
            ok = await a.subscribe([1, 2, 3])
            again = await a.subscribe(None)  # a subscriber may change its subscription
            with pytest.raises(StreamError, match="already has 1 subscribers"):
                await b.subscribe([1])
            await b.hello(Hello(5, st.names, st.channels, st.rate))
            with pytest.raises(StreamError, match="already has 1 subjects open"):
                await b.hello(Hello(6, st.names, st.channels, st.rate))
            await a.close()
            await b.close()
            return ok, again, srv.stats()

    ok, again, stats = _run(main())
    assert ok["subjects"] == [1, 2, 3] and again["subjects"] is None
    sec = stats["security"]
    assert (sec["subscription_limit"], sec["subscriber_limit"], sec["subject_limit"]) == (1, 1, 1)


def test_slow_subscriber_loses_its_oldest_poses_and_is_told() -> None:
    class BlockedSocket:
        def __init__(self) -> None:
            self.sent: list = []
            self.gate = asyncio.Event()

        async def send(self, msg) -> None:  # noqa: ANN001
            await self.gate.wait()
            self.sent.append(msg)

    async def main():  # noqa: ANN202
        ws = BlockedSocket()
        sub = _Subscriber(ws, "json", None, maxlen=4)
        sub.task = asyncio.create_task(sub.run())
        kept = [sub.offer(f"pose {k}") for k in range(10)]
        await asyncio.sleep(0.01)  # the sender took "pose 0" and waits on the socket
        kept += [sub.offer(f"pose {k}") for k in range(10, 20)]
        ws.gate.set()
        await asyncio.sleep(0.05)
        sub.task.cancel()
        return ws.sent, kept, sub.stats()

    sent, kept, stats = _run(main())
    # 10 offered into a queue of 4: 6 dropped, reported as the first message (the sender's
    # first send, held by the socket); 10 more while it waits: 10 more dropped, the 4 newest sent.
    # The next report waits for the next pose after a second (at most one report a second).
    assert stats["dropped"] == 16 and kept.count(False) == 16
    assert json.loads(sent[0]) == {"type": "dropped", "count": 6, "total": 6, "policy": "drop-oldest", "queue": 4}
    assert sent[1:] == ["pose 16", "pose 17", "pose 18", "pose 19"]


def test_replay_stops_at_once_when_the_server_ends_its_subject() -> None:
    """`wearpose stream replay --duration 25` against a server that stops after 0.5 s: the replay
    gets the server's bye (reason: stopping) and returns within a second, with every frame it
    sent estimated."""
    rec = tiny_recording(60)

    async def main():  # noqa: ANN202
        srv = await StreamServer(EchoEstimator, port=0, warmup=0).start()
        t0 = time.perf_counter()
        task = asyncio.create_task(replay(rec, srv.url, realtime=True, duration=25.0))
        await asyncio.sleep(0.5)
        await srv.stop()
        r = await asyncio.wait_for(task, 5)
        return r, time.perf_counter() - t0

    r, took = _run(main())
    assert took < 2.5 and r["ended_by_server"] and "server stopping" in r["ended_by_server"]
    assert 0 < r["frames_sent"] < 25 * 60 and r["frames_lost"] == 0 and not r["gave_up_waiting"]
    # frames that reached the server while it was ending the subject are cut (counted), not lost
    s = r["server_stats"]
    assert s["estimated"] == s["received"] == r["frames_sent"] - r["frames_cut_at_end"] == r["poses_received"]
    assert s["after_end"] <= r["frames_cut_at_end"]


def test_replay_stops_when_the_connection_is_cut() -> None:
    rec = tiny_recording(60)

    async def main():  # noqa: ANN202
        async with StreamServer(EchoEstimator, port=0, warmup=0) as srv:
            task = asyncio.create_task(replay(rec, srv.url, realtime=True, duration=25.0))
            while not srv.connections:
                await asyncio.sleep(0.01)
            await asyncio.sleep(0.3)
            for ws in list(srv.connections):
                await ws.close(1011, "gone")
            return await asyncio.wait_for(task, 5)

    r = _run(main())
    assert "closed" in r["ended_by_server"] and r["frames_sent"] < 25 * 60


def test_udp_control_messages_need_the_token_when_required() -> None:
    rec = tiny_recording(10)
    st = stack_recording(rec)

    async def main():  # noqa: ANN202
        async with StreamServer(EchoEstimator, port=0, udp_port=0, warmup=0, require_token=True) as srv:
            inbox: asyncio.Queue = asyncio.Queue()

            class P(asyncio.DatagramProtocol):
                def datagram_received(self, data: bytes, addr) -> None:  # noqa: ANN001
                    inbox.put_nowait(json.loads(data))

            tr, _ = await asyncio.get_running_loop().create_datagram_endpoint(P, remote_addr=("127.0.0.1", srv.udp_port))
            hello = json.loads(Hello(4, st.names, st.channels, st.rate, "json").to_json())
            tr.sendto(json.dumps(hello).encode())
            refused = await asyncio.wait_for(inbox.get(), 5)
            tr.sendto(json.dumps({**hello, "token": srv.token}).encode())
            ready = await asyncio.wait_for(inbox.get(), 5)
            tr.close()
            return refused, ready, srv.stats()

    refused, ready, stats = _run(main())
    assert refused["type"] == "error" and refused["code"] == "token" and "access token" in refused["error"]
    assert ready["type"] == "ready" and stats["security"]["token"] == 1
