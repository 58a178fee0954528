"""Recording type: construction, queries, conventions (to_canonical), common grid, round trip."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import torch

from recording_testutils import em_stream, imu_stream, rotations, two_sensor_recording
from wearpose.errors import ShapeError, WearposeError
from wearpose.geometry import Z_UP_TO_Y_UP
from wearpose.recording import Recording, RecordingError, SensorInfo, SensorStream, load_recording


def test_queries_and_masking():
    rec = two_sensor_recording()
    assert rec.names == ("left_forearm", "right_forearm")
    assert rec.kinds == ("em6dof", "imu")
    assert rec.duration == pytest.approx(119 / 60)
    s = rec.sensor("left_forearm")
    assert s.kind == "imu" and s.num_frames == 120
    # Dropped frames are masked and carry no data (NaN), never a stale or invented value.
    assert not s.valid[5] and np.isnan(s.acceleration[5]).all() and np.isnan(s.orientation[5]).all()
    assert np.isfinite(s.acceleration[s.valid]).all()
    with pytest.raises(KeyError, match="left_forearm"):
        rec.sensor("nope")


@pytest.mark.parametrize("mutate, match", [
    (lambda kw: kw.pop("acceleration"), "acceleration: missing"),
    (lambda kw: kw.update(acceleration=np.full((10, 3), np.nan)), "NaN or infinite value in valid frame 0"),
    (lambda kw: kw.update(orientation=np.tile(2 * np.eye(3), (10, 1, 1))), "not a rotation"),
    (lambda kw: kw.update(timestamps=np.r_[np.arange(9) / 60, 0.0]), "not strictly increasing"),
    (lambda kw: kw.update(acceleration=np.zeros((9, 3))), "truncated"),
    (lambda kw: kw.update(position=np.zeros((10, 3))), "not allowed for a imu"),
])
def test_stream_validation(mutate, match):
    kw = dict(timestamps=np.arange(10) / 60, valid=np.ones(10, bool), orientation=np.tile(np.eye(3), (10, 1, 1)),
              acceleration=np.zeros((10, 3)))
    mutate(kw)
    with pytest.raises(ShapeError, match=match):
        SensorStream(SensorInfo("a", "imu", rate=60), **kw)


def test_info_validation():
    with pytest.raises(ShapeError, match="unknown kind"):
        SensorInfo("a", "lidar")
    with pytest.raises(ShapeError, match="acc_unit"):
        SensorInfo("a", "imu", acc_unit="ft/s2")
    with pytest.raises(ShapeError, match="name"):
        SensorInfo("a/b", "imu")
    with pytest.raises(ShapeError):
        Recording([imu_stream(), imu_stream()])  # duplicate names


def _declared_imu(n=200, rate=60.0):
    """Truth (Y-up, free acc) and the same data written as g, sensor frame, gravity included, Z up."""
    rng = np.random.default_rng(3)
    R = rotations(n, 7, speed=0.1)  # sensor -> Y-up world
    a = rng.normal(scale=3.0, size=(n, 3))  # free acceleration, Y-up world, m/s^2
    C = Z_UP_TO_Y_UP.numpy()
    Rz = C.T @ R  # sensor -> Z-up world
    f_z = (a - np.array([0, -9.81, 0])) @ C  # specific force in Z-up world: C^T (a - g)
    f_s = np.einsum("nji,nj->ni", Rz, f_z)  # sensor frame: Rz^T f
    info = SensorInfo("wrist", "imu", rate=rate, acc_unit="g", acc_frame="sensor", acc_gravity="included",
                      world_up="z_up", gyro_unit="deg/s")
    w = rng.normal(size=(n, 3))
    s = SensorStream(info, np.arange(n) / rate, np.ones(n, bool), orientation=Rz, acceleration=f_s / 9.81,
                     angular_velocity=np.rad2deg(w))
    return s, R, a, w


def test_to_canonical_converts_every_declared_convention():
    s, R, a, w = _declared_imu()
    em = em_stream()
    em_mm = SensorStream(dataclasses.replace(em.info, name="em_mm", position_unit="mm"), em.timestamps, em.valid,
                         position=em.position.astype(np.float64) * 1000, orientation=em.orientation)
    rec = Recording([s, em_mm])
    assert not rec.is_canonical
    can = rec.to_canonical()
    c = can.sensor("wrist")
    assert c.info.is_canonical and can.is_canonical
    np.testing.assert_allclose(c.orientation, R, atol=1e-10)
    np.testing.assert_allclose(c.acceleration, a, atol=1e-9)
    np.testing.assert_allclose(c.angular_velocity, w, atol=1e-12)  # sensor frame: only the unit changes
    np.testing.assert_allclose(can.sensor("em_mm").position, em.position, atol=1e-6)
    assert can.meta["converted_to_canonical"] == ["em_mm", "wrist"]
    # Converting twice changes nothing: the conventions are now declared canonical.
    again = can.to_canonical()
    np.testing.assert_array_equal(again.sensor("wrist").acceleration, c.acceleration)
    # The original is untouched.
    assert rec.sensor("wrist").info.acc_unit == "g"


def test_declared_as_is_the_inverse_of_to_canonical():
    s, R, a, w = _declared_imu()
    can = Recording([s, em_stream()]).to_canonical()
    dec = can.declared_as(position_unit="mm", gyro_unit="deg/s", acc_unit="g", acc_frame="sensor",
                          acc_gravity="included", world_up="z_up")
    # The same file a device in those conventions writes (the hand-built one above) ...
    d = dec.sensor("wrist")
    assert d.info == s.info
    np.testing.assert_allclose(d.acceleration, s.acceleration, atol=1e-6)
    np.testing.assert_allclose(d.orientation, s.orientation, atol=1e-9)
    np.testing.assert_allclose(d.angular_velocity, s.angular_velocity, atol=1e-9)
    e = dec.sensor(em_stream().info.name)
    assert e.info.position_unit == "mm" and e.info.world_up == "z_up" and not e.info.is_canonical
    # ... and back: the canonical data, masks and NaNs of dropped frames as they were.
    back = dec.to_canonical()
    for name in can.names:
        for ch, x in can.sensor(name).channels().items():
            np.testing.assert_allclose(getattr(back.sensor(name), ch), x, atol=1e-5, err_msg=f"{name} {ch}")
        np.testing.assert_array_equal(back.sensor(name).valid, can.sensor(name).valid)
    with pytest.raises(RecordingError, match="needs a canonical recording"):
        dec.declared_as(position_unit="cm")


def test_declared_as_sensor_frame_needs_orientation():
    n = 20
    info = SensorInfo("m", "mimu", rate=50)
    s = SensorStream(info, np.arange(n) / 50, np.ones(n, bool), acceleration=np.zeros((n, 3)),
                     angular_velocity=np.zeros((n, 3)), magnetic_field=np.ones((n, 3)))
    with pytest.raises(RecordingError, match="sensor 'm': sensor-frame acceleration needs an 'orientation'"):
        Recording([s]).declared_as(acc_frame="sensor")


def test_to_canonical_mimu_without_orientation_keeps_sensor_frame():
    n = 50
    info = SensorInfo("m", "mimu", rate=50, acc_unit="g", acc_frame="sensor", acc_gravity="included")
    s = SensorStream(info, np.arange(n) / 50, np.ones(n, bool), acceleration=np.tile([0, 0, 1.0], (n, 1)),
                     angular_velocity=np.zeros((n, 3)), magnetic_field=np.ones((n, 3)))
    c = Recording([s]).to_canonical().sensor("m")
    assert c.info.acc_unit == "m/s2" and c.info.acc_frame == "sensor" and c.info.acc_gravity == "included"
    np.testing.assert_allclose(c.acceleration[:, 2], 9.81, rtol=1e-6)


def test_common_grid_stacks_and_masks():
    rec = two_sensor_recording()
    g = rec.on_common_grid()
    assert g.names == ("left_forearm", "right_forearm")
    assert g.channels["orientation"].shape == (120, 2, 3, 3)
    assert g.channels["position"].shape == (120, 2, 3)
    assert g.has["position"].tolist() == [False, True]
    assert np.isnan(g.channels["position"][:, 0]).all()
    assert g.valid.shape == (120, 2)
    assert set(np.flatnonzero(~g.all_valid)) == {5, 6, 10}


def test_common_grid_refuses_different_timestamps():
    rec = Recording([imu_stream(), em_stream(t0=0.004), em_stream("other", n=100), imu_stream("same", seed=3)])
    with pytest.raises(RecordingError) as ei:
        rec.on_common_grid()
    msg = str(ei.value)
    assert "right_forearm" in msg and "other" in msg and "same" not in msg
    assert isinstance(ei.value, WearposeError)
    assert rec.on_common_grid(["left_forearm", "same"]).channels["acceleration"].shape == (120, 2, 3)


def test_save_load_round_trip(tmp_path):
    rec = two_sensor_recording(with_gt=True)
    p = rec.save(tmp_path / "sub" / "rec.npz")
    assert not list(p.parent.glob("*.tmp.npz"))  # atomic write leaves no temporary behind
    back = load_recording(p)
    assert back.names == rec.names and back.subject == rec.subject and back.meta == rec.meta
    for a, b in zip(rec.sensors, back.sensors):
        assert a.info == b.info
        np.testing.assert_array_equal(a.timestamps, b.timestamps)
        np.testing.assert_array_equal(a.valid, b.valid)
        for c, v in a.channels().items():
            np.testing.assert_allclose(getattr(b, c), v, atol=2e-6, equal_nan=True)
    assert back.ground_truth_start == 0.5
    assert back.ground_truth.fps == 30.0 and back.ground_truth.meta == {"source_format": "test"}
    assert torch.allclose(back.ground_truth.pose, rec.ground_truth.pose, atol=1e-5)
    assert torch.allclose(back.ground_truth.trans, rec.ground_truth.trans)


def test_from_stacked_inverts_common_grid():
    rec = two_sensor_recording()
    g = rec.on_common_grid()
    back = Recording.from_stacked([s.info for s in rec.sensors], g.timestamps,
                                  {c: torch.from_numpy(v) for c, v in g.channels.items()}, g.valid, meta={"x": 1})
    assert back.names == rec.names and back.meta == {"x": 1}
    for a, b in zip(rec.sensors, back.sensors):
        assert set(a.channels()) == set(b.channels())
        for c in a.channels():
            np.testing.assert_array_equal(getattr(a, c), getattr(b, c))
    with pytest.raises(ShapeError):
        Recording.from_stacked([rec.sensors[0].info], g.timestamps, {"acceleration": np.zeros((120, 3))})
