"""The one interface of live device inputs (``wearpose serve --input NAME``).

A :class:`LiveInput` listens for one device protocol (LSL, OSC, the Xsens MVN network streamer)
and hands the server :class:`DeviceFrame` s: one time step of every sensor, the values exactly
as the device sent them, in the conventions the input *declares* per sensor
(:class:`~wearpose.recording.SensorInfo`: units, sensor or world frame, gravity, up axis;
quaternions already reordered to (w, x, y, z) and checked unit-norm). :func:`canonical_frame`
turns such a frame into canonical sensor channels through the recording format's one
conversion path (:meth:`wearpose.recording.Recording.to_canonical`), so a device frame and the
same data in a recording file give the same estimator input.

Each frame carries a sequence number the input derives from the device's own counter or clock
(MVN sample counter; LSL / OSC time stamps on the nominal rate grid), so the server's reorder
buffer counts gaps as lost and never invents a frame. Anything that does not follow the
protocol raises :class:`~wearpose.stream.packets.PacketError` inside the input, which reports it
through ``on_malformed`` (the server counts it in ``malformed_total`` and the subject's
``malformed``) and goes on.
"""

from __future__ import annotations

import abc
import socket
from dataclasses import dataclass, replace
from typing import Any, Callable, ClassVar, Sequence

import numpy as np
import torch

from wearpose.geometry import quat_to_matrix
from wearpose.recording import SensorInfo
from wearpose.recording.types import OPTIONAL_CHANNELS, REQUIRED_CHANNELS, canonical_arrays
from wearpose.stream.packets import CHANNEL_FLOATS, PacketError

#: A quaternion a device sends must be unit-norm within this (the recording format's tolerance).
QUAT_TOL = 1e-2


@dataclass
class DeviceFrame:
    """One time step of every sensor of an input, as the device sent it.

    Attributes:
        seq: sequence number (u32; +1 per nominal frame period of the device).
        timestamp: s, the device's clock (LSL time stamp, OSC time tag, MVN time code).
        valid: ``(S,)`` bool; a sensor the device did not send for this step is False (masked).
        channels: channel -> ``(S, ...)`` float array in the declared conventions
            (``orientation`` ``(S, 3, 3)`` ``R_WS``), NaN where invalid or absent.
    """

    seq: int
    timestamp: float
    valid: np.ndarray
    channels: dict[str, np.ndarray]


class LiveInput(abc.ABC):
    """A device protocol listener.

    Attributes (set by :meth:`open`, before frames flow):
        sensors: the declared :class:`SensorInfo` of each sensor, in frame column order.
        rate: nominal frame rate, Hz.
        counts: input-side counters (``datagrams``, ``malformed``, ``ignored``...), shown in the
            server's stats under ``inputs``.
    """

    name: ClassVar[str] = "?"
    sensors: tuple[SensorInfo, ...] = ()
    rate: float = 0.0

    def __init__(self) -> None:
        self.counts: dict[str, int] = {"frames": 0, "malformed": 0, "ignored": 0}
        self._on_frame: Callable[[DeviceFrame], None] | None = None
        self._on_malformed: Callable[[Exception], None] | None = None

    @abc.abstractmethod
    async def open(self) -> None:
        """Bind / resolve the device (knows :attr:`sensors` and :attr:`rate` afterwards)."""

    @abc.abstractmethod
    async def close(self) -> None:
        """Stop listening and hand over what is still buffered (flush)."""

    def attach(self, on_frame: Callable[[DeviceFrame], None], on_malformed: Callable[[Exception], None]) -> None:
        """Where frames and protocol violations go (the server's input bridge)."""
        self._on_frame, self._on_malformed = on_frame, on_malformed

    def emit(self, frame: DeviceFrame) -> None:
        self.counts["frames"] += 1
        if self._on_frame is not None:
            self._on_frame(frame)

    def malformed(self, exc: Exception) -> None:
        self.counts["malformed"] += 1
        if self._on_malformed is not None:
            self._on_malformed(exc)

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(s.name for s in self.sensors)

    def stats(self) -> dict[str, Any]:
        return {"input": self.name, "rate_hz": self.rate, "sensors": list(self.names), **self.counts}


def quaternion_matrices(q: Any, order: str, where: str) -> np.ndarray:
    """Device quaternions ``(n, 4)`` in component ``order`` (``"wxyz"`` or ``"xyzw"``) ->
    ``(n, 3, 3)`` rotations (one :func:`wearpose.geometry.quat_to_matrix` call); PacketError
    naming ``where`` when one is not finite or not unit-norm."""
    a = np.asarray(q, dtype=np.float64)
    if a.ndim != 2 or a.shape[1] != 4 or not np.isfinite(a).all():
        raise PacketError(f"{where}: quaternions must be finite numbers, 4 per rotation")
    if order == "xyzw":
        a = a[:, [3, 0, 1, 2]]
    elif order != "wxyz":
        raise ValueError(f"quaternion order {order!r}: expected 'wxyz' or 'xyzw'")
    n = np.linalg.norm(a, axis=1)
    bad = np.flatnonzero(np.abs(n - 1.0) > QUAT_TOL)
    if bad.size:
        raise PacketError(f"{where}: quaternion {int(bad[0])} has norm {n[bad[0]]:.4g}, expected unit quaternions "
                          f"({order}); a wrong component order or unit shows up like this")
    return quat_to_matrix(torch.from_numpy(a)).numpy()


def quaternion_norm_check(q: Any, order: str, where: str) -> None:
    """PacketError unless ``q`` ``(4,)`` is a finite unit quaternion (see :func:`quaternion_matrices`)."""
    a = np.asarray(q, np.float64)
    if a.shape != (4,) or not np.isfinite(a).all():
        raise PacketError(f"{where}: quaternion must be 4 finite numbers")
    n = float(np.sqrt(a @ a))
    if abs(n - 1.0) > QUAT_TOL:
        raise PacketError(f"{where}: quaternion norm {n:.4g}, expected a unit quaternion ({order}); a wrong "
                          f"component order or unit shows up like this")


def quaternion_matrix(q: Sequence[float], order: str, where: str) -> np.ndarray:
    """One device quaternion -> ``(3, 3)`` (see :func:`quaternion_matrices`)."""
    return quaternion_matrices(np.asarray(q, np.float64).reshape(1, -1), order, where)[0]


def canonical_channels(sensors: Sequence[SensorInfo]) -> tuple[str, ...]:
    """The channels the server's hello declares for these sensors (every channel any of them
    carries, in the packet order)."""
    have = {c for s in sensors for c in REQUIRED_CHANNELS[s.kind] + OPTIONAL_CHANNELS[s.kind]}
    return tuple(c for c in CHANNEL_FLOATS if c in have)


def canonical_frame(sensors: Sequence[SensorInfo], frame: DeviceFrame,
                    channels: Sequence[str]) -> np.ndarray:
    """A device frame as the server's payload ``(S, F)`` float32 in canonical units and frames.

    Each valid sensor's values go through :func:`wearpose.recording.types.canonical_arrays`
    with the input's declared :class:`SensorInfo` -- the conversion ``Recording.to_canonical``
    applies to files (units, sensor-frame acceleration, gravity, Z-up world). Invalid sensors
    are NaN. Raises PacketError when a valid sensor lacks a channel its kind requires or has a
    value that is not finite (the decoders already refuse non-unit quaternions).
    """
    out = np.full((len(sensors), sum(CHANNEL_FLOATS[c] for c in channels)), np.nan, np.float32)
    groups: dict[tuple[Any, ...], list[int]] = {}
    for j, info in enumerate(sensors):
        if not frame.valid[j]:
            continue
        have = tuple(c for c, a in frame.channels.items() if a is not None and not np.isnan(a[j]).all())
        missing = [c for c in REQUIRED_CHANNELS[info.kind] if c not in have]
        if missing:
            raise PacketError(f"sensor {info.name!r} seq {frame.seq}: no {missing} (a {info.kind} sensor needs "
                              f"{list(REQUIRED_CHANNELS[info.kind])})")
        bad = [c for c in have if not np.isfinite(frame.channels[c][j]).all()]
        if bad:
            raise PacketError(f"sensor {info.name!r} seq {frame.seq}: non-finite values in {bad}")
        groups.setdefault((_conventions(info), have), []).append(j)
    # Sensors declared alike convert together: the sensor axis is the sample axis of canonical_arrays.
    for (conv, have), idx in groups.items():
        info = sensors[idx[0]]
        ch = {c: np.asarray(frame.channels[c][idx], np.float64) for c in have}
        if not info.is_canonical:
            _, ch = canonical_arrays(info, ch)
        a = 0
        for c in channels:
            n = CHANNEL_FLOATS[c]
            if c in ch:
                out[idx, a:a + n] = ch[c].reshape(len(idx), n)
            a += n
    return out


def _conventions(info: SensorInfo) -> tuple[str, ...]:
    return (info.kind, info.acc_unit, info.acc_frame, info.acc_gravity, info.world_up, info.position_unit,
            info.gyro_unit)


def declared(info: SensorInfo, **conventions: Any) -> SensorInfo:
    """``info`` with these declared conventions (a device's units and frames)."""
    return replace(info, **conventions)


#: Receive buffer asked for on input UDP sockets (bytes; the OS caps it at net.core.rmem_max):
#: a burst of datagrams waits there while the event loop is busy, instead of being dropped.
UDP_RCVBUF = 4 << 20


def udp_socket(host: str, port: int) -> Any:
    """A bound, non-blocking UDP socket with a large receive buffer (:data:`UDP_RCVBUF`)."""
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, UDP_RCVBUF)
    s.bind((host, port))
    s.setblocking(False)
    return s


def drain_udp(sock: Any, handle: Any) -> int:
    """Hand every datagram still queued in ``sock`` (from :func:`udp_socket`) to ``handle(data)``
    (at close: what the device sent before it stopped is estimated, not dropped). Returns how many."""
    n = 0
    while sock is not None:
        try:
            data = sock.recv(1 << 16)
        except (BlockingIOError, InterruptedError, OSError):
            break
        handle(data)
        n += 1
    return n

