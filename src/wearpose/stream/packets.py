"""Wire formats of the streaming server (``docs/streaming.md`` is the user-facing contract).

Two encodings carry the same data:

- **JSON** (WebSocket text message): easy to write from any language.
- **binary** (WebSocket binary message): a fixed little-endian header + float32 payload,
  ~600 bytes for 12 EM sensors instead of ~3 kB of JSON.

Control messages (``hello``, ``subscribe``, ``stats``, ``bye``) are always JSON.

Binary header (:data:`HEADER`, 28 bytes, little-endian ``<2sBBHHIdQ``):

====== ======= ============================================================================
offset type    field
====== ======= ============================================================================
0      2s      magic ``b"WP"``
2      u8      version (:data:`VERSION`)
3      u8      kind: 1 = sensor frame (device -> server), 2 = pose (server -> clients)
4      u16     subject id
6      u16     count: sensors ``S`` (frame) or joints 24 (pose)
8      u32     sequence number (per subject, +1 per sensor frame; the pose echoes its frame's)
12     f64     timestamp, s (the sensor clock; the pose echoes its frame's)
20     u64     validity bits: bit ``i`` = sensor ``i`` valid (frame); bit 0 = pose valid (pose)
====== ======= ============================================================================

Frame payload: ``S x F`` float32, sensor-major, each sensor's channels in the order its
``hello`` declared (``position`` 3 floats m, ``orientation`` 9 floats row-major ``R_WS``,
``acceleration`` / ``angular_velocity`` / ``magnetic_field`` 3 floats each). Values of invalid
sensors are ignored (send anything, NaN is customary).

Pose payload (:data:`POSE_FLOATS` = 255 float32): local rotations ``24 x 9`` row-major, betas
10, root translation 3 (NaN when the estimator gives none), per-joint uncertainty 24 (NaN when
absent), then ``compute_ms`` (the estimator's ``step`` wall time) and ``server_ms`` (packet
arrival at the server to pose sent).
"""

from __future__ import annotations

import json
import math
import struct
from dataclasses import dataclass, field
from typing import Any, Sequence

import numpy as np

from wearpose.errors import WearposeError

#: The packet types and codecs of the streaming contract (``docs/streaming.md``): the names
#: :mod:`wearpose.stream` re-exports (listed here once).
__all__ = [
    "Hello", "FramePacket", "PosePacket", "PacketError", "HEADER", "VERSION", "CHANNEL_FLOATS",
    "encode_frame_binary", "encode_frame_json", "decode_frame_binary", "decode_frame_json",
    "encode_pose_binary", "encode_pose_json", "decode_pose",
]

VERSION = 1
MAGIC = b"WP"
KIND_FRAME = 1
KIND_POSE = 2
HEADER = struct.Struct("<2sBBHHIdQ")
#: Floats per sensor for each channel (row-major 3x3 for orientation).
CHANNEL_FLOATS: dict[str, int] = {"position": 3, "orientation": 9, "acceleration": 3, "angular_velocity": 3,
                                  "magnetic_field": 3}
MAX_SENSORS = 64  # the validity bits are one u64
NUM_JOINTS = 24
POSE_FLOATS = NUM_JOINTS * 9 + 10 + 3 + NUM_JOINTS + 2
#: Largest message the server accepts by default, bytes (``Limits.message_bytes``): 128 KiB, about
#: four times the largest valid message (a JSON frame of 64 sensors with every channel, ~35 kB).
MAX_MESSAGE_BYTES = 1 << 17


class PacketError(WearposeError, ValueError):
    """A message does not follow the packet format (the server logs, counts and skips it)."""


@dataclass(frozen=True)
class Hello:
    """Declares a subject's stream before its frames (JSON ``{"type": "hello", ...}``).

    Attributes:
        subject: subject id, 0..65535 (one estimator instance per subject).
        sensors: sensor names in payload order (the estimator picks its own by name).
        channels: channel names in payload order, from :data:`CHANNEL_FLOATS`.
        rate: nominal frame rate, Hz.
        format: ``"json"`` or ``"binary"``: how the server sends poses back to this connection.
        subject_info: optional ``Recording.subject``-style dict (e.g. EM-POSE ``offsets``).
    """

    subject: int
    sensors: tuple[str, ...]
    channels: tuple[str, ...]
    rate: float
    format: str = "json"
    subject_info: dict[str, Any] = field(default_factory=dict)

    @property
    def floats_per_sensor(self) -> int:
        return sum(CHANNEL_FLOATS[c] for c in self.channels)

    def to_json(self) -> str:
        return json.dumps({"type": "hello", "v": VERSION, "subject": self.subject, "sensors": list(self.sensors),
                           "channels": list(self.channels), "rate": self.rate, "format": self.format,
                           "subject_info": _jsonable(self.subject_info)})

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Hello:
        subject = _subject(d.get("subject"))
        sensors = d.get("sensors")
        if not isinstance(sensors, list) or not sensors or not all(isinstance(s, str) for s in sensors):
            raise PacketError("hello.sensors: expected a non-empty list of sensor names")
        if len(sensors) > MAX_SENSORS or len(set(sensors)) != len(sensors):
            raise PacketError(f"hello.sensors: expected at most {MAX_SENSORS} distinct names, got {len(sensors)}")
        channels = d.get("channels")
        if not isinstance(channels, list) or not channels or any(
                not isinstance(c, str) or c not in CHANNEL_FLOATS for c in channels) or len(set(channels)) != len(channels):
            raise PacketError(f"hello.channels: expected distinct names from {sorted(CHANNEL_FLOATS)}, "
                              f"got {_short(channels)}")
        rate = _finite(d.get("rate"))
        if rate is None or rate <= 0:
            raise PacketError(f"hello.rate: expected a positive number of Hz, got {_short(d.get('rate'))}")
        fmt = d.get("format", "json")
        if fmt not in ("json", "binary"):
            raise PacketError(f"hello.format: expected 'json' or 'binary', got {_short(fmt)}")
        info = d.get("subject_info") or {}
        if not isinstance(info, dict):
            raise PacketError("hello.subject_info: expected a JSON object")
        return cls(subject, tuple(sensors), tuple(channels), float(rate), fmt, info)


@dataclass
class FramePacket:
    """One sensor frame of one subject.

    Attributes:
        subject, seq: ids (``seq`` u32, +1 per frame).
        timestamp: s, sensor clock.
        valid: ``(S,)`` bool.
        data: ``(S, F)`` float32, channels concatenated in the hello's order.
    """

    subject: int
    seq: int
    timestamp: float
    valid: np.ndarray
    data: np.ndarray


@dataclass
class PosePacket:
    """One estimated pose (server -> clients). Shapes as :class:`wearpose.estimators.PoseFrame`.

    Attributes:
        local_rot ``(24, 3, 3)``, betas ``(10,)``, trans ``(3,)`` m or None, uncertainty
        ``(24,)`` or None; compute_ms: the estimator's step time; server_ms: arrival of the
        frame at the server to the pose leaving it; extras: JSON-able method extras (JSON only).
    """

    subject: int
    seq: int
    timestamp: float
    valid: bool
    local_rot: np.ndarray
    betas: np.ndarray
    trans: np.ndarray | None = None
    uncertainty: np.ndarray | None = None
    compute_ms: float = float("nan")
    server_ms: float = float("nan")
    extras: dict[str, Any] = field(default_factory=dict)


def _subject(x: Any) -> int:
    if isinstance(x, bool) or not isinstance(x, int) or not 0 <= x <= 0xFFFF:
        raise PacketError(f"subject: expected an integer 0..65535, got {_short(x)}")
    return x


def _seq(x: Any) -> int:
    if isinstance(x, bool) or not isinstance(x, int) or not 0 <= x <= 0xFFFFFFFF:
        raise PacketError(f"seq: expected an integer 0..2^32-1, got {_short(x)}")
    return x


def _finite(x: Any) -> float | None:
    """``x`` as a finite float, or None when it is not a finite number (bools, strings, NaN,
    infinities and integers too large for a float: JSON allows any number of digits)."""
    if isinstance(x, bool) or not isinstance(x, (int, float)):
        return None
    try:
        f = float(x)
    except OverflowError:
        return None
    return f if math.isfinite(f) else None


def _finite_time(x: Any) -> float:
    t = _finite(x)
    if t is None:
        raise PacketError(f"t: expected a finite timestamp in seconds, got {_short(x)}")
    return t


def _short(x: Any, n: int = 60) -> str:
    """``repr(x)``, cut to ``n`` characters: an error message must not echo a hostile megabyte."""
    r = repr(x)
    return r if len(r) <= n else r[:n] + "..."


def _jsonable(x: Any) -> Any:
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if hasattr(x, "tolist"):  # numpy / torch
        return x.tolist()
    if isinstance(x, float) and not math.isfinite(x):
        return None
    return x


def _bits(valid: np.ndarray) -> int:
    v = np.asarray(valid, bool)
    return int(np.bitwise_or.reduce(v.astype(np.uint64) << np.arange(len(v), dtype=np.uint64), initial=np.uint64(0)))


def _unbits(bits: int, n: int) -> np.ndarray:
    return ((bits >> np.arange(n, dtype=np.uint64)) & 1).astype(bool)


# ---------------------------------------------------------------------------------- frames
def encode_frame_binary(pkt: FramePacket) -> bytes:
    """A :class:`FramePacket` as a binary message (header + float32 payload)."""
    S = len(pkt.valid)
    return HEADER.pack(MAGIC, VERSION, KIND_FRAME, pkt.subject, S, pkt.seq, pkt.timestamp, _bits(pkt.valid)) \
        + np.ascontiguousarray(pkt.data, dtype="<f4").tobytes()


def encode_frame_json(pkt: FramePacket, channels: Sequence[str]) -> str:
    """A :class:`FramePacket` as a JSON message; invalid sensors' values are ``null``."""
    out: dict[str, Any] = {"type": "frame", "v": VERSION, "subject": pkt.subject, "seq": pkt.seq, "t": pkt.timestamp,
                           "valid": [int(v) for v in pkt.valid]}
    a = 0
    for c in channels:
        n = CHANNEL_FLOATS[c]
        block = pkt.data[:, a:a + n]
        out[c] = [[float(x) for x in row] if ok else None for row, ok in zip(block, pkt.valid)]
        a += n
    return json.dumps(out)


def decode_frame_binary(msg: bytes, hello: Hello) -> FramePacket:
    """Parse a binary frame against its subject's :class:`Hello` (PacketError when malformed)."""
    if len(msg) < HEADER.size:
        raise PacketError(f"binary frame: {len(msg)} bytes, shorter than the {HEADER.size}-byte header")
    magic, ver, kind, subject, S, seq, t, bits = HEADER.unpack_from(msg)
    if magic != MAGIC or ver != VERSION or kind != KIND_FRAME:
        raise PacketError(f"binary frame: header magic/version/kind {magic!r}/{ver}/{kind}, expected {MAGIC!r}/{VERSION}/{KIND_FRAME}")
    F = hello.floats_per_sensor
    if S != len(hello.sensors) or len(msg) != HEADER.size + 4 * S * F:
        raise PacketError(f"binary frame subject {subject}: {S} sensors / {len(msg)} bytes, expected "
                          f"{len(hello.sensors)} sensors x {F} floats = {HEADER.size + 4 * len(hello.sensors) * F} bytes")
    if not math.isfinite(t):
        raise PacketError(f"binary frame subject {subject} seq {seq}: timestamp {t!r} is not finite")
    data = np.frombuffer(msg, dtype="<f4", offset=HEADER.size).reshape(S, F).astype(np.float32)
    valid = _unbits(bits, S)
    _check_valid_values(data, valid, subject, seq)
    return FramePacket(subject, seq, t, valid, data)


def peek_subject(msg: bytes) -> int:
    """Subject id of a binary message (PacketError if the header is truncated)."""
    if len(msg) < HEADER.size:
        raise PacketError(f"binary message: {len(msg)} bytes, shorter than the {HEADER.size}-byte header")
    return int(HEADER.unpack_from(msg)[3])


def decode_frame_json(d: dict[str, Any], hello: Hello) -> FramePacket:
    """Parse a JSON frame (already ``json.loads``-ed) against its subject's :class:`Hello`."""
    subject, seq, t = _subject(d.get("subject")), _seq(d.get("seq")), _finite_time(d.get("t"))
    S = len(hello.sensors)
    valid = d.get("valid")
    if not isinstance(valid, list) or len(valid) != S or any(v not in (0, 1, True, False) for v in valid):
        raise PacketError(f"frame subject {subject} seq {seq}: 'valid' must be {S} booleans/0/1")
    valid = np.asarray(valid, dtype=bool)
    data = np.full((S, hello.floats_per_sensor), np.nan, dtype=np.float32)
    a = 0
    for c in hello.channels:
        n = CHANNEL_FLOATS[c]
        rows = d.get(c)
        if not isinstance(rows, list) or len(rows) != S:
            raise PacketError(f"frame subject {subject} seq {seq}: channel {c!r} must be a list of {S} entries")
        for i, row in enumerate(rows):
            if not valid[i]:
                continue
            if c == "orientation" and isinstance(row, list) and len(row) == 3:  # accept [[..],[..],[..]]
                row = [x for r in row for x in (r if isinstance(r, list) else [r])]
            values = [_finite(x) for x in row] if isinstance(row, list) and len(row) == n else None
            if values is None or None in values:
                raise PacketError(f"frame subject {subject} seq {seq}: {c}[{i}] must be {n} finite numbers")
            data[i, a:a + n] = values
        a += n
    _check_valid_values(data, valid, subject, seq)
    return FramePacket(subject, seq, t, valid, data)


def _check_valid_values(data: np.ndarray, valid: np.ndarray, subject: int, seq: int) -> None:
    if not np.isfinite(data[valid]).all():
        bad = [i for i in np.flatnonzero(valid) if not np.isfinite(data[i]).all()]
        raise PacketError(f"frame subject {subject} seq {seq}: non-finite values for sensors marked valid {bad}")


def frame_channels(data: np.ndarray, valid: np.ndarray, channels: Sequence[str]) -> dict[str, np.ndarray]:
    """Split a payload ``(S, F)`` into channel arrays (``orientation`` ``(S, 3, 3)``), NaN where invalid."""
    out: dict[str, np.ndarray] = {}
    a = 0
    for c in channels:
        n = CHANNEL_FLOATS[c]
        block = data[:, a:a + n].copy()
        block[~valid] = np.nan
        out[c] = block.reshape(-1, 3, 3) if c == "orientation" else block
        a += n
    return out


def pack_channels(channels: dict[str, np.ndarray], order: Sequence[str]) -> np.ndarray:
    """Inverse of :func:`frame_channels`: channel arrays ``(S, ...)`` -> payload ``(S, F)`` float32."""
    return np.concatenate([np.asarray(channels[c], np.float32).reshape(len(channels[c]), -1) for c in order], axis=1)


# ---------------------------------------------------------------------------------- poses
def encode_pose_binary(p: PosePacket) -> bytes:
    """A :class:`PosePacket` as a binary message (extras are JSON-only)."""
    nan3, nan24 = np.full(3, np.nan, np.float32), np.full(NUM_JOINTS, np.nan, np.float32)
    payload = np.concatenate([np.asarray(p.local_rot, np.float32).reshape(-1), np.asarray(p.betas, np.float32).reshape(-1),
                              nan3 if p.trans is None else np.asarray(p.trans, np.float32).reshape(3),
                              nan24 if p.uncertainty is None else np.asarray(p.uncertainty, np.float32).reshape(NUM_JOINTS),
                              np.array([p.compute_ms, p.server_ms], np.float32)])
    return HEADER.pack(MAGIC, VERSION, KIND_POSE, p.subject, NUM_JOINTS, p.seq, p.timestamp, int(bool(p.valid))) \
        + payload.astype("<f4").tobytes()


def decode_pose_binary(msg: bytes) -> PosePacket:
    if len(msg) != HEADER.size + 4 * POSE_FLOATS:
        raise PacketError(f"binary pose: {len(msg)} bytes, expected {HEADER.size + 4 * POSE_FLOATS}")
    magic, ver, kind, subject, J, seq, t, bits = HEADER.unpack_from(msg)
    if magic != MAGIC or ver != VERSION or kind != KIND_POSE or J != NUM_JOINTS:
        raise PacketError(f"binary pose: header {magic!r}/{ver}/{kind}/{J}, expected {MAGIC!r}/{VERSION}/{KIND_POSE}/24")
    x = np.frombuffer(msg, dtype="<f4", offset=HEADER.size).astype(np.float32)
    a = NUM_JOINTS * 9
    trans, unc = x[a + 10:a + 13], x[a + 13:a + 13 + NUM_JOINTS]
    return PosePacket(subject, seq, t, bool(bits & 1), x[:a].reshape(NUM_JOINTS, 3, 3), x[a:a + 10],
                      None if np.isnan(trans).all() else trans, None if np.isnan(unc).all() else unc,
                      float(x[-2]), float(x[-1]))


def encode_pose_json(p: PosePacket) -> str:
    return json.dumps({"type": "pose", "v": VERSION, "subject": p.subject, "seq": p.seq, "t": p.timestamp,
                       "valid": bool(p.valid), "local_rot": np.asarray(p.local_rot, np.float32).reshape(-1).round(6).tolist(),
                       "betas": np.asarray(p.betas, np.float32).round(6).tolist(),
                       "trans": None if p.trans is None else np.asarray(p.trans, np.float32).tolist(),
                       "uncertainty": None if p.uncertainty is None else np.asarray(p.uncertainty, np.float32).tolist(),
                       "compute_ms": _jsonable(float(p.compute_ms)), "server_ms": _jsonable(float(p.server_ms)),
                       "extras": _jsonable(p.extras)})


def decode_pose_json(d: dict[str, Any]) -> PosePacket:
    """Parse a JSON pose (already ``json.loads``-ed); PacketError when malformed."""
    try:
        with np.errstate(over="ignore"):  # a hostile 1e39 becomes inf in float32: no warning per value
            return _pose_from_dict(d)
    except (KeyError, ValueError, TypeError, OverflowError) as exc:  # OverflowError: an integer beyond float
        raise PacketError(f"pose message: {_short(exc, 200)}") from None


def _pose_from_dict(d: dict[str, Any]) -> PosePacket:
    extras = d.get("extras") or {}
    if not isinstance(extras, dict):
        raise TypeError("extras: expected a JSON object")
    rot = np.asarray(d["local_rot"], np.float32).reshape(NUM_JOINTS, 3, 3)
    betas = np.asarray(d["betas"], np.float32).reshape(10)
    trans = None if d.get("trans") is None else np.asarray(d["trans"], np.float32).reshape(3)
    unc = None if d.get("uncertainty") is None else np.asarray(d["uncertainty"], np.float32).reshape(NUM_JOINTS)
    nan = float("nan")
    return PosePacket(_subject(d["subject"]), _seq(d["seq"]), _finite_time(d["t"]), bool(d["valid"]), rot, betas,
                      trans, unc, nan if d.get("compute_ms") is None else float(d["compute_ms"]),
                      nan if d.get("server_ms") is None else float(d["server_ms"]), extras)


def decode_pose(msg: str | bytes) -> PosePacket | dict[str, Any]:
    """A server message: a :class:`PosePacket`, or the parsed JSON dict of a control reply
    (PacketError when it is neither)."""
    if isinstance(msg, (bytes, bytearray, memoryview)):
        return decode_pose_binary(bytes(msg))
    d = parse_message(msg)
    return decode_pose_json(d) if d["type"] == "pose" else d


def parse_message(text: str) -> dict[str, Any]:
    """A text message as a JSON object with a string ``type``; PacketError for anything else
    (not JSON, nested too deeply to parse, not an object, no ``type``)."""
    try:
        d = json.loads(text)
    except json.JSONDecodeError as exc:
        raise PacketError(f"text message is not JSON ({exc.msg} at char {exc.pos})") from None
    except RecursionError:  # "[[[[..." past the interpreter's recursion limit
        raise PacketError("text message: JSON nested too deeply") from None
    if not isinstance(d, dict) or not isinstance(d.get("type"), str):
        raise PacketError("text message: expected a JSON object with a string 'type'")
    return d
