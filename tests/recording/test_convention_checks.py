"""Convention checks that catch what users get wrong (issue 22): quaternions written (x, y, z, w),
gyro in deg/s and acceleration in g left undeclared (body sites: test_sites.py).

Each mistake is made on simulated data of every kit that has the channel (noise-free and with
the default noise), written to a file and loaded: the file is refused with a message naming the
field and the one fix; the same data written correctly loads (no false positive).
"""

from __future__ import annotations

import dataclasses
import functools
import time
import warnings
from pathlib import Path

import numpy as np
import pytest
import torch

from tests.sensors.sensor_testutils import smooth_motion
from wearpose.errors import InputFileError
from wearpose.recording import (
    Recording, SensorInfo, SensorStream, check_recording, load_recording, prepend_tpose, recording_arrays,
)
from wearpose.recording.checks import GYRO_MAX_WINDOWS, QUAT_FIX, gyro_evidence

KITS = ("em12", "em6", "imu6", "mimu6", "miposer")
GYRO_KITS = ("imu6", "mimu6", "miposer")  # kits whose sensors carry angular velocity (and acceleration)
NOISES = ("none", "default")
DEG = 180.0 / np.pi


@functools.lru_cache(maxsize=None)
def _body():
    from wearpose.body import BodyModel

    return BodyModel()


@functools.lru_cache(maxsize=None)
def _simulated(kit: str, noise: str, tpose_s: float = 0.0) -> Recording:
    """2 s of smooth motion (optionally after a T-pose hold: the sensors rest), simulated with
    ``kit``. Cached: callers must not modify it (every test writes its own copy)."""
    from wearpose.sensors import simulate

    m = smooth_motion(T=60, fps=30.0, seed=1, dtype=torch.float32)
    if tpose_s:
        m, _ = prepend_tpose(m, tpose_s)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = simulate(m, kit, _body(), seed=2, noise=noise, offsets="random")
    return Recording.from_simulation(res, m, source_pose=False)


def _write(path: Path, arrays: dict[str, np.ndarray]) -> Path:
    np.savez(path, **arrays)
    return path


def _refused(path: Path) -> InputFileError:
    with pytest.raises(InputFileError) as ei:
        load_recording(path)
    assert str(path) in str(ei.value)
    return ei.value


def _with_infos(rec: Recording, **changes: str) -> Recording:
    """The same data with ``changes`` written into the info of every sensor having the channel
    (a declaration left out / got wrong: the data does not change)."""
    out = []
    for s in rec.sensors:
        upd = {k: v for k, v in changes.items()
               if (k.startswith("acc") and s.acceleration is not None) or (k == "gyro_unit" and s.angular_velocity is not None)}
        out.append(SensorStream(dataclasses.replace(s.info, **upd), s.timestamps, s.valid, **s.channels()))
    return Recording(out, None, 0.0, rec.subject, rec.meta)


def _orientation_keys(arrays: dict[str, np.ndarray]) -> list[str]:
    return [k for k in arrays if k.endswith("/orientation")]


# ----------------------------------------------------------------------------- no false positives
@pytest.mark.parametrize("noise", NOISES)
@pytest.mark.parametrize("kit", KITS)
def test_correct_simulated_data_of_every_kit_loads(kit: str, noise: str, tmp_path: Path) -> None:
    rec = _simulated(kit, noise)
    variants = {"canonical": rec}
    if kit in GYRO_KITS:
        variants.update({
            "deg_s": rec.declared_as(gyro_unit="deg/s"),
            "raw_g": rec.declared_as(acc_unit="g", acc_frame="sensor", acc_gravity="included"),
            "raw_m_s2_z_up": rec.declared_as(acc_frame="sensor", acc_gravity="included", world_up="z_up"),
            "world_included": rec.declared_as(acc_gravity="included"),
            "world_included_g": rec.declared_as(acc_unit="g", acc_gravity="included"),
        })
    for name, r in variants.items():
        assert check_recording(r.sensors) == [], name
        load_recording(r.save(tmp_path / f"{name}.npz"))  # raises on any convention issue


@pytest.mark.parametrize("kit", GYRO_KITS)
def test_resting_simulated_data_loads(kit: str, tmp_path: Path) -> None:
    """A T-pose hold (the sensors rest: the rest-frame checks run) in every declared form."""
    rec = _simulated(kit, "default", tpose_s=1.0)
    for name, r in {"free": rec, "included": rec.declared_as(acc_gravity="included"),
                    "raw_g": rec.declared_as(acc_unit="g", acc_frame="sensor", acc_gravity="included")}.items():
        load_recording(r.save(tmp_path / f"{name}.npz"))


# ----------------------------------------------------------------------------- quaternion order
@pytest.mark.parametrize("noise", NOISES)
@pytest.mark.parametrize("kit", KITS)
def test_quaternions_written_w_last_are_refused(kit: str, noise: str, tmp_path: Path) -> None:
    arrays = recording_arrays(_simulated(kit, noise))
    wrong = dict(arrays)
    for k in _orientation_keys(arrays):
        wrong[k] = arrays[k][:, [1, 2, 3, 0]]  # what a writer of (x, y, z, w) puts in the file
    e = _refused(_write(tmp_path / "xyzw.npz", wrong))
    assert e.field.startswith("sensors/") and e.field.endswith("/orientation")
    assert "the quaternions look written (x, y, z, w)" in e.problem
    assert e.expected == QUAT_FIX and "q[..., [3, 0, 1, 2]]" in e.expected
    # The cue each kit relies on: the gyro where there is one, else the rigid lever of EM positions.
    cue = "integrated angular velocity" if kit in ("imu6", "mimu6") else "rigid lever" if kit in ("em12", "em6") else ""
    assert cue in e.problem
    # The one fix, applied to the file as written, gives a file that loads.
    fixed = dict(wrong)
    for k in _orientation_keys(arrays):
        fixed[k] = wrong[k][:, [3, 0, 1, 2]]
    load_recording(_write(tmp_path / "fixed.npz", fixed))


def test_w_last_names_every_sensor_and_the_gyro_cue_of_miposer(tmp_path: Path) -> None:
    rec = _simulated("miposer", "none")
    arrays = recording_arrays(rec)
    for k in _orientation_keys(arrays):
        arrays[k] = arrays[k][:, [1, 2, 3, 0]]
    wrong = load_recording(_write(tmp_path / "xyzw.npz", arrays), check_conventions=False)
    flagged = {i.sensor: i for i in check_recording(wrong.sensors) if i.field == "orientation"}
    for imu in ("left_wrist_imu", "right_wrist_imu"):
        assert "integrated angular velocity" in flagged[imu].problem
    assert set(flagged) <= set(rec.names) and len(flagged) >= 2


@pytest.mark.parametrize("kit", ["imu6", "miposer"])
def test_w_last_caught_by_gravity_without_a_gyro(kit: str, tmp_path: Path) -> None:
    """An IMU without angular velocity but with raw (sensor-frame, gravity-included) readings:
    rotated by the orientation they average to world up only in the right order."""
    raw = _simulated(kit, "default").declared_as(acc_frame="sensor", acc_gravity="included")
    arrays = {k: v for k, v in recording_arrays(raw).items() if not k.endswith("/angular_velocity")}
    imu_keys = [k for k in _orientation_keys(arrays) if k.replace("orientation", "acceleration") in arrays]
    load_recording(_write(tmp_path / "ok.npz", arrays))
    for k in imu_keys:
        arrays[k] = arrays[k][:, [1, 2, 3, 0]]
    e = _refused(_write(tmp_path / "xyzw.npz", arrays))
    assert e.field in {k for k in imu_keys} and "from world up" in e.problem and e.expected == QUAT_FIX


# ----------------------------------------------------------------------------- gyro unit
@pytest.mark.parametrize("noise", NOISES)
@pytest.mark.parametrize("kit", GYRO_KITS)
def test_undeclared_deg_per_s_is_refused(kit: str, noise: str, tmp_path: Path) -> None:
    in_deg = _with_infos(_simulated(kit, noise).declared_as(gyro_unit="deg/s"), gyro_unit="rad/s")
    e = _refused(in_deg.save(tmp_path / "deg.npz"))
    assert e.field.endswith("/angular_velocity") and "looks like deg/s" in e.problem
    assert e.expected == "rad/s (the default); declare gyro_unit 'deg/s' in the sensor info"
    ratio = float(e.problem.split("turns ")[1].split(" times")[0])
    assert 40 < ratio < 80  # 57.3: degrees per radian


def test_deg_per_s_gyro_declared_rad_s_without_orientation(tmp_path: Path) -> None:
    """A MIMU without orientation: deg/s readings beyond any MEMS gyro's range in rad/s."""
    rec = _simulated("mimu6", "none").declared_as(gyro_unit="deg/s")
    streams = [SensorStream(dataclasses.replace(s.info, gyro_unit="rad/s"), s.timestamps, s.valid,
                            **{c: v for c, v in s.channels().items() if c != "orientation"}) for s in rec.sensors]
    e = _refused(Recording(streams).save(tmp_path / "deg.npz"))
    assert e.field.endswith("/angular_velocity") and "beyond any body-worn gyro's range" in e.problem
    assert "declare gyro_unit 'deg/s'" in e.expected


def test_rad_per_s_gyro_declared_deg_per_s_is_refused(tmp_path: Path) -> None:
    e = _refused(_with_infos(_simulated("imu6", "none"), gyro_unit="deg/s").save(tmp_path / "rad.npz"))
    assert e.field.endswith("/angular_velocity") and "looks like rad/s" in e.problem
    assert e.expected == "deg/s as declared; declare gyro_unit 'rad/s' in the sensor info"


# ----------------------------------------------------------------------------- acceleration unit
@pytest.mark.parametrize("noise", NOISES)
@pytest.mark.parametrize("kit", GYRO_KITS)
@pytest.mark.parametrize("frame", ["sensor", "world"])
def test_undeclared_g_is_refused_with_one_fix(kit: str, noise: str, frame: str, tmp_path: Path) -> None:
    """Accelerometer readings in g (gravity included, declared so) but the unit left at m/s^2:
    one problem, one fix -- not also "declare acc_gravity 'removed'" (issue 22)."""
    for tpose_s, how in ((0.0, "never rests"), (1.0, "static magnitude")):
        in_g = _simulated(kit, noise, tpose_s).declared_as(acc_unit="g", acc_frame=frame, acc_gravity="included")
        e = _refused(_with_infos(in_g, acc_unit="m/s2").save(tmp_path / f"g_{tpose_s}.npz"))
        assert e.field.endswith("/acceleration") and "looks like g" in e.problem and how in e.problem
        assert e.expected == "m/s^2 by default; declare acc_unit 'g' in the sensor info"
        assert "acc_gravity" not in e.expected and "gravity is removed" not in e.problem


@pytest.mark.parametrize("kit", GYRO_KITS)
def test_raw_readings_declared_free_acceleration_are_refused(kit: str, tmp_path: Path) -> None:
    """A raw accelerometer (world frame, m/s^2) declared as the default free acceleration, on
    a sensor that never rests: its average is gravity's reaction."""
    raw = _with_infos(_simulated(kit, "default").declared_as(acc_gravity="included"), acc_gravity="removed")
    e = _refused(raw.save(tmp_path / "raw.npz"))
    assert e.field.endswith("/acceleration") and "looks like gravity is included" in e.problem
    assert e.expected == "free acceleration (about 0 on average); declare acc_gravity 'included' in the sensor info"


# ----------------------------------------------------------------------------- speed
def _unchecked_stream(info: SensorInfo, t: np.ndarray, **channels: np.ndarray) -> SensorStream:
    """A stream without the constructor's validation (seconds per hour-long stream): the data
    is valid by construction and the test times the convention checks, not the constructor."""
    s = object.__new__(SensorStream)
    s.info, s.timestamps, s.valid = info, t, np.ones(t.shape[0], bool)
    for c in ("position", "orientation", "acceleration", "angular_velocity", "magnetic_field"):
        setattr(s, c, channels.get(c))
    return s


def test_one_hour_of_twelve_sensors_is_checked_in_bounded_time() -> None:
    """The checks look at a bounded, evenly spread set of windows: a 1-hour, 12-sensor IMU
    recording (60 Hz: orientation, acceleration with a minute at rest, gyro) takes about a
    second (0.84-1.0 s measured on a 2-core machine at load 4); the bound here is loose."""
    from wearpose.geometry import quat_to_matrix

    rate, n = 60.0, 3600 * 60
    t = np.arange(n) / rate
    rng = np.random.default_rng(0)
    w = np.stack([np.sin(0.7 * t), np.cos(1.3 * t), 0.5 * np.sin(0.2 * t)], axis=1) * 2.0  # rad/s
    # Any smooth rotations will do for timing: about a slowly turning axis.
    half = 0.5 * np.cumsum(np.linalg.norm(w, axis=1))[:, None] / rate
    q = np.concatenate([np.cos(half), np.sin(half) * w / np.linalg.norm(w, axis=1, keepdims=True)], axis=1)
    R = quat_to_matrix(torch.from_numpy(q)).numpy().astype(np.float32)
    acc = rng.normal(size=(n, 3)).astype(np.float32)
    acc[: 60 * 60] = 0.001 * rng.normal(size=(3600, 3))  # a minute at rest: the rest-frame checks run
    streams = [_unchecked_stream(SensorInfo(f"s{j}", "imu", rate=rate), t, orientation=R, acceleration=acc,
                                 angular_velocity=w.astype(np.float32)) for j in range(12)]
    start = time.perf_counter()
    check_recording(streams)
    took = time.perf_counter() - start
    assert gyro_evidence(streams[0]).windows <= GYRO_MAX_WINDOWS
    assert took < 10.0, f"checking 1 h x 12 sensors took {took:.2f} s"
