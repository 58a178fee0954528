"""Shared pieces of the loopback emulators (``wearpose stream emulate INPUT RECORDING``).

An emulator plays a recording in a device's wire format at the recording's real rate (or
``speed`` times it) to 127.0.0.1, optionally with injected faults (seeded):

- ``malformed``: probability per frame of sending one extra malformed packet after it (the real
  frame is still sent: a malformed packet never costs a frame);
- ``dropout``: probability per sensor and frame of starting a dropout of ``dropout_frames``
  (uniform range) frames, during which that sensor is not sent (or sent as missing, per
  protocol); the server receives the frame with that sensor masked. The first frame is never
  dropped (inputs that learn the sensor set from the first frame see every sensor).
"""

from __future__ import annotations

import asyncio
import socket
import time
from dataclasses import dataclass, field
from typing import Any, Awaitable, Callable

import numpy as np

from wearpose.stream.replay import Faults


@dataclass
class DeviceData:
    """A recording's sensors on their common grid in a device's declared conventions.

    Attributes:
        names: ``S`` sensor names; timestamps ``(T,)`` s; valid ``(T, S)``; channels: channel ->
        ``(T, S, ...)`` float64 (``orientation`` ``(T, S, 3, 3)``); rate Hz.
    """

    names: tuple[str, ...]
    timestamps: np.ndarray
    valid: np.ndarray
    channels: dict[str, np.ndarray]
    rate: float
    extra: dict[str, Any] = field(default_factory=dict)


def device_data(recording: Any, **conventions: str) -> DeviceData:
    """``recording`` rewritten in a device's conventions (``Recording.declared_as``: the inverse
    of the conversion the input's declarations undo), stacked on its common grid."""
    rec = recording if recording.is_canonical else recording.to_canonical()
    if conventions:
        rec = rec.declared_as(**conventions)
    grid = rec.on_common_grid()
    dt = np.diff(grid.timestamps)
    rate = float(1.0 / np.median(dt)) if len(dt) else 1.0
    return DeviceData(tuple(grid.names), grid.timestamps.copy(), grid.valid.copy(),
                      {c: np.asarray(a, np.float64) for c, a in grid.channels.items()}, rate)


@dataclass
class EmulatorResult:
    frames_sent: int = 0
    malformed_sent: int = 0
    dropped_sensor_samples: int = 0  # injected dropouts (samples the recording had valid)
    recording_masked_samples: int = 0  # samples already masked in the recording (sent as missing too)
    send_lag_ms_max: float = 0.0
    duration_s: float = 0.0

    def to_dict(self) -> dict[str, Any]:
        return dict(self.__dict__)


async def play(n_frames: int, n_sensors: int, rate: float, send: Callable[[int, np.ndarray], Awaitable[None] | None],
               send_malformed: Callable[[int, np.random.Generator], Awaitable[None] | None],
               faults: Faults | None = None, speed: float = 1.0, realtime: bool = True,
               base_valid: np.ndarray | None = None) -> EmulatorResult:
    """Call ``send(k, valid)`` for frames ``k = 0 .. n_frames - 1`` at ``rate * speed`` Hz, with
    the dropout mask applied to ``valid`` ``(S,)`` and a malformed packet after some frames."""
    faults = faults or Faults()
    rng = np.random.default_rng(faults.seed)
    res = EmulatorResult()
    off_until = np.zeros(n_sensors, np.int64)
    period = 1.0 / (rate * speed)
    t0 = time.perf_counter() + 0.02
    for k in range(n_frames):
        if realtime:
            target = t0 + k * period
            now = time.perf_counter()
            # Always yield: a receiver on the same event loop (tests) must read each datagram
            # before the next burst, or the socket's receive buffer overflows.
            await asyncio.sleep(max(0.0, target - now))
            res.send_lag_ms_max = max(res.send_lag_ms_max, (time.perf_counter() - target) * 1e3)
        else:
            await asyncio.sleep(0)
        valid = np.ones(n_sensors, bool) if base_valid is None else base_valid[k].copy()
        res.recording_masked_samples += int((~valid).sum())
        if faults.dropout > 0 and k > 0:
            start = (rng.random(n_sensors) < faults.dropout) & (off_until <= k)
            lo, hi = faults.dropout_frames
            off_until[start] = k + rng.integers(lo, hi + 1, size=int(start.sum()))
            res.dropped_sensor_samples += int((valid & (off_until > k)).sum())
            valid &= off_until <= k
        r = send(k, valid)
        if r is not None:
            await r
        res.frames_sent += 1
        if faults.malformed > 0 and rng.random() < faults.malformed:
            r = send_malformed(k, rng)
            if r is not None:
                await r
            res.malformed_sent += 1
    res.duration_s = round(time.perf_counter() - t0, 3)
    return res


class UdpSender:
    """A connected UDP socket to ``host:port`` (loopback by default) for the emulators."""

    def __init__(self, host: str = "127.0.0.1", port: int = 0) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.connect((host, port))
        self.refused = 0

    def send(self, data: bytes) -> None:
        try:
            self.sock.send(data)
        except ConnectionRefusedError:  # nothing listening (yet): a device keeps sending regardless
            self.refused += 1

    def close(self) -> None:
        self.sock.close()
