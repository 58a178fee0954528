"""load_recording: every malformed file raises InputFileError naming the field and the problem."""

from __future__ import annotations

import json

import numpy as np
import pytest

from recording_testutils import two_sensor_recording
from wearpose.errors import InputFileError
from wearpose.recording import Recording, SensorInfo, SensorStream, load_recording, recording_arrays

IMU = "sensors/left_forearm"
EM = "sensors/right_forearm"


def _write(tmp_path, arrays, name="r.npz"):
    p = tmp_path / name
    np.savez(p, **arrays)
    return p


def _arrays():
    return recording_arrays(two_sensor_recording())


def _header(a):
    return json.loads(str(a["header"]))


def _set_header(a, h):
    a["header"] = np.array(json.dumps(h))


def _err(tmp_path, arrays) -> InputFileError:
    p = _write(tmp_path, arrays)
    with pytest.raises(InputFileError) as ei:
        load_recording(p)
    assert str(p) in str(ei.value)
    return ei.value


def test_valid_file_loads(tmp_path):
    rec = load_recording(_write(tmp_path, _arrays()))
    assert rec.names == ("left_forearm", "right_forearm")


def test_missing_file(tmp_path):
    with pytest.raises(InputFileError, match="file not found"):
        load_recording(tmp_path / "nope.npz")


def test_not_an_npz(tmp_path):
    p = tmp_path / "junk.npz"
    p.write_bytes(b"hello, not a zip")
    with pytest.raises(InputFileError, match=r"not an npz \(zip\) archive"):
        load_recording(p)


def test_newer_version(tmp_path):
    a = _arrays()
    a["version"] = np.array(2)
    e = _err(tmp_path, a)
    assert e.field == "version" and "newer" in e.problem and "upgrade" in e.expected


def test_unknown_format(tmp_path):
    a = _arrays()
    a["format"] = np.array("something.else")
    assert _err(tmp_path, a).field == "format"


def test_truncated_channel(tmp_path):
    a = _arrays()
    a[f"{IMU}/acceleration"] = a[f"{IMU}/acceleration"][:100]
    e = _err(tmp_path, a)
    assert e.field == f"{IMU}/acceleration" and "truncated" in e.problem and "120" in e.problem


def test_nan_only_allowed_in_invalid_frames(tmp_path):
    a = _arrays()
    acc = a[f"{IMU}/acceleration"].copy()
    acc[5] = np.nan  # frame 5 is invalid: fine
    a[f"{IMU}/acceleration"] = acc
    load_recording(_write(tmp_path, a, "ok.npz"))
    acc[7] = np.inf  # frame 7 is valid
    e = _err(tmp_path, a)
    assert e.field == f"{IMU}/acceleration" and "valid frame 7" in e.problem


def test_wrong_shape(tmp_path):
    a = _arrays()
    a[f"{EM}/position"] = np.zeros((120, 2), np.float32)
    e = _err(tmp_path, a)
    assert e.field == f"{EM}/position" and "(120, 2)" in e.problem and "(N, 3)" in e.expected


def test_non_increasing_timestamps(tmp_path):
    a = _arrays()
    t = a[f"{EM}/timestamps"].copy()
    t[50] = t[49]
    a[f"{EM}/timestamps"] = t
    e = _err(tmp_path, a)
    assert e.field == f"{EM}/timestamps" and "strictly increasing" in e.problem


def test_orientation_not_a_rotation(tmp_path):
    a = _arrays()
    q = a[f"{IMU}/orientation"].copy()
    q[3] *= 1.5
    a[f"{IMU}/orientation"] = q
    e = _err(tmp_path, a)
    assert e.field == f"{IMU}/orientation" and "frame 3" in e.problem
    a = _arrays()
    R = np.tile(np.eye(3), (120, 1, 1))
    R[8] = np.diag([1.0, 1.0, -1.0])  # a reflection: orthonormal but det -1
    a[f"{EM}/orientation"] = R
    e = _err(tmp_path, a)
    assert e.field == f"{EM}/orientation" and "not a rotation" in e.problem and "det" in e.problem


def test_positions_in_millimetres(tmp_path):
    a = _arrays()
    a[f"{EM}/position"] = a[f"{EM}/position"] * 1000
    e = _err(tmp_path, a)
    assert e.field == f"{EM}/position" and "looks like millimetres or centimetres" in e.problem
    assert "declare" in e.expected


def _static_g_recording(acc_scale: float, **info_kw) -> Recording:
    n = 240
    rng = np.random.default_rng(0)
    acc = np.tile([0.0, 1.0, 0.0], (n, 1)) * acc_scale + rng.normal(scale=0.002 * acc_scale, size=(n, 3))
    acc[120:] += rng.normal(scale=0.5 * acc_scale, size=(120, 3))  # then moving
    info = SensorInfo("wrist", "imu", rate=60.0, acc_gravity="included", **info_kw)
    return Recording([SensorStream(info, np.arange(n) / 60, np.ones(n, bool),
                                   orientation=np.tile(np.eye(3), (n, 1, 1)), acceleration=acc)])


def test_acceleration_in_g_declared_m_s2(tmp_path):
    p = _static_g_recording(1.0).save(tmp_path / "g.npz")  # the writer does not judge; the reader does
    with pytest.raises(InputFileError) as ei:
        load_recording(p)
    assert ei.value.field == "sensors/wrist/acceleration" and "looks like g" in ei.value.problem
    # Declared correctly, the same data loads; and m/s^2 data declared m/s^2 loads.
    load_recording(_static_g_recording(1.0, acc_unit="g").save(tmp_path / "g_ok.npz"))
    load_recording(_static_g_recording(9.81).save(tmp_path / "ms2.npz"))
    # Declared gravity-removed but the static reading is 1 g: gravity is still in.
    bad = _static_g_recording(9.81)
    bad.sensors[0].info = SensorInfo("wrist", "imu", rate=60.0, acc_gravity="removed")
    with pytest.raises(InputFileError, match="gravity is included"):
        load_recording(bad.save(tmp_path / "grav.npz"))
    # The check can be skipped when the caller knows better.
    load_recording(tmp_path / "g.npz", check_conventions=False)


def test_timestamps_in_milliseconds(tmp_path):
    a = _arrays()
    a[f"{IMU}/timestamps"] = a[f"{IMU}/timestamps"] * 1000
    e = _err(tmp_path, a)
    assert e.field == f"{IMU}/timestamps" and "milliseconds" in e.problem


def test_unknown_kind(tmp_path):
    a = _arrays()
    h = _header(a)
    h["sensors"][0]["kind"] = "lidar"
    _set_header(a, h)
    e = _err(tmp_path, a)
    assert e.field == f"{IMU}/kind" and "unknown kind 'lidar'" in e.problem and "em6dof" in e.expected


def test_unknown_and_missing_fields(tmp_path):
    a = _arrays()
    a[f"{IMU}/accel"] = a[f"{IMU}/acceleration"]
    e = _err(tmp_path, a)
    assert e.field == f"{IMU}/accel" and "unknown field" in e.problem
    a = _arrays()
    del a[f"{IMU}/acceleration"]
    e = _err(tmp_path, a)
    assert e.field == f"{IMU}/acceleration" and "missing" in e.problem
    a = _arrays()
    del a[f"{EM}/timestamps"]
    assert _err(tmp_path, a).field == f"{EM}/timestamps"
    a = _arrays()
    a["sensors/ghost/timestamps"] = np.arange(3.0)
    assert "does not list" in _err(tmp_path, a).problem


def test_bad_header(tmp_path):
    a = _arrays()
    a["header"] = np.array("{not json")
    assert _err(tmp_path, a).field == "header"
    a = _arrays()
    h = _header(a)
    h["sensors"][1]["acc_units"] = "g"  # typo of acc_unit
    _set_header(a, h)
    assert "unknown key" in _err(tmp_path, a).problem


def test_integer_valid_mask_accepted(tmp_path):
    a = _arrays()
    a[f"{IMU}/valid"] = a[f"{IMU}/valid"].astype(np.uint8)
    rec = load_recording(_write(tmp_path, a))
    assert rec.sensor("left_forearm").valid.dtype == bool


def test_ground_truth_errors(tmp_path):
    a = recording_arrays(two_sensor_recording(with_gt=True))
    a["ground_truth/trans"] = a["ground_truth/trans"][:10]
    e = _err(tmp_path, a)
    assert e.field == "ground_truth/trans" and "truncated" in e.problem


def test_g_and_sensor_frame_diagnosed_by_name(tmp_path):
    """A recording written with raw accelerometer data (g, sensor frame, gravity in) but no
    declaration is diagnosed as exactly that."""
    from recording_testutils import rotations

    n = 240
    R = np.repeat(rotations(1, seed=3, speed=1.0), n, axis=0)  # a tilted sensor, at rest for 2 s
    R[120:] = rotations(120, seed=4, speed=0.2)  # then moving
    rng = np.random.default_rng(1)
    f_world = np.tile([0.0, 1.0, 0.0], (n, 1))  # +1 g up at rest
    f_world[120:] += rng.normal(scale=0.5, size=(120, 3))
    f_sensor = np.einsum("nji,nj->ni", R, f_world) + rng.normal(scale=0.002, size=(n, 3))
    info = SensorInfo("wrist", "imu", rate=60.0)  # defaults: m/s^2, world frame, gravity removed
    rec = Recording([SensorStream(info, np.arange(n) / 60, np.ones(n, bool), orientation=R, acceleration=f_sensor)])
    with pytest.raises(InputFileError) as ei:
        load_recording(rec.save(tmp_path / "raw.npz"))
    e = ei.value
    assert e.field == "sensors/wrist/acceleration"
    assert "looks like g" in e.problem and "looks like the sensor frame" in e.problem and "gravity is included" in e.problem
    assert "acc_unit 'g'" in e.expected and "acc_frame 'sensor'" in e.expected
    rec.sensors[0].info = SensorInfo("wrist", "imu", rate=60.0, acc_unit="g", acc_frame="sensor", acc_gravity="included")
    ok = load_recording(rec.save(tmp_path / "declared.npz")).to_canonical()
    np.testing.assert_allclose(ok.sensor("wrist").acceleration[:100], 0.0, atol=0.1)  # 0.002 g noise


def test_z_up_orientations_diagnosed(tmp_path):
    """Orientations from a Z-up world declared as Y-up: gravity's reaction lines up with Z."""
    from recording_testutils import rotations

    n = 240
    R = np.repeat(rotations(1, seed=5, speed=1.0), n, axis=0)
    f_world_zup = np.tile([0.0, 0.0, 9.81], (n, 1))  # +1 g along Z: the device's world is Z up
    f_sensor = np.einsum("nji,nj->ni", R, f_world_zup)
    info = SensorInfo("wrist", "imu", rate=60.0, acc_frame="sensor", acc_gravity="included")  # world_up y_up
    rec = Recording([SensorStream(info, np.arange(n) / 60, np.ones(n, bool), orientation=R, acceleration=f_sensor)])
    with pytest.raises(InputFileError) as ei:
        load_recording(rec.save(tmp_path / "zup.npz"))
    assert "look like a z-up world" in ei.value.problem and "world_up 'z_up'" in ei.value.expected
    rec.sensors[0].info = SensorInfo("wrist", "imu", rate=60.0, acc_frame="sensor", acc_gravity="included", world_up="z_up")
    ok = load_recording(rec.save(tmp_path / "declared.npz")).to_canonical()
    np.testing.assert_allclose(ok.sensor("wrist").acceleration, 0.0, atol=1e-4)
