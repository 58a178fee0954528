"""Xsens MVN network streamer (UDP) input and its loopback emulator.

Implemented from Xsens' *MVN real-time network streaming Protocol Specification*, document
MV0305P revision N (September 2018; "added finger tracking and updated header"). What is read:

- **Header** (24 bytes, big-endian, §2.4.1): ID string ``"MXTP"`` + two ASCII digits of the
  message type, sample counter u32, datagram counter u8 (bit 7 = last datagram of the sample;
  ``0x80`` = the whole sample in one datagram), number of items u8, time code u32 (ms since the
  start of the recording), character ID u8, number of body segments u8, number of props u8,
  number of finger tracking segments u8, 2 reserved bytes, payload size u16.
- **Type 23, motion tracker kinematics** (§2.7.4), 44 bytes per tracker: segment ID i32 (the
  segment the tracker is on; ID = segment index + 1, §3.1), orientation quaternion q1..q4
  (re, i, j, k) f32, global free acceleration x y z f32, sensor-local magnetic field x y z f32;
  Z-up right-handed world. Only segments with a tracker are sent. These become the sensors.
- **Type 02, pose data quaternion** (§2.5.3), 32 bytes per segment: segment ID i32, position
  x y z f32, quaternion q1..q4 (re, i, j, k) f32; Z-up right-handed world. Kept as the MVN pose
  of the frame (:attr:`MvnInput.on_pose`), e.g. as ground truth beside a sparse estimate.

Declared conventions of a tracker sensor (converted by ``Recording.to_canonical``): kind
``imu``, orientation ``R_WS`` in a Z-up world (``world_up="z_up"``), acceleration free (gravity
removed) in the world frame, m/s^2; magnetic field sensor frame, unit ``a.u.`` (MVN normalises
it to the local field). The specification gives the free acceleration's unit nowhere; MVN
exports it in m/s^2 and so does this input.

Sequence numbers are MVN's sample counter, time stamps its time code (s). Split samples
(datagram counter other than ``0x80``) are not reassembled: they are counted as ``ignored``
(17 trackers are 772 bytes, far below the Ethernet MTU). Other message types and other
characters are ignored (counted). Anything else that does not follow the layout is malformed.
"""

from __future__ import annotations

import asyncio
import struct
from typing import Any, Callable, Sequence

import numpy as np
import torch

from wearpose.body import BodyModel, forward_kinematics, global_to_local
from wearpose.estimators.base import PoseFrame
from wearpose.geometry import MVN_TO_WEARPOSE, matrix_to_quat, wearpose_to_mvn_segment
from wearpose.recording import SensorInfo
from wearpose.stream.inputs.base import DeviceFrame, LiveInput, drain_udp, quaternion_matrices, udp_socket
from wearpose.stream.inputs.emulate import UdpSender, device_data, play
from wearpose.stream.packets import PacketError

DEFAULT_PORT = 9763  # §2.3: "9 = X, M = 6, E = 3"
HEADER = struct.Struct(">6sIBBIBBBB2sH")
TRACKER = struct.Struct(">i4f3f3f")  # 44 bytes
SEGMENT = struct.Struct(">i3f4f")  # 32 bytes
TYPE_POSE_QUAT = b"02"
TYPE_TRACKERS = b"23"
#: MVN's 23 body segments in index order (§3.1, table 1); ID = index + 1.
SEGMENTS: tuple[str, ...] = (
    "pelvis", "l5", "l3", "t12", "t8", "neck", "head",
    "right_shoulder", "right_upper_arm", "right_forearm", "right_hand",
    "left_shoulder", "left_upper_arm", "left_forearm", "left_hand",
    "right_upper_leg", "right_lower_leg", "right_foot", "right_toe",
    "left_upper_leg", "left_lower_leg", "left_foot", "left_toe",
)
#: wearpose body site of a tracker on each segment (None: no site of that name).
SITES: dict[str, str] = {
    "pelvis": "pelvis", "t8": "sternum", "head": "head", "right_shoulder": "right_shoulder",
    "right_upper_arm": "right_upper_arm", "right_forearm": "right_forearm", "right_hand": "right_wrist",
    "left_shoulder": "left_shoulder", "left_upper_arm": "left_upper_arm", "left_forearm": "left_forearm",
    "left_hand": "left_wrist", "right_upper_leg": "right_thigh", "right_lower_leg": "right_shin",
    "right_foot": "right_foot", "left_upper_leg": "left_thigh", "left_lower_leg": "left_shin", "left_foot": "left_foot",
}
#: The SMPL joint each MVN segment drives (``SMPL_FROM_MVN[j]`` = segment index of SMPL joint j).
#: SMPL's spine1/2/3 take L3/T12/T8 (L5 is not used), its hands (22, 23) the MVN hands.
SMPL_FROM_MVN: tuple[int, ...] = (0, 19, 15, 2, 20, 16, 3, 21, 17, 4, 22, 18, 5, 11, 7, 6, 12, 8, 13, 9, 14, 10, 14, 10)


def tracker_info(segment: str, rate: float) -> SensorInfo:
    """The declared conventions of an MVN tracker on ``segment`` (module doc)."""
    return SensorInfo(segment, "imu", SITES.get(segment), rate, acc_unit="m/s2", acc_frame="world",
                      acc_gravity="removed", world_up="z_up", mag_unit="a.u.")


def segment_id(name: str) -> int:
    if name not in SEGMENTS:
        raise ValueError(f"MVN segment {name!r}: expected one of {', '.join(SEGMENTS)}")
    return SEGMENTS.index(name) + 1


# ------------------------------------------------------------------------- wire format
def encode_header(kind: bytes, sample: int, items: int, time_ms: int, payload: int, character: int = 0,
                  datagram_counter: int = 0x80) -> bytes:
    return HEADER.pack(b"MXTP" + kind, sample & 0xFFFFFFFF, datagram_counter, items, time_ms & 0xFFFFFFFF,
                       character, len(SEGMENTS), 0, 0, b"\x00\x00", payload)


def encode_trackers(sample: int, time_ms: int, ids: Sequence[int], quats: np.ndarray, free_acc: np.ndarray,
                    mag: np.ndarray, character: int = 0) -> bytes:
    """A type-23 datagram: trackers ``ids`` with quaternions ``(n, 4)`` (re, i, j, k), free
    acceleration ``(n, 3)`` m/s^2 and magnetic field ``(n, 3)``."""
    body = b"".join(TRACKER.pack(int(i), *map(float, q), *map(float, a), *map(float, m))
                    for i, q, a, m in zip(ids, quats, free_acc, mag))
    return encode_header(TYPE_TRACKERS, sample, len(ids), time_ms, len(body), character) + body


def encode_pose(sample: int, time_ms: int, positions: np.ndarray, quats: np.ndarray, character: int = 0) -> bytes:
    """A type-02 datagram of the 23 segments: positions ``(23, 3)`` and quaternions ``(23, 4)``."""
    body = b"".join(SEGMENT.pack(k + 1, *map(float, p), *map(float, q)) for k, (p, q) in enumerate(zip(positions, quats)))
    return encode_header(TYPE_POSE_QUAT, sample, len(positions), time_ms, len(body), character) + body


def decode_header(data: bytes) -> dict[str, Any]:
    """The header fields of a datagram (PacketError when it is no MVN datagram)."""
    if len(data) < HEADER.size:
        raise PacketError(f"MVN datagram: {len(data)} bytes, shorter than the {HEADER.size}-byte header")
    ident, sample, dgram, items, time_ms, character, nseg, nprops, nfinger, _, size = HEADER.unpack_from(data)
    if ident[:4] != b"MXTP" or not ident[4:].isdigit():
        raise PacketError(f"MVN datagram: ID string {ident!r}, expected b'MXTP' and two digits")
    if size != len(data) - HEADER.size:
        raise PacketError(f"MVN datagram type {ident[4:].decode()}: payload size field {size}, but "
                          f"{len(data) - HEADER.size} bytes follow the header")
    return {"type": ident[4:], "sample": sample, "datagram_counter": dgram, "items": items, "time_ms": time_ms,
            "character": character, "segments": nseg, "props": nprops, "fingers": nfinger, "size": size}


def _records(data: bytes, h: dict[str, Any], rec: struct.Struct) -> list[tuple[Any, ...]]:
    if h["size"] != h["items"] * rec.size:
        raise PacketError(f"MVN datagram type {h['type'].decode()} sample {h['sample']}: {h['items']} items of "
                          f"{rec.size} bytes = {h['items'] * rec.size}, but the payload has {h['size']}")
    return [rec.unpack_from(data, HEADER.size + k * rec.size) for k in range(h["items"])]


def decode_trackers(data: bytes, h: dict[str, Any]) -> dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Type 23: segment name -> (R (3, 3) in the Z-up world, free acceleration (3,), magnetic field (3,))."""
    recs = _records(data, h, TRACKER)
    names = []
    for r in recs:
        sid = r[0]
        if not 1 <= sid <= len(SEGMENTS):
            raise PacketError(f"MVN trackers sample {h['sample']}: segment ID {sid}, expected 1..{len(SEGMENTS)}")
        if SEGMENTS[sid - 1] in names:
            raise PacketError(f"MVN trackers sample {h['sample']}: segment {SEGMENTS[sid - 1]!r} twice")
        names.append(SEGMENTS[sid - 1])
    if not recs:
        return {}
    a = np.asarray([r[1:] for r in recs], np.float64)
    if not np.isfinite(a[:, 4:]).all():
        raise PacketError(f"MVN trackers sample {h['sample']}: non-finite acceleration or magnetic field")
    R = quaternion_matrices(a[:, :4], "wxyz", f"MVN trackers sample {h['sample']}")
    return {n: (R[k], a[k, 4:7], a[k, 7:10]) for k, n in enumerate(names)}


def decode_pose(data: bytes, h: dict[str, Any]) -> tuple[np.ndarray, np.ndarray]:
    """Type 02: positions ``(23, 3)`` (MVN world, as sent) and rotations ``(23, 3, 3)`` of the body segments."""
    recs = _records(data, h, SEGMENT)
    if len(recs) < len(SEGMENTS) or [r[0] for r in recs[:len(SEGMENTS)]] != list(range(1, len(SEGMENTS) + 1)):
        raise PacketError(f"MVN pose sample {h['sample']}: expected the {len(SEGMENTS)} body segments with IDs 1..23 first")
    a = np.asarray([r[1:] for r in recs[:len(SEGMENTS)]], np.float64)
    if not np.isfinite(a[:, :3]).all():
        raise PacketError(f"MVN pose sample {h['sample']}: non-finite segment position")
    return a[:, :3], quaternion_matrices(a[:, 3:], "wxyz", f"MVN pose sample {h['sample']}")


# ------------------------------------------------------------------------- the input
class MvnInput(LiveInput):
    """Listens for the MVN network streamer on UDP ``host:port``.

    Args:
        host, port: where to listen (MVN's "Host" setting must name this machine; default port 9763).
        segments: tracker segments to read, e.g. ``("pelvis", "head", "left_forearm", ...)``;
            None: the trackers of the first type-23 datagram (waited for in :meth:`open`).
        rate: the network streamer's stream rate, Hz (MVN does not send it).
        character: MVN character ID to read (others are ignored).
        position_unit: unit of type-02 positions: ``"m"`` (what MVN sends; §2.5.6 of revision N
            says cm, its user manual metres) or ``"cm"``.
        first_timeout: seconds :meth:`open` waits for the first tracker datagram.
        pose_subject: also publish MVN's own pose (type-02 datagrams, :class:`MvnPoseEstimator`)
            as this subject, e.g. ground truth beside a sparse estimate (``--mvn-pose-subject``).
    """

    name = "mvn"

    def __init__(self, host: str = "127.0.0.1", port: int = DEFAULT_PORT, segments: Sequence[str] | None = None,
                 rate: float = 60.0, character: int = 0, position_unit: str = "m", first_timeout: float = 30.0,
                 pose_subject: int | None = None) -> None:
        super().__init__()
        #: Publish MVN's own pose (type 02) as this subject beside the estimate (None: do not).
        self.pose_subject = pose_subject
        self.host, self.port, self.rate, self.character = host, port, float(rate), character
        if position_unit not in ("m", "cm"):
            raise ValueError(f"position_unit {position_unit!r}: expected 'm' or 'cm'")
        self.position_scale = 1.0 if position_unit == "m" else 0.01
        for s in segments or ():
            segment_id(s)  # a name that is no MVN segment fails here
        self.segments = None if segments is None else tuple(segments)
        self.first_timeout = first_timeout
        self.counts.update(datagrams=0, poses=0, ignored_trackers=0)
        #: ``(seq, t, positions (23, 3) m in the MVN world, rotations (23, 3, 3))`` per type-02 datagram.
        self.on_pose: Callable[[int, float, np.ndarray, np.ndarray], None] | None = None
        self._transport: Any = None
        self._first: asyncio.Future | None = None

    async def open(self) -> None:
        loop = asyncio.get_running_loop()
        if self.segments is None:
            self._first = loop.create_future()
        self._sock = udp_socket(self.host, self.port)
        self._transport, _ = await loop.create_datagram_endpoint(lambda: _Protocol(self), sock=self._sock)
        self.port = self._transport.get_extra_info("sockname")[1]
        if self._first is not None:
            try:
                self.segments = await asyncio.wait_for(self._first, self.first_timeout)
            except asyncio.TimeoutError:
                self._transport.close()
                raise PacketError(f"no MVN tracker datagram (type 23) on udp://{self.host}:{self.port} within "
                                  f"{self.first_timeout:g} s: enable 'Motion Tracker Kinematics' in MVN's network "
                                  f"streamer, or name the trackers (--mvn-segments)") from None
        self.sensors = tuple(tracker_info(s, self.rate) for s in self.segments)

    async def close(self) -> None:
        if self._transport is not None:
            drain_udp(self._sock, self.datagram)
            self._transport.close()

    def datagram(self, data: bytes) -> None:
        self.counts["datagrams"] += 1
        try:
            h = decode_header(data)
            if h["character"] != self.character or h["type"] not in (TYPE_TRACKERS, TYPE_POSE_QUAT):
                self.counts["ignored"] += 1
                return
            if h["datagram_counter"] != 0x80:
                self.counts["ignored"] += 1  # a sample split over datagrams (module doc)
                return
            if h["type"] == TYPE_POSE_QUAT:
                self._pose(data, h)
            else:
                self._trackers(data, h)
        except PacketError as exc:
            self.malformed(exc)

    def _pose(self, data: bytes, h: dict[str, Any]) -> None:
        pos, R = decode_pose(data, h)
        self.counts["poses"] += 1
        if self.on_pose is not None:
            self.on_pose(h["sample"], h["time_ms"] / 1000.0, pos * self.position_scale, R)

    def _trackers(self, data: bytes, h: dict[str, Any]) -> None:
        got = decode_trackers(data, h)
        if self.segments is None:  # learning the tracker set from the first datagram
            if self._first is not None and not self._first.done():
                self._first.set_result(tuple(s for s in SEGMENTS if s in got))
            return
        S = len(self.segments)
        valid = np.zeros(S, bool)
        R = np.full((S, 3, 3), np.nan)
        acc, mag = np.full((S, 3), np.nan), np.full((S, 3), np.nan)
        for j, name in enumerate(self.segments):
            if name in got:
                valid[j] = True
                R[j], acc[j], mag[j] = got[name]
        self.counts["ignored_trackers"] += len(set(got) - set(self.segments))
        self.emit(DeviceFrame(h["sample"], h["time_ms"] / 1000.0, valid,
                              {"orientation": R, "acceleration": acc, "magnetic_field": mag}))


class _Protocol(asyncio.DatagramProtocol):
    def __init__(self, owner: MvnInput) -> None:
        self.owner = owner

    def datagram_received(self, data: bytes, addr: Any) -> None:
        self.owner.datagram(data)


# ------------------------------------------------------------------------- the emulator
def _quat(R: np.ndarray) -> np.ndarray:
    return matrix_to_quat(torch.from_numpy(np.ascontiguousarray(R, np.float64))).numpy()


def mvn_pose_arrays(recording: Any) -> tuple[np.ndarray, np.ndarray] | None:
    """The recording's ground truth as MVN segments on the sensors' grid: positions ``(T, 23, 3)``
    m and rotations ``(T, 23, 3, 3)`` in MVN's world and segment axes (None without ground truth)."""
    gt = getattr(recording, "ground_truth", None)
    if gt is None:
        return None
    body = BodyModel()
    G, J = forward_kinematics(gt.pose.double(), body.rest_joints(gt.betas).double().expand(len(gt.pose), -1, -1),
                              body.parents)
    J = J + gt.trans.double()[:, None]
    # each MVN segment takes the SMPL joint that drives it (L5: spine1 as L3)
    smpl_of = [SMPL_FROM_MVN.index(k) if k in SMPL_FROM_MVN else 3 for k in range(len(SEGMENTS))]
    Rm = wearpose_to_mvn_segment(G[:, smpl_of]).numpy()
    Pm = (MVN_TO_WEARPOSE.double().T @ J[:, smpl_of][..., None])[..., 0].numpy()  # C^T p: wearpose -> MVN
    return Pm, Rm


async def emulate_mvn(recording: Any, host: str = "127.0.0.1", port: int = DEFAULT_PORT, *, faults: Any = None,
                      speed: float = 1.0, realtime: bool = True, duration: float | None = None,
                      pose: bool = True, character: int = 0) -> dict[str, Any]:
    """Play ``recording`` as the MVN network streamer: per frame one type-23 datagram of its
    sensors (each named by its MVN segment, e.g. ``left_forearm``; sensors with other names are
    refused) and, with ``pose`` and ground truth, one type-02 datagram of the 23 segments."""
    d = device_data(recording, world_up="z_up")  # acceleration stays free, world frame, m/s^2
    ids = [segment_id(n) for n in d.names]
    T = len(d.timestamps)
    N = T if duration is None else max(1, int(round(duration * d.rate)))
    q = _quat(d.channels["orientation"])  # (T, S, 4)
    acc = d.channels["acceleration"]
    mag = d.channels.get("magnetic_field", np.zeros_like(acc))
    mag = np.where(np.isnan(mag), 0.0, mag)
    gt = mvn_pose_arrays(recording) if pose else None
    gt_q = None if gt is None else _quat(gt[1])
    gt_start = float(getattr(recording, "ground_truth_start", 0.0))
    out = UdpSender(host, port)
    t0 = float(d.timestamps[0])

    def send(k: int, valid: np.ndarray) -> None:
        i = k % T
        t_ms = int(round((t0 + k / d.rate) * 1000))
        sel = np.flatnonzero(valid & d.valid[i])
        out.send(encode_trackers(k, t_ms, [ids[j] for j in sel], q[i, sel], acc[i, sel], mag[i, sel], character))
        if gt is not None:
            g = int(round((d.timestamps[i] - gt_start) * recording.ground_truth.fps))
            if 0 <= g < len(gt[0]):
                out.send(encode_pose(k, t_ms, gt[0][g], gt_q[g], character))

    def bad(k: int, rng: np.random.Generator) -> None:
        i = k % T
        good = encode_trackers(k, 0, ids, q[i], acc[i], mag[i], character)
        kind = int(rng.integers(0, 6))
        if kind == 0:
            msg = good[:int(rng.integers(1, HEADER.size))]  # truncated header
        elif kind == 1:
            msg = b"MXTQ" + good[4:]  # wrong ID string
        elif kind == 2:
            msg = good[:-4]  # payload shorter than its size field
        elif kind == 3:  # size field and items disagree
            msg = bytearray(good)
            msg[11] = (msg[11] + 1) % 256
            msg = bytes(msg)
        elif kind == 4:  # a non-unit quaternion
            msg = bytearray(good)
            struct.pack_into(">f", msg, HEADER.size + 4, 3.0)
            msg = bytes(msg)
        else:  # an unknown segment ID
            msg = bytearray(good)
            struct.pack_into(">i", msg, HEADER.size, 99)
            msg = bytes(msg)
        out.send(msg)

    try:
        res = await play(N, len(ids), d.rate, send, bad, faults, speed, realtime,
                         base_valid=np.stack([d.valid[k % T] for k in range(N)]))
    finally:
        out.close()
    return {"input": "mvn", "target": f"udp://{host}:{port}", "rate_hz": d.rate, "sensors": list(d.names),
            "pose_datagrams": gt is not None, **res.to_dict()}


# ------------------------------------------------------------------------- MVN's own pose as a subject
def segment_info(segment: str, rate: float, position_unit: str = "m") -> SensorInfo:
    """A type-02 body segment as a declared sensor (kind ``vio``: position + orientation in MVN's
    Z-up world), so the pose goes through the same conversion as every device frame."""
    return SensorInfo(f"mvn_{segment}", "vio", None, rate, world_up="z_up", position_unit=position_unit)


class MvnPoseEstimator:
    """Pass-through "estimator" of MVN's own pose (type 02): the 23 segment orientations, once in
    wearpose's Y-up world (the declared conversion), become SMPL global joint rotations by the
    segment-axes change (:data:`wearpose.geometry.MVN_TO_WEARPOSE`; identity at MVN's T-pose =
    SMPL's T-pose) and then local rotations (:data:`SMPL_FROM_MVN`: L5 unused, SMPL's hands take
    the MVN hands); root translation = the pelvis segment origin minus the body model's rest
    pelvis. The world heading differs from the sensors' by MVN's and wearpose's axis choices (a
    fixed yaw); local rotations do not depend on it."""

    name = "mvn-pose"
    kit_name = "mvn"
    body_asset_id = "default"
    fps = 0.0  # any rate
    causal = True
    lookahead = 0

    def __init__(self) -> None:
        self.sensor_names = tuple(f"mvn_{s}" for s in SEGMENTS)
        self._pelvis_rest = BodyModel().rest_joints()[0].double()

    def reset(self) -> None:
        pass

    def step(self, frame: Any) -> Any:
        idx = [frame.names.index(n) for n in self.sensor_names]
        R = torch.as_tensor(np.asarray(frame.channels["orientation"][idx], np.float64))  # segment -> Y-up world
        G = R[list(SMPL_FROM_MVN)] @ MVN_TO_WEARPOSE.T  # SMPL joint axes -> segment axes -> world
        valid = bool(np.all(frame.valid[idx]))
        local = global_to_local(G[None])[0].float() if valid else torch.eye(3).repeat(24, 1, 1)
        p = torch.as_tensor(np.asarray(frame.channels["position"][idx[0]], np.float64))
        trans = (p - self._pelvis_rest).float() if valid else None
        return PoseFrame(local, torch.zeros(10), trans, valid, frame.timestamp, extras={"source": "mvn type 02"})


def pose_frame(seq: int, t: float, positions: np.ndarray, R: np.ndarray) -> DeviceFrame:
    """A type-02 pose as a device frame of the 23 :func:`segment_info` sensors."""
    return DeviceFrame(seq, t, np.ones(len(SEGMENTS), bool), {"position": positions, "orientation": R})
