"""Stream a :class:`~wearpose.recording.Recording` to the server at real time, optionally with
injected faults, and measure what comes back (used by ``wearpose stream replay`` and
``benchmarks/stream.py``).

Faults (:class:`Faults`, all seeded):

- ``malformed``: probability per frame of sending one extra malformed message after it
  (truncated/over-long binary, bad magic, bad JSON, wrong sensor count, NaN in a valid sensor,
  unknown type, unknown subject); the real frame is still sent, so none is lost by design.
- ``dropout``: probability per sensor and frame of starting a dropout burst of
  ``dropout_frames`` (uniform range) frames: those samples are sent invalid (masked).
- ``reorder``: probability per frame of sending it one frame period late, after its successor.
"""

from __future__ import annotations

import asyncio
import time
from dataclasses import asdict, dataclass
from typing import Any, Callable

import numpy as np

from wearpose.stream.client import StreamClient, StreamError
from wearpose.stream.packets import (
    CHANNEL_FLOATS,
    HEADER,
    FramePacket,
    Hello,
    PosePacket,
    encode_frame_binary,
    pack_channels,
)


@dataclass
class Faults:
    malformed: float = 0.0
    dropout: float = 0.0
    dropout_frames: tuple[int, int] = (1, 30)
    reorder: float = 0.0
    seed: int = 0


@dataclass
class _Stream:
    """A recording's frames stacked for sending: ``data`` ``(T, S, F)``, ``valid`` ``(T, S)``."""

    names: tuple[str, ...]
    channels: tuple[str, ...]
    timestamps: np.ndarray
    valid: np.ndarray
    data: np.ndarray
    rate: float


def stack_recording(recording: Any) -> _Stream:
    """Every sensor of ``recording`` on its common grid, channels shared by all sensors."""
    grid = recording.on_common_grid()
    channels = tuple(c for c in CHANNEL_FLOATS if c in grid.channels and not np.isnan(
        grid.channels[c][grid.valid]).all())
    T, S = grid.valid.shape
    data = np.concatenate([np.asarray(grid.channels[c], np.float32).reshape(T, S, -1) for c in channels], axis=2)
    dt = np.diff(grid.timestamps)
    rate = float(1.0 / np.median(dt)) if len(dt) else 1.0
    return _Stream(tuple(grid.names), channels, np.asarray(grid.timestamps, np.float64), grid.valid.copy(), data, rate)


def _summary_ms(x: list[float] | np.ndarray) -> dict[str, float | None]:
    a = np.asarray(x, dtype=np.float64)
    a = a[np.isfinite(a)]
    if not len(a):
        return {"median": None, "mean": None, "p99": None, "max": None, "n": 0}
    return {"median": round(float(np.median(a)), 3), "mean": round(float(a.mean()), 3), "p99": round(float(np.percentile(a, 99)), 3),
            "max": round(float(a.max()), 3), "n": int(len(a))}


def _stages(seqs: list[int], e2e: list[float], srv: list[float], comp: list[float], limit: float) -> dict[str, Any]:
    """Where the time of the frames with sequence number below ``limit`` went (the start of a
    stream, where a one-off stall shows): end to end, compute (the estimator's step), queue (in
    the server, waiting for the estimator) and transport (the rest: sockets and both event loops),
    each as :func:`_summary_ms`, plus the slowest of those frames with its split, in ms."""
    n = int(np.searchsorted(np.asarray(seqs), limit))  # ``seqs`` ascending, like e2e/srv/comp
    if n == 0:
        return {"frames": 0}
    a_e2e, a_srv, a_comp = (np.asarray(x[:n], dtype=np.float64) for x in (e2e, srv, comp))
    k = int(np.argmax(a_e2e))
    return {"frames": n, "latency_ms": _summary_ms(a_e2e), "compute_ms": _summary_ms(a_comp),
            "queue_ms": _summary_ms(a_srv - a_comp), "transport_ms": _summary_ms(a_e2e - a_srv),
            "slowest": {"seq": int(seqs[k]), "latency_ms": round(float(a_e2e[k]), 3),
                        "compute_ms": round(float(a_comp[k]), 3), "queue_ms": round(float(a_srv[k] - a_comp[k]), 3),
                        "transport_ms": round(float(a_e2e[k] - a_srv[k]), 3)}}


def _malformed(kind: int, good: bytes, hello: Hello, rng: np.random.Generator) -> str | bytes:
    """One malformed message of type ``kind % 8`` derived from a good binary frame."""
    kind %= 8
    if kind == 0:
        return good[: int(rng.integers(1, HEADER.size))]  # truncated header
    if kind == 1:
        return good + b"\x00\x00\x00\x00"  # payload one float too long
    if kind == 2:
        return b"XX" + good[2:]  # bad magic
    if kind == 3:
        return '{"type": "frame", "subject": ' + str(hello.subject) + ', "seq": '  # cut JSON
    if kind == 4:
        return ('{"type": "frame", "v": 1, "subject": %d, "seq": 0, "t": 0.0, "valid": [1]}' % hello.subject)
    if kind == 5:
        bad = bytearray(good)
        bad[HEADER.size:HEADER.size + 4] = np.float32(np.nan).tobytes()  # NaN in sensor 0 (sent valid)
        bad[20:28] = (0xFFFFFFFFFFFFFFFF >> (64 - len(hello.sensors))).to_bytes(8, "little")
        return bytes(bad)
    if kind == 6:
        return '{"type": "teleport", "subject": %d}' % hello.subject
    bad = bytearray(good)
    bad[4:6] = (65535 if hello.subject != 65535 else 65534).to_bytes(2, "little")  # unknown subject
    return bytes(bad)


async def replay(recording: Any, url: str, *, subject: int = 0, fmt: str = "binary", realtime: bool = True,
                 speed: float = 1.0, duration: float | None = None, faults: Faults | None = None,
                 progress: Callable[[int, int], None] | None = None, client: StreamClient | None = None,
                 drain_timeout: float | None = None, token: str | None = None) -> dict[str, Any]:
    """Stream ``recording`` as subject ``subject`` and collect its poses.

    Args:
        recording: a :class:`~wearpose.recording.Recording` (all sensors on one grid).
        url: server ``ws://host:port``.
        fmt: ``"binary"`` or ``"json"`` packets (poses come back in the same format).
        realtime: pace frames at the recording's rate times ``speed`` (else as fast as possible).
        duration: seconds of stream to send, looping the recording (default: once through).
        faults: injected faults (module doc).
        progress: ``(frames sent, total)`` callback, called about once a second.
        client: an open :class:`StreamClient` to use (several subjects on one connection).
        drain_timeout: seconds to wait after the last frame for the remaining poses (default
            max(600, twice the stream's duration)); frames still queued at the server then count
            in ``frames_lost`` and ``gave_up_waiting`` is True.
        token: the server's access token (``wearpose serve`` prints it; needed when the server
            requires it); ignored with ``client`` (give it to that client).

    Returns:
        dict: ``frames_sent``, ``poses_received``, ``frames_expected`` (sent minus those the
        server's stride skips), ``frames_lost`` (expected without a pose by the end of the
        drain; ``frames_lost_by_server``: of those, the ones the server gave up or dropped as
        late, the rest were still queued), ``drain_s`` (last frame sent -> last pose in), latency
        summaries in
        ms (``latency_ms`` end to end = send -> pose received; ``server_ms`` frame arrival ->
        pose sent, of which ``compute_ms`` is the estimator's step; ``transport_ms`` = end to end
        minus server), ``send_lag_ms`` (how late the sender was against the schedule), the
        server's final ``server_stats``, ``faults`` and ``invalid_pose_frames``;
        ``ended_by_server``: None, or why the stream stopped early (the server ended the subject,
        e.g. shutting down, or closed the connection): the replay stops sending at once and
        returns what it has, it never waits for a server that is gone; ``frames_cut_at_end``:
        frames sent while the server was already ending the subject (it did not accept them;
        not counted in ``frames_expected`` / ``frames_lost``); ``frames_shed_by_server``: frames
        the overloaded server shed (``Limits.max_lag_s``; part of ``frames_lost``) and
        ``warnings``: sentences for the user (shedding, a median latency over 100 ms).
    """
    faults = faults or Faults()
    rng = np.random.default_rng(faults.seed)
    st = stack_recording(recording)
    T, S = st.valid.shape
    N = T if duration is None else max(1, int(round(duration * st.rate)))
    sent: dict[int, float] = {}
    # Only plain numbers per pose (receive time, server_ms, compute_ms, valid): tens of thousands of
    # kept PosePackets would make the client's garbage collections long, and stall its clock.
    recv: dict[int, tuple[float, float, float, bool]] = {}

    def on_pose(t: float, p: PosePacket) -> None:
        if p.subject == subject:
            recv[p.seq] = (t, p.server_ms, p.compute_ms, p.valid)

    own = client is None
    c = client or StreamClient(url, token=token)
    if own:
        await c.connect()
    prev_on_pose = c.on_pose
    c.on_pose = on_pose if prev_on_pose is None else (lambda t, p: (prev_on_pose(t, p), on_pose(t, p)))
    hello = Hello(subject, st.names, st.channels, st.rate, fmt, dict(recording.subject or {}))
    try:
        ready = await c.hello(hello)
        off_until = np.zeros(S, dtype=np.int64)
        n_malformed = n_reordered = n_dropped_samples = 0
        swapped: set[int] = set()  # frames sent after their successor
        lag: list[float] = []
        held: FramePacket | None = None
        period = 1.0 / (st.rate * speed)
        t0 = time.perf_counter() + 0.05
        last_progress = t0

        async def send(p: FramePacket) -> None:
            t = time.perf_counter()
            await c.send_frame(p)
            sent[p.seq] = t  # only frames that left: one the server had ended is not "lost"

        ended: str | None = None  # why the server ended the stream early (None: it did not)
        try:
            for k in range(N):
                if realtime:
                    target = t0 + k * period
                    now = time.perf_counter()
                    if target > now:
                        await asyncio.sleep(target - now)
                    lag.append(max(0.0, time.perf_counter() - target) * 1e3)
                i = k % T
                valid = st.valid[i].copy()
                if faults.dropout > 0:
                    start = (rng.random(S) < faults.dropout) & (off_until <= k)
                    lo, hi = faults.dropout_frames
                    off_until[start] = k + rng.integers(lo, hi + 1, size=int(start.sum()))
                    n_dropped_samples += int((valid & (off_until > k)).sum())
                    valid &= off_until <= k
                data = st.data[i].copy()
                data[~valid] = np.nan
                ts = float(st.timestamps[0] + k / st.rate)
                pkt = FramePacket(subject, k, ts, valid, data)
                if held is None and k + 1 < N and faults.reorder > 0 and rng.random() < faults.reorder:
                    held, n_reordered = pkt, n_reordered + 1  # sent after its successor
                    swapped.add(k)
                else:
                    await send(pkt)
                    if held is not None:
                        await send(held)
                        held = None
                if faults.malformed > 0 and rng.random() < faults.malformed:
                    await c.send_raw(_malformed(int(rng.integers(0, 8)), encode_frame_binary(pkt), hello, rng))
                    n_malformed += 1
                if progress is not None and time.perf_counter() - last_progress > 1.0:
                    last_progress = time.perf_counter()
                    progress(k + 1, N)
                if not realtime and k % 64 == 63:
                    await asyncio.sleep(0)  # let the reader run
            if held is not None:
                await send(held)
        except StreamError as exc:  # the server ended the subject or closed the connection: stop, report
            ended = str(exc)
        # The estimator may be behind (frames queue, never dropped): give it time to finish.
        t_end = time.perf_counter()
        gave_up = False
        if ended is None:
            try:
                server_stats = await c.bye(subject, timeout=drain_timeout if drain_timeout is not None
                                           else max(600.0, 2.0 * N / st.rate))
            except asyncio.TimeoutError:
                # Report what arrived; the server still holds (and will estimate) the rest.
                gave_up = True
                stats = await c.stats()
                server_stats = stats.get("subjects", {}).get(str(subject), {})
            except StreamError as exc:  # the connection went away while waiting
                ended = str(exc)
        if ended is not None:
            server_stats = (c.ended.get(subject) or {}).get("stats", {})
        drain_s = time.perf_counter() - t_end
    finally:
        c.on_pose = prev_on_pose
        if own:
            await c.close()
    stride = int(ready.get("stride", 1))
    # Ended by the server: the last frames sent may have reached it while it was ending the
    # subject (it did not accept them: sent minus received). They are cut, not lost.
    cut = max(0, len(sent) - int(server_stats.get("received", len(sent)))) if ended is not None else 0
    accepted = sorted(sent)[:len(sent) - cut]
    expected = [s for s in accepted if s % stride == 0]
    got = [s for s in expected if s in recv]
    e2e = [(recv[s][0] - sent[s]) * 1e3 for s in got]
    srv = [recv[s][1] for s in got]
    comp = [recv[s][2] for s in got]
    # Where the tail comes from: the slowest 1 % of frames, split as above, and how many of them
    # are a swapped pair (sent after its successor, or the successor that had to wait for it).
    tail: dict[str, Any] = {}
    if got:
        a_e2e, a_srv, a_comp = np.asarray(e2e), np.asarray(srv), np.asarray(comp)
        top = a_e2e >= np.percentile(a_e2e, 99)
        seqs = np.asarray(got)[top]
        tail = {"frames": int(top.sum()), "latency_ms_mean": round(float(a_e2e[top].mean()), 3),
                "compute_ms_mean": round(float(a_comp[top].mean()), 3),
                "queue_ms_mean": round(float((a_srv - a_comp)[top].mean()), 3),
                "transport_ms_mean": round(float((a_e2e - a_srv)[top].mean()), 3),
                "swapped_pair_frames": int(sum(1 for q in seqs if q in swapped or q - 1 in swapped)),
                "in_first_second": int((seqs < st.rate).sum())}
    shed = int(server_stats.get("shed", 0))
    warnings_: list[str] = []
    if shed:
        warnings_.append(f"the server was overloaded and shed {shed} of {len(expected)} frames unestimated (each had "
                         "waited longer than its max lag with newer frames queued: the overload policy, "
                         "docs/streaming.md); give it more CPU or stream at the estimator's rate (--stride auto)")
    late = _summary_ms(e2e)
    if late["median"] is not None and late["median"] > 100.0:
        warnings_.append(f"median latency {late['median']:.0f} ms: the server or this client is starved of CPU")
    return {
        "warnings": warnings_, "frames_shed_by_server": shed,
        "subject": subject, "format": fmt, "rate_hz": st.rate, "sensors": len(st.names), "channels": list(st.channels),
        "frames_sent": len(sent), "frames_expected": len(expected), "poses_received": len(recv),
        "frames_lost": len(expected) - len(got),
        "frames_lost_by_server": int(server_stats.get("lost", 0)) + int(server_stats.get("late", 0)) + shed,
        "gave_up_waiting": gave_up, "drain_s": round(drain_s, 3), "ended_by_server": ended, "frames_cut_at_end": cut,
        "frames_queued_at_server_at_end": server_stats.get("queue_now") if gave_up else 0,
        "invalid_pose_frames": sum(1 for s in got if not recv[s][3]),
        "latency_ms": _summary_ms(e2e), "server_ms": _summary_ms(srv), "compute_ms": _summary_ms(comp),
        "transport_ms": _summary_ms(np.asarray(e2e) - np.asarray(srv)),
        "queue_ms": _summary_ms(np.asarray(srv) - np.asarray(comp)),
        "send_lag_ms": _summary_ms(lag) if lag else None, "tail_top1pct": tail,
        "first_frames_latency_ms": [round(x, 3) for x in e2e[:10]],
        "first_two_seconds": _stages(got, e2e, srv, comp, limit=2.0 * st.rate),
        "injected": {"malformed": n_malformed, "reordered": n_reordered, "dropped_sensor_samples": n_dropped_samples},
        "faults": asdict(faults), "ready": ready, "server_stats": server_stats,
    }
