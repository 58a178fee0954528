"""x-IMU3 live input through x-io's official ``ximu3`` package, and its loopback emulator.

One ``ximu3.Connection`` per device (``ximu3`` 1.9.1, the ``ximu3`` extra). Two transports:

- ``tcp`` (default): the x-IMU3 is the TCP server (its Wi-Fi TCP port); wearpose connects to
  ``host:port`` of each device (``ximu3.TcpConnectionConfig``). Nothing listens on this machine.
- ``udp``: the device sends its messages to a UDP port of this machine
  (``ximu3.UdpConnectionConfig(host, port, port)``: ``host`` is the device, ``port`` the local
  receive port; wearpose sends no command, so the send port is unused). ``ximu3`` 1.9.1 binds the
  receive port on **all interfaces** (``0.0.0.0``; it takes no bind address), not only loopback.

Messages read (x-IMU3 User Manual, "Data messages", checked against what ``ximu3`` 1.9.1
parses): the **inertial** message (``I``: timestamp in microseconds, gyroscope x y z in deg/s,
accelerometer x y z in g, sensor frame, gravity included) and the **quaternion** message
(``Q``: w x y z, the device's AHRS, sensor -> Earth North-West-Up). Both in either of the device's
formats: ASCII (comma-separated, CR LF terminated, four decimals) or binary (``0x80`` + the ASCII
identifier, u64 timestamp, float32 arguments, little-endian, SLIP-like byte stuffing, LF
terminated); ``ximu3`` decodes both. Declared as the file import declares a log
(``docs/devices.md``): ``acc_unit="g"``, ``acc_frame="sensor"``, ``acc_gravity="included"``,
``gyro_unit="deg/s"``, ``world_up="z_up"``; converted by ``Recording.to_canonical``'s path.

A device's **sample** is its inertial and quaternion messages with the same timestamp (the
device's message rates must be equal: the real log's are both ~50 Hz); a message without its
twin is counted ``unpaired``. **Frames**: sequence ``round((t - t0) * rate)`` with ``t`` the
device timestamp (s) and ``t0`` the first sample's; devices whose clock lies more than 1 s from
the others' (not one clock) are put on it by the arrival of their first sample, as the log import
does. A frame is handed on when every device has sent its sample, or with the missing devices
masked once each has moved ``window`` frames past it (or 2 s of frames passed: a device that
stopped); frames are handed on in order. What ``ximu3`` cannot parse (its receive-error callback: unknown identifier,
unparsable ASCII, wrong binary length...) and quaternions that are not unit-norm are malformed
(counted); other messages (battery, temperature...) are not subscribed to.
"""

from __future__ import annotations

import asyncio
import struct
from typing import Any, Mapping, Sequence

import numpy as np
import torch

from wearpose.errors import ConfigError
from wearpose.geometry import matrix_to_quat
from wearpose.recording import SensorInfo
from wearpose.recording.types import known_sites
from wearpose.stream.inputs.base import DeviceFrame, LiveInput, quaternion_matrices, quaternion_norm_check
from wearpose.stream.inputs.emulate import UdpSender, device_data, play
from wearpose.stream.packets import PacketError

TRANSPORTS = ("tcp", "udp")
FORMATS = ("binary", "ascii")
#: The device's declared conventions (module doc; the same as ``recording.from_ximu3``'s).
CONVENTIONS = {"acc_unit": "g", "acc_frame": "sensor", "acc_gravity": "included", "gyro_unit": "deg/s",
               "world_up": "z_up"}
#: Devices whose first timestamps lie further apart than this (s) do not share a clock.
ONE_CLOCK_S = 1.0
END, ESC, ESC_END, ESC_ESC = 0x0A, 0xDB, 0xDC, 0xDD


def _ximu3() -> Any:
    try:
        import ximu3  # optional dependency: the ximu3 extra (live x-IMU3 devices)
    except ImportError:  # pragma: no cover - the extra is installed in the project's venv
        raise ConfigError("--input ximu3 needs x-io's ximu3 package: pip install 'wearpose[ximu3]'") from None
    return ximu3


class Ximu3Input(LiveInput):
    """x-IMU3 devices through ``ximu3`` connections (module doc).

    Args:
        sensors: sensor name -> port (tcp: the device's TCP port on ``host``; udp: the local
            receive port the device sends to).
        rate: the devices' message rate, Hz (frames are on this grid).
        host: tcp/udp: the devices' address (one host for all; loopback for the emulator).
        transport: ``tcp`` or ``udp``.
        window: frames a device must have moved past a frame it did not send for it to count
            as missing there.
        timeout: s to keep trying to connect (tcp: the device may come up after the server).
    """

    name = "ximu3"

    def __init__(self, sensors: Mapping[str, int], rate: float, host: str = "127.0.0.1", transport: str = "tcp",
                 window: int = 2, timeout: float = 120.0) -> None:
        super().__init__()
        if transport not in TRANSPORTS:
            raise ValueError(f"x-IMU3 transport {transport!r}: expected one of {', '.join(TRANSPORTS)}")
        if not sensors:
            raise ValueError("x-IMU3: name the devices, NAME=PORT each (e.g. --ximu3-sensor pelvis=7000)")
        if rate <= 0:
            raise ValueError(f"x-IMU3: the device rate must be positive, got {rate}")
        self.ports, self.rate, self.host = dict(sensors), float(rate), host
        self.transport, self.window, self.timeout = transport, window, timeout
        self.sensors = tuple(SensorInfo(n, "imu", n if n in known_sites() else None, self.rate, **CONVENTIONS)
                             for n in self.ports)
        self.timeout_frames = max(window + 1, int(round(2.0 * self.rate)))
        self._conns: list[Any] = []
        self._loop: asyncio.AbstractEventLoop | None = None
        self._half: list[dict[int, dict[str, np.ndarray]]] = [{} for _ in self.sensors]  # ts_us -> I / Q
        self._t0: float | None = None
        self._offset: list[float | None] = [None] * len(self.sensors)  # s added to a device's clock
        self._first: list[float | None] = [None] * len(self.sensors)
        self._pending: dict[int, dict[str, Any]] = {}
        self._done_below: int | None = None
        self._newest = [-1] * len(self.sensors)
        self.counts.update(messages=0, unpaired=0, late=0, receive_errors=0)

    # ----------------------------------------------------------------- connections
    def _config(self, port: int) -> Any:
        x = _ximu3()
        if self.transport == "tcp":
            return x.TcpConnectionConfig(self.host, int(port))
        return x.UdpConnectionConfig(self.host, int(port), int(port))

    async def open(self) -> None:
        self._loop = asyncio.get_running_loop()
        for j, (name, port) in enumerate(self.ports.items()):
            conn = _ximu3().Connection(self._config(port))
            conn.add_inertial_callback(lambda m, j=j: self._from_thread(self._inertial, j, m.timestamp, (
                m.gyroscope_x, m.gyroscope_y, m.gyroscope_z, m.accelerometer_x, m.accelerometer_y, m.accelerometer_z)))
            conn.add_quaternion_callback(lambda m, j=j: self._from_thread(self._quaternion, j, m.timestamp,
                                                                          (m.w, m.x, m.y, m.z)))
            conn.add_receive_error_callback(lambda e, j=j: self._from_thread(self._receive_error, j, int(e)))
            await self._connect(conn, name, port)
            self._conns.append(conn)

    async def _connect(self, conn: Any, name: str, port: int) -> None:
        """``conn.open()`` (blocking: in a thread), retried until :attr:`timeout`."""
        loop = asyncio.get_running_loop()
        deadline = loop.time() + self.timeout
        while True:
            try:
                await asyncio.to_thread(conn.open)
                return
            except RuntimeError as exc:
                if loop.time() >= deadline:
                    raise ConfigError(f"--input ximu3: device {name!r} at {self.transport}://{self.host}:{port} did not "
                                      f"answer in {self.timeout:g} s ({exc}); check the device's IP and port") from None
                await asyncio.sleep(0.2)

    async def close(self) -> None:
        conns, self._conns = self._conns, []
        for c in conns:
            await asyncio.to_thread(c.close)
        self._loop = None
        for seq in sorted(self._pending):
            self._release(seq)

    def _from_thread(self, fn: Any, *args: Any) -> None:
        # ximu3 calls back on its own thread: hand over to the event loop that owns the state.
        loop = self._loop
        if loop is None:
            return
        try:
            loop.call_soon_threadsafe(fn, *args)
        except RuntimeError:  # the loop closed under a late callback
            pass

    # ----------------------------------------------------------------- messages
    def _receive_error(self, j: int, code: int) -> None:
        self.counts["receive_errors"] += 1
        why = _ximu3().receive_error_to_string(code)
        self.malformed(PacketError(f"x-IMU3 {self.names[j]!r}: {why} (ximu3 receive error)"))

    def _inertial(self, j: int, ts: int, v: Sequence[float]) -> None:
        self.counts["messages"] += 1
        a = np.asarray(v, np.float64)
        if not np.isfinite(a).all():
            self.malformed(PacketError(f"x-IMU3 {self.names[j]!r} inertial {ts}: non-finite values"))
            return
        self._half_sample(j, int(ts), "I", a)

    def _quaternion(self, j: int, ts: int, q: Sequence[float]) -> None:
        self.counts["messages"] += 1
        try:
            quaternion_norm_check(q, "wxyz", f"x-IMU3 {self.names[j]!r} quaternion {ts}")
        except PacketError as exc:
            self.malformed(exc)
            return
        self._half_sample(j, int(ts), "Q", np.asarray(q, np.float64))

    def _half_sample(self, j: int, ts: int, key: str, value: np.ndarray) -> None:
        half = self._half[j]
        got = half.setdefault(ts, {})
        if key in got:
            self.counts["unpaired"] += 1  # a second message of one kind with one timestamp
        got[key] = value
        if len(got) == 2:
            del half[ts]
            for old in [t for t in half if t < ts]:  # the twin of an older message never came
                self.counts["unpaired"] += len(half.pop(old))
            self._sample(j, ts / 1e6, got)

    def _sample(self, j: int, t: float, got: dict[str, np.ndarray]) -> None:
        if self._offset[j] is None:
            others = [f + (o or 0.0) for f, o in zip(self._first, self._offset) if f is not None]
            newest = None if self._t0 is None else self._t0 + max(self._newest) / self.rate
            self._first[j] = t
            self._offset[j] = 0.0 if not others or abs(t - min(others)) <= ONE_CLOCK_S or newest is None \
                else newest - t
        t = t + float(self._offset[j])
        if self._t0 is None:
            self._t0 = t
        seq = int(round((t - self._t0) * self.rate))
        if seq < 0 or (seq not in self._pending and self._done_below is not None and seq < self._done_below):
            self.counts["late"] += 1
            return
        f = self._pending.setdefault(seq, {"t": t, "values": {}})
        f["values"][j] = got
        self._newest[j] = max(self._newest[j], seq)
        self._flush()

    # ----------------------------------------------------------------- frames
    def _flush(self) -> None:
        newest = max(self._newest)
        S = len(self.sensors)
        for seq in sorted(self._pending):  # in order: a frame waits for the ones before it
            f = self._pending[seq]
            if not (all(j in f["values"] or self._newest[j] - seq >= self.window for j in range(S))
                    or newest - seq >= self.timeout_frames):
                break
            self._release(seq)

    def _release(self, seq: int) -> None:
        f = self._pending.pop(seq)
        S = len(self.sensors)
        valid = np.array([j in f["values"] for j in range(S)])
        ori = np.full((S, 3, 3), np.nan)
        acc = np.full((S, 3), np.nan)
        gyro = np.full((S, 3), np.nan)
        idx = [j for j in range(S) if valid[j]]
        if idx:
            ori[idx] = quaternion_matrices(np.stack([f["values"][j]["Q"] for j in idx]), "wxyz", "x-IMU3")
            for j in idx:
                gyro[j], acc[j] = f["values"][j]["I"][:3], f["values"][j]["I"][3:]
        self._done_below = seq + 1 if self._done_below is None else max(self._done_below, seq + 1)
        self.emit(DeviceFrame(seq & 0xFFFFFFFF, f["t"], valid,
                              {"orientation": ori, "acceleration": acc, "angular_velocity": gyro}))


# --------------------------------------------------------------------------- wire format
def encode_message(ident: str, timestamp_us: int, args: Sequence[float], fmt: str = "binary") -> bytes:
    """One x-IMU3 data message (module doc): ``ident`` ``"I"`` / ``"Q"``..., timestamp in
    microseconds, float arguments; ``fmt`` ``binary`` (float32, byte-stuffed, LF) or ``ascii``
    (four decimals, CR LF)."""
    if fmt == "ascii":
        return (",".join([ident, str(int(timestamp_us))] + [f"{float(a):.4f}" for a in args]) + "\r\n").encode()
    if fmt != "binary":
        raise ValueError(f"x-IMU3 message format {fmt!r}: expected one of {', '.join(FORMATS)}")
    raw = bytes([0x80 + ord(ident)]) + struct.pack(f"<Q{len(args)}f", int(timestamp_us), *args)
    out = bytearray()
    for b in raw:
        if b == END:
            out += bytes([ESC, ESC_END])
        elif b == ESC:
            out += bytes([ESC, ESC_ESC])
        else:
            out.append(b)
    out.append(END)
    return bytes(out)


def malformed_message(kind: int, timestamp_us: int, q: Sequence[float], fmt: str) -> bytes:
    """One message that does not follow the protocol (the emulator's faults; each is one error):
    0 an unknown identifier, 1 an ASCII inertial message with a word for a number, 2 a binary
    inertial message two floats short, 3 a quaternion of norm 2 (``ximu3`` parses it; the input
    refuses it)."""
    if kind == 0:
        return f"Z,{int(timestamp_us)},1.0000\r\n".encode()
    if kind == 1:
        return f"I,{int(timestamp_us)},abc,0.0000,0.0000,0.0000,0.0000,1.0000\r\n".encode()
    if kind == 2:
        return encode_message("I", timestamp_us, [0.0, 0.0, 0.0, 1.0], "binary")
    return encode_message("Q", timestamp_us, [2.0 * float(x) for x in q], fmt)


# --------------------------------------------------------------------------- the emulator
async def emulate_ximu3(recording: Any, host: str = "127.0.0.1", port: int = 7000, ports: Mapping[str, int] | None = None,
                        *, transport: str = "tcp", fmt: str = "binary", faults: Any = None, speed: float = 1.0,
                        realtime: bool = True, duration: float | None = None, epoch_us: int = 917_000_000,
                        connect_timeout: float = 120.0) -> dict[str, Any]:
    """Play ``recording`` as x-IMU3 devices: per frame and sensor an inertial and a quaternion
    message with the frame's timestamp (``epoch_us`` + t, microseconds), in ``fmt``. ``tcp``:
    each device listens on ``host:ports[name]`` (default ``port + i``) and plays once every
    device has a connection (waiting up to ``connect_timeout``); ``udp``: each device sends one
    datagram per message to ``host:ports[name]``."""
    if transport not in TRANSPORTS:
        raise ValueError(f"x-IMU3 transport {transport!r}: expected one of {', '.join(TRANSPORTS)}")
    if fmt not in FORMATS:
        raise ValueError(f"x-IMU3 message format {fmt!r}: expected one of {', '.join(FORMATS)}")
    d = device_data(recording, **CONVENTIONS)
    names, T = d.names, len(d.timestamps)
    N = T if duration is None else max(1, int(round(duration * d.rate)))
    ports = dict(ports or {n: port + i for i, n in enumerate(names)})
    missing = [n for n in names if n not in ports]
    if missing:
        raise ValueError(f"x-IMU3 emulator: no port for sensor(s) {missing} (give NAME=PORT for every sensor)")
    quat = matrix_to_quat(torch.from_numpy(np.ascontiguousarray(d.channels["orientation"]))).numpy()
    zeros = np.zeros((T, len(names), 3))
    gyro = np.nan_to_num(d.channels.get("angular_velocity", zeros))
    acc = np.nan_to_num(d.channels.get("acceleration", zeros))
    links = await _links(transport, host, {n: ports[n] for n in names}, connect_timeout)

    def ts_of(k: int) -> int:
        return int(epoch_us + round((float(d.timestamps[0]) + k / d.rate) * 1e6))

    async def send(k: int, valid: np.ndarray) -> None:
        i, ts = k % T, ts_of(k)
        for j, n in enumerate(names):
            if valid[j] and d.valid[i, j]:
                links[n].write(encode_message("I", ts, [*gyro[i, j], *acc[i, j]], fmt))
                links[n].write(encode_message("Q", ts, quat[i, j].tolist(), fmt))
        await _drain(links)

    async def bad(k: int, rng: np.random.Generator) -> None:
        j = int(rng.integers(0, len(names)))
        links[names[j]].write(malformed_message(int(rng.integers(0, 4)), ts_of(k), quat[k % T, j].tolist(), fmt))
        await _drain(links)

    try:
        res = await play(N, len(names), d.rate, send, bad, faults, speed, realtime,
                         base_valid=np.stack([d.valid[k % T] for k in range(N)]))
        await asyncio.sleep(0.2)  # let the last bytes leave before the device hangs up
    finally:
        for link in links.values():
            link.close()
    target = ", ".join(f"{n}={transport}://{host}:{ports[n]}" for n in names)
    return {"input": "ximu3", "transport": transport, "format": fmt, "target": target, "rate_hz": d.rate,
            "sensors": list(names), **res.to_dict()}


class _UdpLink:
    def __init__(self, host: str, port: int) -> None:
        self.sender = UdpSender(host, port)

    def write(self, data: bytes) -> None:
        self.sender.send(data)  # one datagram per message

    async def drain(self) -> None:
        pass

    def close(self) -> None:
        self.sender.close()


class _TcpLink:
    def __init__(self, writer: asyncio.StreamWriter, server: asyncio.AbstractServer) -> None:
        self.writer, self.server = writer, server

    def write(self, data: bytes) -> None:
        if not self.writer.is_closing():
            self.writer.write(data)

    async def drain(self) -> None:
        try:
            await self.writer.drain()
        except (ConnectionError, OSError):  # the host hung up: a device keeps running regardless
            pass

    def close(self) -> None:
        self.writer.close()
        self.server.close()


async def _links(transport: str, host: str, ports: dict[str, int], timeout: float) -> dict[str, Any]:
    """Per device a writable link: a UDP sender, or the accepted TCP connection of a server the
    device runs on ``host:port`` (waits for every device's connection)."""
    if transport == "udp":
        return {n: _UdpLink(host, p) for n, p in ports.items()}
    accepted: dict[str, asyncio.Future] = {n: asyncio.get_running_loop().create_future() for n in ports}
    servers = {}
    for n, p in ports.items():
        def on_client(reader: asyncio.StreamReader, writer: asyncio.StreamWriter, n: str = n) -> None:
            if accepted[n].done():  # one host per device: a second connection is refused
                writer.close()
            else:
                accepted[n].set_result(writer)
        servers[n] = await asyncio.start_server(on_client, host, p)
    try:
        await asyncio.wait_for(asyncio.gather(*accepted.values()), timeout)
    except asyncio.TimeoutError:
        for s in servers.values():
            s.close()
        waiting = [n for n, f in accepted.items() if not f.done()]
        raise TimeoutError(f"x-IMU3 emulator: no connection to {waiting} within {timeout:g} s "
                           "(start wearpose serve --input ximu3)") from None
    return {n: _TcpLink(accepted[n].result(), servers[n]) for n in ports}


async def _drain(links: dict[str, Any]) -> None:
    for link in links.values():
        await link.drain()

