"""Packet codecs: round trips, and every malformed kind the replay tool injects is rejected."""

from __future__ import annotations

import json

import numpy as np
import pytest

from wearpose.stream import (
    HEADER,
    FramePacket,
    Hello,
    PacketError,
    PosePacket,
    ReorderBuffer,
    decode_frame_binary,
    decode_frame_json,
    decode_pose,
    encode_frame_binary,
    encode_frame_json,
    encode_pose_binary,
    encode_pose_json,
)
from wearpose.stream.packets import frame_channels
from wearpose.stream.replay import _malformed

HELLO = Hello(3, ("a", "b", "c"), ("position", "orientation"), 120.0, "binary")


def _frame(seed: int = 0) -> FramePacket:
    rng = np.random.default_rng(seed)
    data = rng.normal(size=(3, 12)).astype(np.float32)
    valid = np.array([True, False, True])
    data[1] = np.nan
    return FramePacket(3, 41, 12.5, valid, data)


def test_frame_round_trips_binary_and_json() -> None:
    pkt = _frame()
    msg = encode_frame_binary(pkt)
    assert len(msg) == HEADER.size + 3 * 12 * 4
    for back in (decode_frame_binary(msg, HELLO), decode_frame_json(json.loads(encode_frame_json(pkt, HELLO.channels)), HELLO)):
        assert (back.subject, back.seq, back.timestamp) == (3, 41, 12.5)
        np.testing.assert_array_equal(back.valid, pkt.valid)
        np.testing.assert_allclose(back.data[pkt.valid], pkt.data[pkt.valid], rtol=1e-6)
    ch = frame_channels(pkt.data, pkt.valid, HELLO.channels)
    assert ch["orientation"].shape == (3, 3, 3) and np.isnan(ch["position"][1]).all()


def test_validity_bits_cover_64_sensors() -> None:
    names = tuple(f"s{i}" for i in range(64))
    h = Hello(0, names, ("position",), 60.0)
    valid = np.arange(64) % 3 != 0
    pkt = FramePacket(0, 0, 0.0, valid, np.where(valid[:, None], 1.0, np.nan).astype(np.float32) * np.ones((64, 3), np.float32))
    np.testing.assert_array_equal(decode_frame_binary(encode_frame_binary(pkt), h).valid, valid)


def test_pose_round_trips() -> None:
    rng = np.random.default_rng(1)
    p = PosePacket(2, 7, 1.25, True, rng.normal(size=(24, 3, 3)).astype(np.float32), rng.normal(size=10).astype(np.float32),
                   None, rng.random(24).astype(np.float32), 3.5, 4.25, {"frame": "em_source"})
    for back in (decode_pose(encode_pose_binary(p)), decode_pose(encode_pose_json(p))):
        assert (back.subject, back.seq, back.timestamp, back.valid, back.trans) == (2, 7, 1.25, True, None)
        np.testing.assert_allclose(back.local_rot, p.local_rot, atol=1e-5)
        np.testing.assert_allclose(back.uncertainty, p.uncertainty, atol=1e-5)
        assert back.compute_ms == pytest.approx(3.5) and back.server_ms == pytest.approx(4.25)


@pytest.mark.parametrize("kind", range(8))
def test_injected_malformed_messages_are_rejected(kind: int) -> None:
    good = encode_frame_binary(_frame())
    bad = _malformed(kind, good, HELLO, np.random.default_rng(kind))
    with pytest.raises((PacketError, json.JSONDecodeError, ValueError)):
        if isinstance(bad, bytes):
            from wearpose.stream.packets import peek_subject

            if peek_subject(bad) != HELLO.subject:
                raise PacketError("unknown subject")
            decode_frame_binary(bad, HELLO)
        else:
            d = json.loads(bad)
            if d.get("type") != "frame":
                raise PacketError("unknown type")
            decode_frame_json(d, HELLO)


@pytest.mark.parametrize("bad", [
    {"subject": -1}, {"sensors": []}, {"channels": ["position", "colour"]}, {"rate": 0}, {"format": "xml"},
])
def test_bad_hello_is_rejected(bad: dict) -> None:
    d = json.loads(HELLO.to_json())
    d.update(bad)
    with pytest.raises(PacketError):
        Hello.from_dict(d)


def test_reorder_buffer() -> None:
    r = ReorderBuffer(window=3)
    assert r.push(0, 0) == [0]
    assert r.push(2, 2) == []  # waits for 1
    assert r.push(1, 1) == [1, 2]  # out of order, within the bound: nothing lost
    assert r.push(4, 4) == [] and r.push(5, 5) == []
    assert r.push(6, 6) == [4, 5, 6]  # 3 never came within 3 frames: given up
    assert r.lost == 1
    assert r.push(3, 3) == [] and r.late == 1  # too late: dropped, not estimated
    assert r.push(8, 8) == [] and r.push(8, 8) == [] and r.duplicate == 1
    assert r.flush() == [8] and r.lost == 2


def test_reorder_buffer_orders_across_the_u32_wrap_around() -> None:
    top = 2**32
    r = ReorderBuffer(window=3)
    assert r.push(top - 2, "a") == ["a"]
    assert r.push(0, "c") == []  # after top - 1: waits for it
    assert r.push(top - 1, "b") == ["b", "c"]  # swapped across the wrap, nothing lost
    assert r.push(2, "e") == [] and r.push(1, "d") == ["d", "e"]
    assert r.push(top - 1, "late") == [] and r.late == 1  # an old frame, not one 2**32 ahead
    assert r.push(5, "f") == []  # 3 and 4 missing: waited for
    assert r.push(6, "g") == ["f", "g"] and r.lost == 2  # 3 frames on: given up (never invented)
    assert (r.duplicate, r.late) == (0, 1)
