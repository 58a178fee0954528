"""Wire formats of the live inputs (no network): MVN datagrams, OSC bundles and profiles, the
LSL channel layout, and the device-frame conversion (the recording format's)."""

from __future__ import annotations

import struct

import numpy as np
import pytest
import torch

from wearpose.errors import InputFileError
from wearpose.geometry import axis_angle_to_matrix, matrix_to_quat
from wearpose.recording import Recording, SensorInfo, SensorStream
from wearpose.stream.inputs.base import DeviceFrame, canonical_channels, canonical_frame
from wearpose.stream.inputs.mvn import HEADER, decode_header, decode_pose, decode_trackers, encode_pose, encode_trackers
from wearpose.stream.inputs.osc import decode_bundle, encode_bundle, load_profile, parse_sensor_ports
from wearpose.stream.packets import PacketError


def _rot(n: int, seed: int = 0) -> np.ndarray:
    g = torch.Generator().manual_seed(seed)
    return axis_angle_to_matrix(torch.randn(n, 3, generator=g, dtype=torch.float64)).numpy()


def test_mvn_trackers_round_trip_and_header() -> None:
    R = _rot(3)
    q = matrix_to_quat(torch.from_numpy(R)).numpy()
    acc, mag = np.arange(9.0).reshape(3, 3), -np.arange(9.0).reshape(3, 3)
    d = encode_trackers(41, 1234, [1, 7, 15], q, acc, mag)
    assert d[:6] == b"MXTP23" and len(d) == HEADER.size + 3 * 44
    h = decode_header(d)
    assert (h["sample"], h["items"], h["time_ms"], h["datagram_counter"], h["size"]) == (41, 3, 1234, 0x80, 132)
    got = decode_trackers(d, h)
    assert list(got) == ["pelvis", "head", "left_hand"]  # segment ID = index + 1 (spec 3.1)
    assert np.allclose(got["head"][0], R[1], atol=1e-6) and np.allclose(got["left_hand"][1], acc[2])
    assert np.allclose(got["pelvis"][2], mag[0])


def test_mvn_pose_round_trip() -> None:
    R = _rot(23, 1)
    pos = np.random.default_rng(0).normal(size=(23, 3))
    d = encode_pose(5, 0, pos, matrix_to_quat(torch.from_numpy(R)).numpy())
    p, R2 = decode_pose(d, decode_header(d))
    assert np.allclose(p, pos, atol=1e-6) and np.allclose(R2, R, atol=1e-6)


@pytest.mark.parametrize("mutate, words", [
    (lambda d: d[:10], "shorter than"), (lambda d: b"MXTQ" + d[4:], "ID string"), (lambda d: d[:-4], "payload size"),
    (lambda d: d[:11] + bytes([d[11] + 1]) + d[12:], "items"),
    (lambda d: d[:24] + struct.pack(">i", 99) + d[28:], "segment ID 99"),
    (lambda d: d[:28] + struct.pack(">f", 3.0) + d[32:], "norm"),
])
def test_mvn_malformed_named(mutate, words) -> None:
    q = matrix_to_quat(torch.from_numpy(_rot(2))).numpy()
    d = mutate(encode_trackers(1, 0, [1, 2], q, np.zeros((2, 3)), np.zeros((2, 3))))
    with pytest.raises(PacketError, match=words):
        decode_trackers(d, decode_header(d))


def test_osc_bundle_time_tag_and_messages() -> None:
    t = 1.8e9 + 12.345678
    d = encode_bundle(t, [("/quaternion", [1.0, 0.0, 0.0, 0.0]), ("/linear", [0.1, 0.2, 0.3])])
    t2, msgs = decode_bundle(d)
    assert abs(t2 - t) < 1e-6
    assert [m[0] for m in msgs] == ["/quaternion", "/linear"] and np.allclose(msgs[1][1], [0.1, 0.2, 0.3])
    for bad in (d[:12], b"#bundle\x00" + d[8:16] + b"\x00\x00\x00\x08xxxxxxxx", b"/quaternion\x00,f\x00\x00"):
        with pytest.raises(PacketError):
            decode_bundle(bad)


def test_osc_profiles_ship_and_bad_ones_name_the_field(tmp_path) -> None:
    ng = load_profile("ngimu")
    info = ng.sensor_info("pelvis", 60.0)
    assert (info.acc_unit, info.acc_frame, info.acc_gravity, info.gyro_unit, info.world_up) == \
        ("g", "sensor", "removed", "deg/s", "z_up")
    assert load_profile("generic").devices == "address"
    p = tmp_path / "bad.yaml"
    p.write_text("devices: address\nmessages:\n  /{sensor}/q:\n    args: 3\n    channels:\n"
                 "      orientation: {from: 0}\n")
    with pytest.raises(InputFileError, match=r"messages//\{sensor\}/q/channels/orientation/from"):
        load_profile(p)
    assert parse_sensor_ports(["a=9000", "b=9001"]) == {"a": 9000, "b": 9001}
    assert parse_sensor_ports(["a", "b"]) == ["a", "b"]
    with pytest.raises(ValueError, match="NAME=PORT"):
        parse_sensor_ports(["a=9000", "b"])


def test_lsl_layout_from_metadata_and_errors() -> None:
    from wearpose.stream.inputs.lsl import layout_from_info, stream_info

    infos = [SensorInfo("wrist", "imu", None, 60.0, acc_unit="g", gyro_unit="deg/s"),
             SensorInfo("pelvis", "imu", "pelvis", 60.0)]
    chans = {"wrist": ["orientation", "acceleration", "angular_velocity"], "pelvis": ["orientation", "acceleration"]}
    info, cols = stream_info("layout-test", infos, chans, 60.0)
    sensors, index = layout_from_info(info)
    assert [s.name for s in sensors] == ["wrist", "pelvis"]
    assert (sensors[0].acc_unit, sensors[0].gyro_unit, sensors[1].acc_unit) == ("g", "deg/s", "m/s2")
    assert index["wrist"]["orientation"] == [0, 1, 2, 3] and len(cols) == 10 + 7
    import pylsl

    bad = pylsl.StreamInfo("bad", "MoCap", 1, 60.0, "float32", "x")
    bad.desc().append_child("channels").append_child("channel").append_child_value("label", "wrist_qw")
    with pytest.raises(PacketError, match="channel 0: label 'wrist_qw'"):
        layout_from_info(bad)


def test_device_frame_converts_like_the_file() -> None:
    """A frame declared in a device's conventions gives what Recording.to_canonical gives."""
    R = _rot(2, 3)
    acc = np.array([[0.1, 0.2, 1.1], [-0.3, 0.0, 0.9]])  # g, sensor frame, gravity included
    gyro = np.array([[10.0, -20.0, 5.0], [1.0, 2.0, 3.0]])
    infos = [SensorInfo(n, "imu", None, 60.0, acc_unit="g", acc_frame="sensor", acc_gravity="included",
                        world_up="z_up", gyro_unit="deg/s") for n in ("a", "b")]
    chans = canonical_channels(infos)
    out = canonical_frame(infos, DeviceFrame(0, 0.0, np.array([True, True]),
                                             {"orientation": R, "acceleration": acc, "angular_velocity": gyro}), chans)
    rec = Recording([SensorStream(i, np.array([0.0]), np.array([True]), orientation=R[j:j + 1].astype(np.float32),
                                  acceleration=acc[j:j + 1].astype(np.float32),
                                  angular_velocity=gyro[j:j + 1].astype(np.float32))
                     for j, i in enumerate(infos)]).to_canonical()
    for j, s in enumerate(rec.sensors):
        a = 0
        for c in chans:
            n = 9 if c == "orientation" else 3
            v = getattr(s, c)
            if v is not None:
                assert np.allclose(out[j, a:a + n], v[0].reshape(-1), atol=1e-6), c
            a += n
    # a valid sensor with a NaN is malformed; an invalid one is NaN
    with pytest.raises(PacketError, match="non-finite"):
        canonical_frame(infos, DeviceFrame(0, 0.0, np.array([True, True]), {
            "orientation": R, "acceleration": np.array([[np.nan, 0, 0], [0, 0, 1.0]]), "angular_velocity": gyro}), chans)
    masked = canonical_frame(infos, DeviceFrame(0, 0.0, np.array([False, True]),
                                                {"orientation": R, "acceleration": acc, "angular_velocity": gyro}), chans)
    assert np.isnan(masked[0]).all() and np.isfinite(masked[1, :15]).all()  # 15: all but the magnetic field


def test_osc_frames_wait_for_a_device_whose_socket_drains_later() -> None:
    """Each NGIMU has its own socket: on a busy server one device's backlog is read ahead of
    another's. A frame is only incomplete for a sensor once that sensor's own stream moved past it."""
    from wearpose.stream.inputs.osc import OscInput

    src = OscInput("ngimu", {"a": 9100, "b": 9101}, 60.0)
    frames = []
    src.attach(frames.append, lambda exc: frames.append(exc))

    def bundle(k: int) -> bytes:
        return encode_bundle(1.8e9 + k / 60.0, [("/quaternion", [1.0, 0, 0, 0]), ("/sensors", [0.0] * 10),
                                               ("/linear", [0.0, 0.0, 0.0])])

    for k in range(10):
        src.datagram(bundle(k), ["a"])  # device a's whole backlog first
    for k in range(10):
        if k != 4:  # device b lost frame 4
            src.datagram(bundle(k), ["b"])
    # 4 waits until b has sent frame 6 (window 2), after the complete 5; then in order
    assert [f.seq for f in frames] == [0, 1, 2, 3, 5, 4, 6, 7, 8, 9]
    masked = {f.seq: f.valid.tolist() for f in frames}
    assert masked[4] == [True, False] and all(v == [True, True] for k, v in masked.items() if k != 4)
