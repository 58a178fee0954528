"""Hostile input to the live-input decoders (hypothesis), as tests/stream/test_packets_fuzz.py
does for the stream server's packets: an Xsens MVN datagram, an OSC bundle or an LSL sample is
decoded or raises :class:`PacketError`, the documented error, and nothing else; the inputs'
receive paths (``MvnInput.datagram``, ``OscInput.datagram``, ``LslInput._samples``) count a bad
one as malformed and never raise (an exception there would end the UDP protocol's callback or
the LSL pull).

CI runs 200 inputs per strategy; ``WEARPOSE_FUZZ_EXAMPLES=10000`` runs 10 000
(``python benchmarks/inputs_fuzz.py``, results in benchmarks/results/inputs_fuzz.md).
"""

from __future__ import annotations

import collections
import math
import struct

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from tests.stream.test_packets_fuzz import FUZZ
from wearpose.stream.inputs.base import DeviceFrame
from wearpose.stream.inputs.mvn import (
    HEADER,
    SEGMENT,
    SEGMENTS,
    TRACKER,
    TYPE_POSE_QUAT,
    TYPE_TRACKERS,
    MvnInput,
    decode_header,
    decode_pose,
    decode_trackers,
    encode_header,
    encode_pose,
    encode_trackers,
)
from wearpose.stream.inputs.osc import OscInput, decode_bundle, encode_bundle
from wearpose.stream.packets import PacketError

#: Inputs tried per test (datagrams, bundles, samples), read by benchmarks/inputs_fuzz.py.
TRIED: collections.Counter[str] = collections.Counter()


def _tried(test: str, n: int = 1) -> None:
    TRIED[test] += n


#: Every float32 (NaN, infinities, subnormals, huge) and every int32.
F32 = st.floats(width=32, allow_nan=True, allow_infinity=True)
I32 = st.integers(-2**31, 2**31 - 1)


def _flip(valid: bytes) -> st.SearchStrategy:
    """``valid`` with one byte set to any value."""
    return st.tuples(st.integers(0, len(valid) - 1), st.integers(0, 255)).map(
        lambda a: valid[:a[0]] + bytes([a[1]]) + valid[a[0] + 1:])


# ------------------------------------------------------------------------- Xsens MVN
_UNIT_Q = np.tile([1.0, 0.0, 0.0, 0.0], (23, 1))
VALID_TRACKERS = encode_trackers(7, 100, [1, 7, 15], _UNIT_Q[:3], np.zeros((3, 3)), np.ones((3, 3)))
VALID_POSE = encode_pose(7, 100, np.zeros((23, 3)), _UNIT_Q)


def _mvn_header(kind: bytes, items: int, payload: int) -> st.SearchStrategy:
    """A header MvnInput accepts (character 0, one datagram per sample) or one with any field."""
    ok = st.builds(lambda s, t: encode_header(kind, s, items, t, payload), st.integers(0, 2**32 - 1), st.integers(0, 2**32 - 1))
    anyh = st.builds(lambda ident, s, d, n, t, c, g, p, f, r, z: HEADER.pack(ident, s, d, n, t, c, g, p, f, r, z),
                     st.just(b"MXTP" + kind) | st.binary(min_size=6, max_size=6), st.integers(0, 2**32 - 1),
                     st.integers(0, 255), st.just(items) | st.integers(0, 255), st.integers(0, 2**32 - 1),
                     st.integers(0, 255), st.integers(0, 255), st.integers(0, 255), st.integers(0, 255),
                     st.binary(min_size=2, max_size=2), st.just(payload) | st.integers(0, 0xFFFF))
    return ok | anyh


def _records(kind: bytes, rec: struct.Struct, ids: st.SearchStrategy, max_n: int) -> st.SearchStrategy:
    """A header of ``kind`` and ``n`` records of ``rec`` with any segment IDs and any float32 values."""
    n_floats = (rec.size - 4) // 4  # an int32 ID, then float32s
    record = st.builds(lambda i, xs: rec.pack(i, *xs), ids, st.lists(F32, min_size=n_floats, max_size=n_floats))

    def datagram(recs: list[bytes]) -> st.SearchStrategy:
        body = b"".join(recs)
        return _mvn_header(kind, len(recs), len(body)).map(lambda h: h + body)

    return st.lists(record, max_size=max_n).flatmap(datagram)


MVN_DATAGRAMS = (st.binary(max_size=1200)  # anything
                 | st.tuples(_mvn_header(TYPE_TRACKERS, 3, 132), st.binary(max_size=300)).map(b"".join)  # any payload
                 | _records(TYPE_TRACKERS, TRACKER, st.integers(0, 25) | I32, 25)  # any IDs and values
                 | _records(TYPE_POSE_QUAT, SEGMENT, st.integers(1, 23) | I32, 26)
                 | st.lists(F32, min_size=23 * 7, max_size=23 * 7).map(  # 23 segments in order, any float values
                     lambda xs: encode_header(TYPE_POSE_QUAT, 1, 23, 0, 23 * SEGMENT.size)
                     + b"".join(SEGMENT.pack(k + 1, *xs[7 * k:7 * k + 7]) for k in range(23)))
                 | _flip(VALID_TRACKERS) | _flip(VALID_POSE))


@FUZZ
@given(MVN_DATAGRAMS)
def test_mvn_decoders_raise_only_packet_error(data: bytes) -> None:
    _tried("test_mvn_decoders_raise_only_packet_error")
    try:
        h = decode_header(data)
    except PacketError:
        return
    try:
        got = decode_trackers(data, h)
    except PacketError:
        got = {}
    for name, (R, acc, mag) in got.items():
        assert name in SEGMENTS and R.shape == (3, 3) and np.isfinite(R).all()
        assert np.isfinite(acc).all() and np.isfinite(mag).all()
    try:
        pos, R = decode_pose(data, h)
    except PacketError:
        return
    assert pos.shape == (23, 3) and R.shape == (23, 3, 3) and np.isfinite(pos).all() and np.isfinite(R).all()


@FUZZ
@given(st.lists(MVN_DATAGRAMS, min_size=1, max_size=4))
def test_mvn_input_counts_hostile_datagrams_and_never_raises(datagrams: list[bytes]) -> None:
    _tried("test_mvn_input_counts_hostile_datagrams_and_never_raises", len(datagrams))
    src = MvnInput("127.0.0.1", 0, segments=["pelvis", "head", "left_hand"], rate=60.0)
    frames, bad, poses = [], [], []
    src.attach(frames.append, bad.append)
    src.on_pose = lambda *a: poses.append(a)
    for d in datagrams:
        src.datagram(d)
    assert all(isinstance(e, PacketError) for e in bad)
    assert src.counts["datagrams"] == len(datagrams) and src.counts["malformed"] == len(bad)
    for f in frames:
        _check_frame(f, 3)


def _check_frame(f: DeviceFrame, S: int) -> None:
    assert isinstance(f, DeviceFrame) and f.valid.shape == (S,) and f.valid.dtype == bool
    assert 0 <= f.seq <= 0xFFFFFFFF and math.isfinite(f.timestamp)
    for c, v in f.channels.items():
        assert v.shape[0] == S and np.isfinite(v[f.valid]).all(), c


# ------------------------------------------------------------------------- OSC
OSC_ARG = F32 | st.integers(-2**31, 2**31 - 1) | st.text(max_size=6) | st.booleans() | st.binary(max_size=6)
OSC_ADDRESSES = st.sampled_from(["/quaternion", "/sensors", "/linear", "/a/quaternion", "/b/sensors"]) \
    | st.text(max_size=12).map(lambda s: "/" + s)
NGIMU_QUAT = encode_bundle(1.8e9, [("/quaternion", [1.0, 0.0, 0.0, 0.0]), ("/sensors", [0.0] * 10),
                                   ("/linear", [0.0, 0.0, 0.0])])


def _osc_string(b: bytes) -> bytes:
    """OSC 1.0 string: the bytes, a NUL, padded with NULs to a multiple of 4."""
    return b + b"\x00" * (4 - len(b) % 4)


def _osc_message(addr: str, args: list) -> bytes:
    """An OSC 1.0 message, encoded here (python-osc's builder re-parses what it builds and fails
    on some values): any address and typed arguments, float32 ``f``, int32 ``i``, string ``s``,
    blob ``b``, booleans ``T``/``F``."""
    tags, data = ",", b""
    for a in args:
        if isinstance(a, bool):
            tags += "T" if a else "F"
        elif isinstance(a, int):
            tags, data = tags + "i", data + struct.pack(">i", a)
        elif isinstance(a, float):
            tags, data = tags + "f", data + struct.pack(">f", a)
        elif isinstance(a, str):
            tags, data = tags + "s", data + _osc_string(a.encode("utf-8", "surrogatepass"))
        else:
            tags, data = tags + "b", data + struct.pack(">i", len(a)) + a + b"\x00" * (-len(a) % 4)
    return _osc_string(addr.encode("utf-8", "surrogatepass")) + _osc_string(tags.encode()) + data


def _bundle(t: tuple[int, int], msgs: list[bytes]) -> bytes:
    return b"#bundle\x00" + struct.pack(">II", *t) + b"".join(struct.pack(">i", len(m)) + m for m in msgs)


OSC_MESSAGES = st.builds(_osc_message, OSC_ADDRESSES, st.lists(OSC_ARG, max_size=12))
OSC_BUNDLES = (st.binary(max_size=600)  # anything
               | st.binary(max_size=400).map(lambda b: b"#bundle\x00" + b)  # a bundle tag, anything after
               | st.builds(_bundle, st.tuples(st.integers(0, 2**32 - 1), st.integers(0, 2**32 - 1)),
                           st.lists(OSC_MESSAGES | st.binary(max_size=40), max_size=5))  # well framed, any messages
               | st.builds(_bundle, st.just((3_000_000_000, 0)),
                           st.lists(st.builds(_osc_message, st.sampled_from(["/quaternion", "/sensors", "/linear"]),
                                              st.lists(F32, max_size=11)), min_size=1, max_size=3))  # any floats
               | _flip(NGIMU_QUAT))


@FUZZ
@given(OSC_BUNDLES)
def test_osc_decode_bundle_raises_only_packet_error(data: bytes) -> None:
    _tried("test_osc_decode_bundle_raises_only_packet_error")
    try:
        t, msgs = decode_bundle(data)
    except PacketError:
        return
    assert math.isfinite(t) and all(isinstance(a, str) and isinstance(p, list) for a, p in msgs)


@FUZZ
@given(st.lists(st.tuples(OSC_BUNDLES, st.sampled_from(["a", "b"])), min_size=1, max_size=4))
def test_osc_input_counts_hostile_bundles_and_never_raises(datagrams: list[tuple[bytes, str]]) -> None:
    _tried("test_osc_input_counts_hostile_bundles_and_never_raises", len(datagrams))
    src = OscInput("ngimu", {"a": 9100, "b": 9101}, 60.0)
    frames, bad = [], []
    src.attach(frames.append, bad.append)
    for d, dev in datagrams:
        src.datagram(d, [dev])
    assert all(isinstance(e, PacketError) for e in bad) and src.counts["malformed"] == len(bad)
    for f in frames:
        _check_frame(f, 2)


# ------------------------------------------------------------------------- LSL
@pytest.fixture(scope="module")
def lsl_layout():
    pytest.importorskip("pylsl", reason="LSL needs the devices extra (pylsl)")
    from wearpose.recording import SensorInfo
    from wearpose.stream.inputs.lsl import layout_from_info, stream_info

    infos = [SensorInfo(n, "imu", n, 60.0) for n in ("pelvis", "head")]
    chans = {n: ["orientation", "acceleration", "angular_velocity"] for n in ("pelvis", "head")}
    info, cols = stream_info("fuzz", infos, chans, 60.0)
    return (*layout_from_info(info, None), len(cols))


# LSL carries float32 samples of the declared width (per sensor: w x y z, acc xyz, gyro xyz); the
# sender sets each time stamp (any double). Rows: a valid sample, one with a sensor missing (NaN),
# or all missing, with any values written over some columns.
_GOOD = [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]
_BASES = [_GOOD * 2, _GOOD + [float("nan")] * 10, [float("nan")] * 20]
LSL_ROW = st.tuples(st.sampled_from(_BASES), st.dictionaries(st.integers(0, 19), F32, max_size=20)).map(
    lambda a: [a[1].get(i, v) for i, v in enumerate(a[0])])
LSL_ROWS = st.integers(1, 5).flatmap(lambda n: st.tuples(
    st.lists(LSL_ROW, min_size=n, max_size=n),
    st.lists(st.floats(allow_nan=True, allow_infinity=True) | st.floats(0, 1e6), min_size=n, max_size=n)))


@FUZZ
@given(LSL_ROWS)
def test_lsl_samples_count_hostile_values_and_never_raise(lsl_layout, rows: tuple[list, list]) -> None:
    from wearpose.stream.inputs.lsl import LslInput

    sensors, index, width = lsl_layout
    assert width == 20
    src = LslInput("fuzz")
    src.sensors, src._index, src.rate = sensors, index, sensors[0].rate
    frames, bad = [], []
    src.attach(frames.append, bad.append)
    chunk, ts = rows
    _tried("test_lsl_samples_count_hostile_values_and_never_raise", len(ts))
    src._samples(np.asarray(chunk, np.float32).astype(np.float64), ts)
    assert all(isinstance(e, PacketError) for e in bad) and len(frames) + len(bad) == len(ts)
    for f in frames:
        _check_frame(f, 2)


def test_lsl_sample_with_a_non_finite_time_stamp_is_malformed(lsl_layout) -> None:
    """Found by the 10 000-example run: an LSL sender sets each sample's time stamp, and a NaN or
    infinite one raised ValueError / OverflowError out of the pull callback (the frame number)."""
    from wearpose.stream.inputs.lsl import LslInput

    sensors, index, _ = lsl_layout
    src = LslInput("fuzz")
    src.sensors, src._index, src.rate = sensors, index, sensors[0].rate
    frames, bad = [], []
    src.attach(frames.append, bad.append)
    row = [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0] * 2
    src._samples(np.array([row] * 5), [float("nan"), 10.0, float("inf"), 1e308 * 10 - 1e308, 10.5])
    assert [f.seq for f in frames] == [0, 30] and len(bad) == 3
    assert all(isinstance(e, PacketError) and "time stamp" in str(e) for e in bad)
