"""Lab Streaming Layer (LSL) input, its loopback emulator and the loopback liblsl configuration.

**Layout of a sensor stream** (one LSL stream carries every sensor; ``channel_format`` float32
or double; ``nominal_srate`` = the frame rate): each channel's metadata in
``desc/channels/channel`` names sensor, quantity and unit:

- ``label``: ``SENSOR:COMPONENT``, e.g. ``left_forearm:qw``. Components: ``px py pz``
  (position), ``qw qx qy qz`` (orientation quaternion, any channel order: the labels say which
  is which), ``ax ay az`` (acceleration), ``gx gy gz`` (angular velocity), ``mx my mz``
  (magnetic field).
- ``type``: ``Position``, ``Orientation``, ``Acceleration``, ``AngularVelocity``, ``MagneticField``.
- ``unit``: ``m`` / ``cm`` / ``mm``; ``quaternion`` (unit quaternion); ``m/s^2`` / ``g``;
  ``rad/s`` / ``deg/s``; any text for the magnetic field.

Optional per-sensor facts in ``desc/sensors/sensor`` (``name``, ``kind``, ``site``,
``acc_frame`` world|sensor, ``acc_gravity`` removed|included, ``world_up`` y_up|z_up,
``reference`` source|world); defaults: kind from the channels (position + orientation:
``em6dof``; orientation + acceleration: ``imu``), world-frame free acceleration, Y up. A sensor
whose values are all NaN in a sample is missing in that frame (masked); a sample with some NaN
of one sensor, or a quaternion that is not unit-norm, is malformed (counted).

**Time.** The LSL time stamp of each sample is kept as the frame's time stamp (the sender's
clock, as pushed); the sequence number is ``round((t - t_first) * nominal_srate)``.

**Network.** liblsl reads its configuration from the file named by ``LSLAPICFG``.
:func:`write_loopback_config` writes one that keeps LSL on this machine (``ResolveScope =
machine``, ``KnownPeers = {127.0.0.1}``, ``IPv6 = disable``); the tests set it before pylsl loads
liblsl, and ``wearpose serve`` / ``wearpose stream emulate`` take ``--lsl-loopback``.
"""

from __future__ import annotations

import asyncio
import math
import os
import threading
from pathlib import Path
from typing import Any, Sequence

import numpy as np
import pylsl
import torch
from pylsl.util import LostError

from wearpose.geometry import matrix_to_quat
from wearpose.recording import SensorInfo
from wearpose.recording.types import known_sites
from wearpose.stream.inputs.base import DeviceFrame, LiveInput, quaternion_matrices, quaternion_norm_check
from wearpose.stream.inputs.emulate import device_data, play
from wearpose.stream.packets import PacketError

COMPONENTS: dict[str, tuple[str, str]] = {  # component -> (channel, LSL channel type)
    "px": ("position", "Position"), "py": ("position", "Position"), "pz": ("position", "Position"),
    "qw": ("orientation", "Orientation"), "qx": ("orientation", "Orientation"),
    "qy": ("orientation", "Orientation"), "qz": ("orientation", "Orientation"),
    "ax": ("acceleration", "Acceleration"), "ay": ("acceleration", "Acceleration"), "az": ("acceleration", "Acceleration"),
    "gx": ("angular_velocity", "AngularVelocity"), "gy": ("angular_velocity", "AngularVelocity"),
    "gz": ("angular_velocity", "AngularVelocity"),
    "mx": ("magnetic_field", "MagneticField"), "my": ("magnetic_field", "MagneticField"),
    "mz": ("magnetic_field", "MagneticField"),
}
_ORDER = {"position": ("px", "py", "pz"), "orientation": ("qw", "qx", "qy", "qz"), "acceleration": ("ax", "ay", "az"),
          "angular_velocity": ("gx", "gy", "gz"), "magnetic_field": ("mx", "my", "mz")}
_UNITS = {"position": {"m": "m", "cm": "cm", "mm": "mm"}, "orientation": {"quaternion": None, "normalized": None},
          "acceleration": {"m/s^2": "m/s2", "m/s2": "m/s2", "g": "g"},
          "angular_velocity": {"rad/s": "rad/s", "deg/s": "deg/s"}}
LOOPBACK_CONFIG = """; liblsl configuration written by wearpose: LSL stays on this machine
[ports]
IPv6 = disable
[multicast]
ResolveScope = machine
[lab]
KnownPeers = {127.0.0.1}
"""


def write_loopback_config(path: str | Path, set_env: bool = True) -> Path:
    """Write the loopback liblsl configuration to ``path`` and (``set_env``) point ``LSLAPICFG``
    at it. Must happen before liblsl reads its configuration (the first LSL call of the process)."""
    p = Path(path)
    p.write_text(LOOPBACK_CONFIG)
    if set_env:
        os.environ["LSLAPICFG"] = str(p)
    return p


def _pylsl() -> Any:
    return pylsl


# ------------------------------------------------------------------------- layout
def layout_from_info(info: Any, rate: float | None = None) -> tuple[tuple[SensorInfo, ...], dict[str, Any]]:
    """Sensors and column map of an LSL stream info (with its ``desc``; module doc). Raises
    PacketError naming the channel and the fix when the metadata does not follow the layout."""
    n = info.channel_count()
    ch = info.desc().child("channels").child("channel")
    cols: dict[str, dict[str, list[tuple[int, str]]]] = {}
    units: dict[tuple[str, str], str] = {}
    for i in range(n):
        if ch.empty():
            raise PacketError(f"LSL stream {info.name()!r}: {n} channels but only {i} desc/channels/channel entries; "
                              "label every channel SENSOR:COMPONENT (docs/devices.md, LSL)")
        label, unit, typ = ch.child_value("label"), ch.child_value("unit"), ch.child_value("type")
        sensor, _, comp = label.rpartition(":")
        if not sensor or comp not in COMPONENTS:
            raise PacketError(f"LSL stream {info.name()!r} channel {i}: label {label!r}, expected SENSOR:COMPONENT with "
                              f"COMPONENT one of {' '.join(COMPONENTS)}")
        channel, want_type = COMPONENTS[comp]
        if typ and typ != want_type:
            raise PacketError(f"LSL stream {info.name()!r} channel {i} ({label}): type {typ!r}, expected {want_type!r}")
        cols.setdefault(sensor, {}).setdefault(channel, []).append((i, comp))
        if channel in _UNITS and unit not in _UNITS[channel]:
            raise PacketError(f"LSL stream {info.name()!r} channel {i} ({label}): unit {unit!r}, expected one of "
                              f"{list(_UNITS[channel])}")
        prev = units.setdefault((sensor, channel), unit)
        if prev != unit:
            raise PacketError(f"LSL stream {info.name()!r} channel {i} ({label}): unit {unit!r} differs from the "
                              f"sensor's other {channel} channels ({prev!r})")
        ch = ch.next_sibling()
    facts: dict[str, dict[str, str]] = {}
    s = info.desc().child("sensors").child("sensor")
    while not s.empty():
        facts[s.child_value("name")] = {k: s.child_value(k) for k in ("kind", "site", "acc_frame", "acc_gravity",
                                                                      "world_up", "reference") if s.child_value(k)}
        s = s.next_sibling()
    r = float(rate or info.nominal_srate())
    if r <= 0:
        raise PacketError(f"LSL stream {info.name()!r}: nominal_srate {info.nominal_srate()} (irregular); give the "
                          "frame rate (--rate)")
    sensors, index = [], {}
    for name, chans in cols.items():
        for c, lst in chans.items():
            if sorted(comp for _, comp in lst) != sorted(_ORDER[c]):
                raise PacketError(f"LSL stream {info.name()!r} sensor {name!r}: {c} has components "
                                  f"{[comp for _, comp in lst]}, expected {list(_ORDER[c])}")
        f = facts.get(name, {})
        kind = f.get("kind") or ("em6dof" if {"position", "orientation"} <= set(chans) and "acceleration" not in chans
                                 else "imu" if {"orientation", "acceleration"} <= set(chans) else "mimu")
        conv: dict[str, Any] = {k: f[k] for k in ("acc_frame", "acc_gravity", "world_up", "reference") if k in f}
        if "position" in chans:
            conv["position_unit"] = _UNITS["position"][units[(name, "position")]]
        if "acceleration" in chans:
            conv["acc_unit"] = _UNITS["acceleration"][units[(name, "acceleration")]]
        if "angular_velocity" in chans:
            conv["gyro_unit"] = _UNITS["angular_velocity"][units[(name, "angular_velocity")]]
        if "magnetic_field" in chans:
            conv["mag_unit"] = units[(name, "magnetic_field")] or "a.u."
        site = f.get("site") or (name if name in known_sites() else None)
        try:
            sensors.append(SensorInfo(name, kind, site, r, **conv))
        except Exception as exc:  # noqa: BLE001 - ShapeError naming the field
            raise PacketError(f"LSL stream {info.name()!r} sensor {name!r}: {exc}") from None
        index[name] = {c: [i for i, _ in sorted(lst, key=lambda x: _ORDER[c].index(x[1]))] for c, lst in chans.items()}
    return tuple(sensors), index


def stream_info(name: str, sensors: Sequence[SensorInfo], channels: dict[str, Sequence[str]], rate: float,
                source_id: str = "wearpose-emulator") -> tuple[Any, list[tuple[str, str]]]:
    """An LSL StreamInfo of the layout (module doc) and its column list ``(sensor, component)``;
    ``channels``: sensor name -> its channels."""
    pylsl = _pylsl()
    cols = [(s.name, comp) for s in sensors for c in channels[s.name] for comp in _ORDER[c]]
    info = pylsl.StreamInfo(name, "MoCap", len(cols), rate, "float32", source_id)
    desc = info.desc().append_child("channels")
    unit_of = {}
    for s in sensors:
        unit_of[(s.name, "position")] = s.position_unit
        unit_of[(s.name, "orientation")] = "quaternion"
        unit_of[(s.name, "acceleration")] = "m/s^2" if s.acc_unit == "m/s2" else s.acc_unit
        unit_of[(s.name, "angular_velocity")] = s.gyro_unit
        unit_of[(s.name, "magnetic_field")] = s.mag_unit
    for sensor, comp in cols:
        c, typ = COMPONENTS[comp]
        e = desc.append_child("channel")
        e.append_child_value("label", f"{sensor}:{comp}")
        e.append_child_value("unit", unit_of[(sensor, c)])
        e.append_child_value("type", typ)
    ss = info.desc().append_child("sensors")
    for s in sensors:
        e = ss.append_child("sensor")
        for k in ("name", "kind", "site", "acc_frame", "acc_gravity", "world_up", "reference"):
            v = getattr(s, k)
            if v is not None:
                e.append_child_value(k, str(v))
    return info, cols


# ------------------------------------------------------------------------- the input
class LslInput(LiveInput):
    """An LSL inlet on a sensor stream of the layout above.

    Args:
        stream: the stream's ``name`` to resolve (``--lsl-stream``).
        rate: frame rate, Hz (default: the stream's nominal rate).
        timeout: seconds to wait for the stream to appear (default 2 minutes).
    """

    name = "lsl"

    def __init__(self, stream: str = "wearpose-sensors", rate: float | None = None, timeout: float = 120.0) -> None:
        super().__init__()
        self.stream, self._rate, self.timeout = stream, rate, timeout
        self._inlet: Any = None
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._loop: asyncio.AbstractEventLoop | None = None
        self._t0: float | None = None
        self.counts.update(samples=0, lost_connection=0)

    async def open(self) -> None:
        pylsl = _pylsl()
        self._loop = asyncio.get_running_loop()

        def resolve() -> Any:
            found = pylsl.resolve_byprop("name", self.stream, 1, self.timeout)
            if not found:
                raise PacketError(f"no LSL stream named {self.stream!r} found within {self.timeout:g} s (is the "
                                  f"device's outlet running on this machine or a known peer?)")
            inlet = pylsl.StreamInlet(found[0], max_buflen=60, recover=False)
            return inlet, inlet.info(self.timeout)

        self._inlet, info = await self._loop.run_in_executor(None, resolve)
        self.sensors, self._index = layout_from_info(info, self._rate)
        self.rate = self.sensors[0].rate
        self._thread = threading.Thread(target=self._pull, name=f"wearpose-lsl-{self.stream}", daemon=True)
        self._thread.start()

    async def close(self) -> None:
        self._stop.set()
        if self._thread is not None:
            await asyncio.get_running_loop().run_in_executor(None, self._thread.join, 5.0)
        if self._inlet is not None:  # what the outlet pushed before it stopped
            while True:
                try:
                    chunk, ts = self._inlet.pull_chunk(timeout=0.0)
                except LostError:
                    break
                if not chunk:
                    break
                self._samples(np.asarray(chunk, np.float64), list(ts))
            await asyncio.sleep(0)  # samples the pull thread handed to the loop just before it stopped

    def _pull(self) -> None:
        while not self._stop.is_set():
            try:
                chunk, ts = self._inlet.pull_chunk(timeout=0.05)
            except LostError:  # the outlet went away (recover=False: a new outlet is a new stream)
                self.counts["lost_connection"] += 1
                return
            if chunk:
                assert self._loop is not None
                try:
                    self._loop.call_soon_threadsafe(self._samples, np.asarray(chunk, np.float64), list(ts))
                except RuntimeError:  # loop closed
                    return

    def _samples(self, chunk: np.ndarray, ts: list[float]) -> None:
        for row, t in zip(chunk, ts):
            self.counts["samples"] += 1
            try:
                self.emit(self._frame(row, t))
            except PacketError as exc:
                self.malformed(exc)

    def _frame(self, row: np.ndarray, t: float) -> DeviceFrame:
        # The sender sets each time stamp: a NaN or infinite one (or one so far from the first that
        # the frame number overflows) is a malformed sample, not an exception in the pull callback.
        k = (t - self._t0) * self.rate if self._t0 is not None else 0.0
        if not (math.isfinite(t) and math.isfinite(k)):
            raise PacketError(f"LSL sample: time stamp {t!r} s is not finite or too far from the stream's first "
                              f"({self._t0!r} s); expected seconds on the LSL clock (pylsl.local_clock())")
        S = len(self.sensors)
        valid = np.zeros(S, bool)
        chans: dict[str, np.ndarray] = {}
        quats: dict[int, np.ndarray] = {}
        for j, s in enumerate(self.sensors):
            idx = self._index[s.name]
            vals = {c: row[i] for c, i in idx.items()}
            allnan = all(np.isnan(v).all() for v in vals.values())
            if allnan:
                continue
            if not all(np.isfinite(v).all() for v in vals.values()):
                raise PacketError(f"LSL sample t={t:.4f} sensor {s.name!r}: some values missing (NaN) or infinite; a "
                                  f"missing sensor sends NaN in every channel")
            valid[j] = True
            for c, v in vals.items():
                if c == "orientation":
                    quaternion_norm_check(v, "wxyz", f"LSL sample t={t:.4f} sensor {s.name!r}")
                    quats[j] = v
                else:
                    chans.setdefault(c, np.full((S, 3), np.nan))[j] = v
        for s_idx in self._index.values():  # every channel present even when no sensor sent it
            for c in s_idx:
                chans.setdefault(c, np.full((S, 3, 3) if c == "orientation" else (S, 3), np.nan))
        if quats:  # one conversion for the frame's quaternions
            chans["orientation"][list(quats)] = quaternion_matrices(np.stack(list(quats.values())), "wxyz", "LSL")
        if self._t0 is None:
            self._t0 = t
        return DeviceFrame(int(round(k)) & 0xFFFFFFFF, t, valid, chans)


# ------------------------------------------------------------------------- the emulator
async def emulate_lsl(recording: Any, stream: str = "wearpose-sensors", *, faults: Any = None, speed: float = 1.0,
                      realtime: bool = True, duration: float | None = None, wait_consumer: float = 30.0,
                      **conventions: str) -> dict[str, Any]:
    """Play ``recording`` as an LSL outlet ``stream`` of the layout above, in the conventions
    given (``Recording.declared_as`` arguments, e.g. ``position_unit="cm"``) and declared in the
    metadata. Waits up to ``wait_consumer`` s for an inlet, then pushes every frame with time
    stamp ``t_start + k / rate`` (LSL clock); dropped sensors are sent as NaN."""
    pylsl = _pylsl()
    d = device_data(recording, **conventions)
    rec = recording if recording.is_canonical else recording.to_canonical()
    infos = [s.info for s in (rec.declared_as(**conventions) if conventions else rec).sensors]
    chans = {s.name: [c for c in _ORDER if c in d.channels and not np.isnan(d.channels[c][:, j][d.valid[:, j]]).all()]
             for j, s in enumerate(infos)}
    info, cols = stream_info(stream, infos, chans, d.rate)
    outlet = pylsl.StreamOutlet(info)
    T = len(d.timestamps)
    N = T if duration is None else max(1, int(round(duration * d.rate)))
    q = matrix_to_quat(torch.from_numpy(np.ascontiguousarray(d.channels["orientation"]))).numpy() \
        if "orientation" in d.channels else None
    comp_idx = {k: i for i, k in enumerate(("x", "y", "z"))}

    def row(i: int, valid: np.ndarray) -> list[float]:
        out = []
        for sensor, comp in cols:
            j = d.names.index(sensor)
            if not (valid[j] and d.valid[i, j]):
                out.append(float("nan"))
                continue
            c = COMPONENTS[comp][0]
            if c == "orientation":
                out.append(float(q[i, j, "wxyz".index(comp[1])]))
            else:
                out.append(float(d.channels[c][i, j, comp_idx[comp[1]]]))
        return out

    loop = asyncio.get_running_loop()
    if wait_consumer > 0:
        await loop.run_in_executor(None, outlet.wait_for_consumers, wait_consumer)
    t_start = pylsl.local_clock() + 0.05

    def send(k: int, valid: np.ndarray) -> None:
        outlet.push_sample(row(k % T, valid), t_start + k / d.rate)

    def bad(k: int, rng: np.random.Generator) -> None:
        r = row(k % T, np.ones(len(d.names), bool))
        kind = int(rng.integers(0, 3))
        first = [i for i, (s, _) in enumerate(cols) if s == cols[0][0]]
        if kind == 0:  # one value of a sensor missing, the others not
            r[first[0]] = float("nan")
        elif kind == 1:  # infinite
            r[first[-1]] = float("inf")
        else:  # a quaternion of norm 2 (or a scaled first channel block)
            for i, (s, comp) in enumerate(cols):
                if comp.startswith("q"):
                    r[i] *= 2.0
        outlet.push_sample(r, t_start + k / d.rate)

    try:
        res = await play(N, len(d.names), d.rate, send, bad, faults, speed, realtime,
                         base_valid=np.stack([d.valid[k % T] for k in range(N)]))
        await asyncio.sleep(0.2)  # let the inlet pull the last chunk before the outlet goes away
    finally:
        del outlet
    return {"input": "lsl", "target": f"lsl:{stream}", "rate_hz": d.rate, "sensors": list(d.names),
            "channels": len(cols), **res.to_dict()}
