"""OSC (Open Sound Control over UDP) input with a YAML address map per device profile, and
its loopback emulator.

A profile (``profiles/*.yaml``; ``ngimu`` and ``generic`` ship, any file path works) names the
OSC messages that make a sensor frame: per message its address (``{sensor}`` stands for the
sensor's name in ``devices: address`` profiles), its argument count and, per channel, the first
argument, the unit, the frame, gravity and the quaternion order. Those become the sensor's
declared :class:`~wearpose.recording.SensorInfo`, converted by ``Recording.to_canonical``.

Frames are identified by the OSC **bundle time tag** (NTP format, the device's clock; the NGIMU
time-tags every bundle): the sequence number is ``round((t - t_first) * rate)``. A sensor's
frame is complete when every message of the profile has arrived for that time tag; a frame is
handed on when every sensor is complete, or -- with the missing sensors masked -- once each
missing sensor has sent a frame ``window`` frames newer (or 2 s of frames have passed: a device
that stopped). A message outside a bundle, with the wrong number
or type of arguments, or a quaternion that is not unit-norm, is malformed (counted); messages
the profile does not name (``/battery``, ``/temperature``...) are ignored (counted).
"""

from __future__ import annotations

import asyncio
import re
import struct
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np
import torch
import yaml
from pythonosc.osc_bundle import OscBundle
from pythonosc.osc_message import OscMessage
from pythonosc.osc_message_builder import OscMessageBuilder

from wearpose.errors import InputFileError
from wearpose.geometry import matrix_to_quat
from wearpose.recording import SensorInfo
from wearpose.recording.types import known_sites
from wearpose.stream.inputs.base import DeviceFrame, LiveInput, drain_udp, quaternion_matrices, quaternion_norm_check, udp_socket
from wearpose.stream.inputs.emulate import UdpSender, device_data, play
from wearpose.stream.packets import PacketError

PROFILE_DIR = Path(__file__).parent / "profiles"
#: Seconds between the NTP epoch (1900) and the Unix epoch (1970).
NTP_UNIX = 2208988800
_UNITS = {"acceleration": ("m/s2", "g"), "angular_velocity": ("rad/s", "deg/s"), "position": ("m", "cm", "mm")}
_FLOATS = {"orientation": 4, "acceleration": 3, "angular_velocity": 3, "magnetic_field": 3, "position": 3}


@dataclass(frozen=True)
class ChannelMap:
    channel: str
    start: int
    unit: str | None = None
    frame: str | None = None
    gravity: str | None = None
    quaternion: str = "wxyz"


@dataclass(frozen=True)
class OscProfile:
    """A parsed address map (module doc). ``messages``: address pattern -> (args, channel maps)."""

    name: str
    path: Path
    devices: str
    kind: str
    world_up: str
    messages: dict[str, tuple[int, tuple[ChannelMap, ...]]]

    def conventions(self) -> dict[str, str]:
        """The declared conventions (``Recording.declared_as`` arguments) of data read with this profile."""
        conv = {"world_up": self.world_up}
        for _, maps in self.messages.values():
            for m in maps:
                if m.channel == "acceleration":
                    conv.update(acc_unit=m.unit, acc_frame=m.frame, acc_gravity=m.gravity)
                elif m.channel == "angular_velocity":
                    conv["gyro_unit"] = m.unit
                elif m.channel == "position":
                    conv["position_unit"] = m.unit
        return conv

    def sensor_info(self, name: str, rate: float) -> SensorInfo:
        """The declared conventions of one sensor read with this profile."""
        mag = [m.unit for _, maps in self.messages.values() for m in maps if m.channel == "magnetic_field" and m.unit]
        extra = {"mag_unit": mag[0]} if mag else {}
        return SensorInfo(name, self.kind, name if name in known_sites() else None, rate, **self.conventions(), **extra)

    def address(self, pattern: str, sensor: str) -> str:
        return pattern.replace("{sensor}", sensor)


def load_profile(name_or_path: str | Path) -> OscProfile:
    """A shipped profile by name (``ngimu``, ``generic``) or a YAML file; InputFileError naming
    the file, the field and the fix when it does not follow the format."""
    p = Path(name_or_path)
    if not p.suffix and (PROFILE_DIR / f"{name_or_path}.yaml").is_file():
        p = PROFILE_DIR / f"{name_or_path}.yaml"
    if not p.is_file():
        shipped = ", ".join(sorted(x.stem for x in PROFILE_DIR.glob("*.yaml")))
        raise InputFileError(p, "no such OSC profile", f"a shipped profile name ({shipped}) or a YAML file path")
    try:
        d = yaml.safe_load(p.read_text())
    except yaml.YAMLError as exc:
        raise InputFileError(p, f"not YAML ({exc})", "a YAML mapping as in profiles/generic.yaml") from None

    def need(ok: bool, field: str, problem: str, expected: str) -> None:
        if not ok:
            raise InputFileError(p, problem, expected, field)

    need(isinstance(d, dict), "(top)", "not a mapping", "keys profile, devices, timestamp, kind, world_up, messages")
    devices, kind, up = d.get("devices", "address"), d.get("kind", "imu"), d.get("world_up", "y_up")
    need(devices in ("port", "address"), "devices", f"{devices!r}", "'port' (one UDP port per sensor) or 'address'")
    need(d.get("timestamp", "bundle") == "bundle", "timestamp", f"{d.get('timestamp')!r}", "'bundle' (OSC time tags)")
    need(kind in ("imu", "mimu", "em6dof", "vio"), "kind", f"{kind!r}", "imu, mimu, em6dof or vio")
    need(up in ("y_up", "z_up"), "world_up", f"{up!r}", "y_up or z_up")
    msgs = d.get("messages")
    need(isinstance(msgs, dict) and msgs, "messages", "missing or empty", "a mapping of OSC address -> {args, channels}")
    out: dict[str, tuple[int, tuple[ChannelMap, ...]]] = {}
    for addr, spec in msgs.items():
        f = f"messages/{addr}"
        need(isinstance(addr, str) and addr.startswith("/"), f, "address does not start with '/'", "an OSC address")
        need(devices == "port" or "{sensor}" in addr, f, "no {sensor} in the address", "with devices: address, "
             "every address names the sensor, e.g. /{sensor}/quaternion")
        need(isinstance(spec, dict) and isinstance(spec.get("args"), int) and spec["args"] > 0, f"{f}/args",
             f"{spec.get('args') if isinstance(spec, dict) else spec!r}", "the number of arguments, a positive integer")
        chans = spec.get("channels")
        need(isinstance(chans, dict) and chans, f"{f}/channels", "missing", "channel -> {from, unit, ...}")
        maps = []
        for ch, m in chans.items():
            g = f"{f}/channels/{ch}"
            need(ch in _FLOATS, g, f"unknown channel {ch!r}", f"one of {sorted(_FLOATS)}")
            need(isinstance(m, dict) and isinstance(m.get("from"), int), g + "/from", "missing", "the index of the first argument")
            need(0 <= m["from"] and m["from"] + _FLOATS[ch] <= spec["args"], g + "/from",
                 f"{m['from']} + {_FLOATS[ch]} values beyond {spec['args']} arguments", "an index inside the arguments")
            unit = m.get("unit")
            if ch in _UNITS:
                need(unit in _UNITS[ch], g + "/unit", f"{unit!r}", f"one of {list(_UNITS[ch])}")
            cm = ChannelMap(ch, m["from"], unit, m.get("frame", "world" if ch == "acceleration" else None),
                            m.get("gravity", "removed" if ch == "acceleration" else None), m.get("quaternion", "wxyz"))
            if ch == "acceleration":
                need(cm.frame in ("world", "sensor"), g + "/frame", f"{cm.frame!r}", "world or sensor")
                need(cm.gravity in ("removed", "included"), g + "/gravity", f"{cm.gravity!r}", "removed or included")
            if ch == "orientation":
                need(cm.quaternion in ("wxyz", "xyzw"), g + "/quaternion", f"{cm.quaternion!r}", "wxyz or xyzw")
            maps.append(cm)
        out[addr] = (spec["args"], tuple(maps))
    return OscProfile(str(d.get("profile", p.stem)), p, devices, kind, up, out)


# ------------------------------------------------------------------------- bundles
def encode_bundle(time_s: float, messages: Sequence[tuple[str, Sequence[float]]]) -> bytes:
    """An OSC bundle with time tag ``time_s`` (seconds since the Unix epoch, as NTP) holding
    float32 messages ``(address, args)``."""
    ntp = time_s + NTP_UNIX
    sec = int(ntp)
    frac = min(int(round((ntp - sec) * 2 ** 32)), 2 ** 32 - 1)
    parts = [b"#bundle\x00", struct.pack(">II", sec, frac)]
    for addr, args in messages:
        b = OscMessageBuilder(addr)
        for a in args:
            b.add_arg(float(a), "f")
        dg = b.build().dgram
        parts += [struct.pack(">i", len(dg)), dg]
    return b"".join(parts)


def decode_bundle(data: bytes) -> tuple[float, list[tuple[str, list[Any]]]]:
    """A bundle's time tag (s, Unix epoch) and its messages; PacketError for anything else."""
    if not data.startswith(b"#bundle\x00") or len(data) < 16:
        raise PacketError("OSC datagram: not a time-tagged bundle (the profile identifies frames by bundle time tags)")
    sec, frac = struct.unpack_from(">II", data, 8)
    i = 16
    if i == len(data):
        raise PacketError("OSC bundle: empty (a time tag and no message)")
    while i < len(data):  # OSC 1.0: elements of (int32 size, content) that exactly fill the bundle
        size = struct.unpack_from(">i", data, i)[0] if i + 4 <= len(data) else -1
        if size <= 0 or size % 4 or i + 4 + size > len(data) or data[i + 4:i + 5] not in (b"/", b"#"):
            raise PacketError(f"OSC bundle: element at byte {i} is not a size-prefixed message or bundle")
        i += 4 + size
    try:
        bundle = OscBundle(data)
        msgs = [(c.address, list(c.params)) for c in bundle if isinstance(c, OscMessage)]
    except Exception as exc:  # noqa: BLE001 - python-osc raises several types on garbage
        raise PacketError(f"OSC bundle does not parse: {str(exc)[:80]}") from None
    return sec - NTP_UNIX + frac / 2 ** 32, msgs


# ------------------------------------------------------------------------- the input
class OscInput(LiveInput):
    """Listens for OSC bundles on UDP.

    Args:
        profile: a shipped profile name or a YAML path (module doc).
        sensors: ``devices: port`` profiles: sensor name -> UDP port; ``devices: address``:
            sensor names (all on ``port``).
        rate: the devices' send rate, Hz (frames are on this grid).
        host: interface to listen on.
        port: the one port of ``devices: address`` profiles.
        window: frames a sensor's own stream must have moved past a frame it did not send for it
            to count as missing there (a device silent for 2 s releases the frames it holds).
    """

    name = "osc"

    def __init__(self, profile: str | Path, sensors: Mapping[str, int] | Sequence[str], rate: float,
                 host: str = "127.0.0.1", port: int = 9000, window: int = 2) -> None:
        super().__init__()
        self.profile = load_profile(profile)
        if self.profile.devices == "port":
            if not isinstance(sensors, Mapping) or not sensors:
                raise ValueError(f"OSC profile {self.profile.name!r} has one UDP port per device: give sensors as "
                                 "name=port (e.g. --osc-sensor pelvis=9000)")
            self.ports = dict(sensors)
        else:
            self.ports = {n: port for n in sensors}
        self.host, self.rate, self.window = host, float(rate), window
        self.sensors = tuple(self.profile.sensor_info(n, self.rate) for n in self.ports)
        self._addr = {self.profile.address(a, n): (j, a) for j, n in enumerate(self.ports)
                      for a in self.profile.messages}
        self._t0: float | None = None
        self._pending: dict[int, dict[str, Any]] = {}
        self._done_below: int | None = None  # frames below this were handed on
        self._newest = [-1] * len(self.sensors)  # per sensor: the newest frame it sent
        self.timeout_frames = max(window + 1, int(round(2.0 * self.rate)))  # 2 s
        self._transports: list[Any] = []
        self.counts.update(bundles=0, late=0)

    async def open(self) -> None:
        loop = asyncio.get_running_loop()
        for port in sorted(set(self.ports.values())):
            names = [n for n, p in self.ports.items() if p == port]
            sock = udp_socket(self.host, port)
            tr, _ = await loop.create_datagram_endpoint(lambda names=names: _Protocol(self, names), sock=sock)
            self._transports.append((tr, sock, names))

    async def close(self) -> None:
        for tr, sock, names in self._transports:
            drain_udp(sock, lambda data, names=names: self.datagram(data, names))
            tr.close()
        for seq in sorted(self._pending):
            self._release(seq)

    def datagram(self, data: bytes, names: Sequence[str]) -> None:
        try:
            t, msgs = decode_bundle(data)
            self.counts["bundles"] += 1
            self._bundle(t, msgs, names)
        except PacketError as exc:
            self.malformed(exc)

    def _bundle(self, t: float, msgs: list[tuple[str, list[Any]]], names: Sequence[str]) -> None:
        parsed = []
        for addr, args in msgs:
            key = self._lookup(addr, names)
            if key is None:
                self.counts["ignored"] += 1
                continue
            j, pattern = key
            nargs, maps = self.profile.messages[pattern]
            if len(args) != nargs or not all(isinstance(a, (int, float)) and not isinstance(a, bool) for a in args):
                raise PacketError(f"OSC {addr}: {len(args)} arguments {str(args)[:60]}, expected {nargs} numbers "
                                  f"(profile {self.profile.name})")
            vals = {}
            for m in maps:
                a = np.asarray(args[m.start:m.start + _FLOATS[m.channel]], np.float64)
                if m.channel == "orientation":  # checked now, turned into a matrix with the frame's others
                    quaternion_norm_check(a, m.quaternion, f"OSC {addr}")
                    vals[m.channel] = a if m.quaternion == "wxyz" else a[[3, 0, 1, 2]]
                elif not np.isfinite(a).all():
                    raise PacketError(f"OSC {addr}: non-finite {m.channel}")
                else:
                    vals[m.channel] = a
            parsed.append((j, pattern, vals))
        if not parsed:
            return
        if self._t0 is None:
            self._t0 = t
        seq = int(round((t - self._t0) * self.rate))
        if seq < 0 or (seq not in self._pending and self._done_below is not None and seq < self._done_below):
            self.counts["late"] += 1  # its frame was handed on already (masked there)
            return
        f = self._pending.setdefault(seq, {"t": t, "got": {}, "values": {}})
        for j, pattern, vals in parsed:
            f["got"].setdefault(j, set()).add(pattern)
            f["values"].setdefault(j, {}).update(vals)
            self._newest[j] = max(self._newest[j], seq)
        self._flush()

    def _lookup(self, addr: str, names: Sequence[str]) -> tuple[int, str] | None:
        key = self._addr.get(addr)
        if key is None:
            return None
        if self.profile.devices == "port" and self.names[key[0]] not in names:
            # a /quaternion on one device's port belongs to that device
            for j, n in enumerate(self.names):
                if n in names:
                    return j, key[1]
            return None
        return key

    def _complete(self, f: dict[str, Any]) -> bool:
        want = set(self.profile.messages)
        return len(f["got"]) == len(self.sensors) and all(g == want for g in f["got"].values())

    def _flush(self) -> None:
        # A sensor is missing from a frame once *its own* stream has moved `window` frames past
        # it (each device has its own socket, drained at its own pace when the server is busy);
        # a device that stopped altogether holds frames at most `timeout_frames`.
        newest = max(self._newest)
        want = set(self.profile.messages)
        for seq in sorted(self._pending):
            f = self._pending[seq]
            if all(f["got"].get(j) == want or self._newest[j] - seq >= self.window for j in range(len(self.sensors))) \
                    or newest - seq >= self.timeout_frames:
                self._release(seq)

    def _release(self, seq: int) -> None:
        f = self._pending.pop(seq)
        S = len(self.sensors)
        want = set(self.profile.messages)
        valid = np.array([f["got"].get(j) == want for j in range(S)])
        chans: dict[str, np.ndarray] = {}
        for _, maps in self.profile.messages.values():
            for m in maps:
                shape = (S, 3, 3) if m.channel == "orientation" else (S, _FLOATS[m.channel])
                chans[m.channel] = np.full(shape, np.nan)
        quats = {}
        for j in range(S):
            if valid[j]:
                for c, v in f["values"][j].items():
                    if c == "orientation":
                        quats[j] = v
                    else:
                        chans[c][j] = v
        if quats:
            chans["orientation"][list(quats)] = quaternion_matrices(np.stack(list(quats.values())), "wxyz", "OSC")
        self._done_below = seq + 1 if self._done_below is None else max(self._done_below, seq + 1)
        self.emit(DeviceFrame(seq & 0xFFFFFFFF, f["t"], valid, chans))


class _Protocol(asyncio.DatagramProtocol):
    def __init__(self, owner: OscInput, names: Sequence[str]) -> None:
        self.owner, self.names = owner, names

    def datagram_received(self, data: bytes, addr: Any) -> None:
        self.owner.datagram(data, self.names)


# ------------------------------------------------------------------------- the emulator
async def emulate_osc(recording: Any, profile: str | Path = "generic", host: str = "127.0.0.1", port: int = 9000,
                      ports: Mapping[str, int] | None = None, *, faults: Any = None, speed: float = 1.0,
                      realtime: bool = True, duration: float | None = None, epoch: float = 1.8e9) -> dict[str, Any]:
    """Play ``recording`` as OSC devices of ``profile``: per frame and sensor one bundle
    (time tag ``epoch + t``) with every message of the profile; ``devices: port`` profiles send
    sensor ``i`` to ``ports[name]`` (default ``port + i``). Arguments the profile does not map
    (e.g. the NGIMU's accelerometer and barometer in ``/sensors``) carry the sensor's
    accelerometer reading (g, gravity included) and 1013.25 hPa."""
    prof = load_profile(profile)
    d = device_data(recording, **prof.conventions())
    raw = device_data(recording, acc_unit="g", acc_frame="sensor", acc_gravity="included", world_up=prof.world_up)
    names, T = d.names, len(d.timestamps)
    N = T if duration is None else max(1, int(round(duration * d.rate)))
    if prof.devices == "port":
        ports = dict(ports or {n: port + i for i, n in enumerate(names)})
        socks = {n: UdpSender(host, ports[n]) for n in names}
    else:
        one = UdpSender(host, port)
        socks = {n: one for n in names}
    quat = matrix_to_quat(torch.from_numpy(np.ascontiguousarray(d.channels["orientation"]))).numpy()

    def args_of(pattern: str, i: int, j: int) -> list[float]:
        nargs, maps = prof.messages[pattern]
        a = np.zeros(nargs)
        if pattern.endswith("/sensors") and nargs == 10:  # NGIMU layout: raw accelerometer, barometer
            acc = raw.channels.get("acceleration")
            a[3:6] = 0.0 if acc is None else np.nan_to_num(acc[i, j])
            a[9] = 1013.25
        for m in maps:
            if m.channel == "orientation":
                q = quat[i, j]
                a[m.start:m.start + 4] = q if m.quaternion == "wxyz" else q[[1, 2, 3, 0]]
            else:
                v = d.channels.get(m.channel)
                a[m.start:m.start + 3] = 0.0 if v is None else np.nan_to_num(v[i, j])
        return a.tolist()

    def send(k: int, valid: np.ndarray) -> None:
        i = k % T
        t = epoch + float(d.timestamps[0]) + k / d.rate
        for j, n in enumerate(names):
            if valid[j] and d.valid[i, j]:
                socks[n].send(encode_bundle(t, [(prof.address(p, n), args_of(p, i, j)) for p in prof.messages]))

    def bad(k: int, rng: np.random.Generator) -> None:
        i, j = k % T, int(rng.integers(0, len(names)))
        n = names[j]
        t = epoch + float(d.timestamps[0]) + k / d.rate
        pattern = list(prof.messages)[0]
        kind = int(rng.integers(0, 4))
        if kind == 0:
            msg = b"#bundle\x00" + bytes(rng.integers(0, 256, 12, dtype=np.uint8))  # garbage after the tag
        elif kind == 1:  # a message outside a bundle
            b = OscMessageBuilder(prof.address(pattern, n))
            b.add_arg(1.0, "f")
            msg = b.build().dgram
        elif kind == 2:  # too few arguments
            msg = encode_bundle(t, [(prof.address(pattern, n), args_of(pattern, i, j)[:-1])])
        else:  # a quaternion of norm 2 (or a scaled first message)
            msg = encode_bundle(t, [(prof.address(pattern, n), [2 * x for x in args_of(pattern, i, j)])])
        socks[n].send(msg)

    try:
        res = await play(N, len(names), d.rate, send, bad, faults, speed, realtime,
                         base_valid=np.stack([d.valid[k % T] for k in range(N)]))
    finally:
        for s in set(socks.values()):
            s.close()
    target = f"udp://{host}:{port}" if prof.devices == "address" else \
        ", ".join(f"{n}=udp://{host}:{p}" for n, p in ports.items())
    return {"input": "osc", "profile": prof.name, "target": target, "rate_hz": d.rate, "sensors": list(names),
            **res.to_dict()}


def parse_sensor_ports(items: Sequence[str]) -> dict[str, int] | list[str]:
    """``--osc-sensor`` values: ``NAME=PORT`` each (a dict) or ``NAME`` each (a list); ValueError
    naming the item otherwise."""
    if all("=" in x for x in items):
        out: dict[str, int] = {}
        for x in items:
            name, _, port = x.partition("=")
            if not port.isdigit() or not 0 < int(port) < 65536:
                raise ValueError(f"--osc-sensor {x!r}: expected NAME=PORT with a UDP port 1..65535")
            out[name] = int(port)
        return out
    if any("=" in x for x in items):
        raise ValueError("--osc-sensor: give every sensor as NAME=PORT (one port per device) or every one as NAME")
    return list(items)
