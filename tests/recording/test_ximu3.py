"""x-IMU3 log folders (``from_ximu3`` / ``wearpose recording import ximu3``): tiny synthetic logs
written here, and the real lower-body log of ../shared/real-sensors."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from wearpose.cli import app
from wearpose.errors import InputFileError
from wearpose.recording import from_ximu3

PERIOD_US = 20_000


def _device(root: Path, name: str, serial: str, start_us: int, n: int, lost: tuple[int, ...] = ()) -> None:
    """A device at rest, level (identity AHRS quaternion): gyro 5 deg/s about z, 1 g up."""
    d = root / f"{name} {serial} (UDP)"
    d.mkdir(parents=True)
    keep = [k for k in range(n) if k not in lost]
    t = start_us + np.asarray(keep) * PERIOD_US
    inertial = np.column_stack([t, np.zeros(len(t)), np.zeros(len(t)), np.full(len(t), 5.0),
                                np.zeros(len(t)), np.zeros(len(t)), np.ones(len(t))])
    quat = np.column_stack([t, np.ones(len(t)), np.zeros((len(t), 3))])
    np.savetxt(d / "Inertial.csv", inertial, delimiter=",", fmt="%.6f", comments="",
               header="Timestamp (us),Gyroscope X (deg/s),Gyroscope Y (deg/s),Gyroscope Z (deg/s),"
                      "Accelerometer X (g),Accelerometer Y (g),Accelerometer Z (g)")
    np.savetxt(d / "Quaternion.csv", quat, delimiter=",", fmt="%.6f", comments="", header="Timestamp (us),W,X,Y,Z")
    (d / "Command.json").write_text(json.dumps([{"ping": {"interface": "UDP", "name": name, "sn": serial}}]))


@pytest.fixture
def log(tmp_path: Path) -> Path:
    root = tmp_path / "log"
    _device(root, "Pelvis", "00000001", 1_000_000, 50)
    _device(root, "Left Lower Leg", "00000002", 1_004_000, 50, lost=(10, 11, 30))
    return root


def test_devices_declared_units_and_lost_samples_masked(log: Path) -> None:
    rec = from_ximu3(log)
    assert rec.names == ("left_lower_leg", "pelvis")
    leg, pelvis = rec.sensor("left_lower_leg"), rec.sensor("pelvis")
    assert leg.info.site == "left_shin" and pelvis.info.site == "pelvis" and leg.kind == "imu"
    assert (leg.info.acc_unit, leg.info.acc_frame, leg.info.acc_gravity, leg.info.gyro_unit, leg.info.world_up) == \
        ("g", "sensor", "included", "deg/s", "z_up")
    assert leg.info.rate == pytest.approx(50.0) and leg.num_frames == 50 and int((~leg.valid).sum()) == 3
    assert not leg.valid[[10, 11, 30]].any() and np.isnan(leg.acceleration[10]).all()  # masked, never filled
    # one shared clock: the leg started 4 ms after the pelvis; a lost slot keeps its nominal time
    assert leg.timestamps[0] == pytest.approx(0.004) and pelvis.timestamps[0] == 0.0
    assert leg.timestamps[10] == pytest.approx(0.004 + 10 * 0.02)
    found = {d["device"]: d for d in rec.meta["import"]["devices"]}
    assert found["Left Lower Leg"]["lost"] == 3 and found["Pelvis"]["lost"] == 0
    assert rec.meta["import"]["clock"].startswith("shared device clock")
    # canonical: at rest, level -> free acceleration 0, gyro in rad/s, Y up
    c = rec.to_canonical().sensor("left_lower_leg")
    np.testing.assert_allclose(c.acceleration[c.valid], 0.0, atol=1e-5)
    np.testing.assert_allclose(c.angular_velocity[c.valid][:, 2], np.deg2rad(5.0), rtol=1e-6)


def test_unsynchronised_clocks_start_each_device_at_zero(tmp_path: Path) -> None:
    _device(tmp_path / "log", "Pelvis", "1", 1_000_000, 20)
    _device(tmp_path / "log", "Left Foot", "2", 9_000_000, 20)
    rec = from_ximu3(tmp_path / "log")
    assert rec.sensor("left_foot").timestamps[0] == 0.0 and rec.sensor("pelvis").timestamps[0] == 0.0
    assert rec.meta["import"]["clock"].startswith("device clocks differ")


def test_bad_logs_name_the_file_and_the_fix(log: Path, tmp_path: Path) -> None:
    with pytest.raises(InputFileError, match="no x-IMU3 device folders"):
        from_ximu3(tmp_path)
    q = next(log.glob("Pelvis*")) / "Quaternion.csv"
    lines = q.read_text().splitlines()
    q.write_text("\n".join(lines[:-1]) + "\n")
    with pytest.raises(InputFileError, match="Quaternion.csv.*timestamps differ from Inertial.csv's"):
        from_ximu3(log)
    (next(log.glob("Pelvis*")) / "Inertial.csv").write_text("Timestamp (us),a\n1,2\n")
    with pytest.raises(InputFileError, match=r"Inertial.csv \[header\]: 2 columns, 1 rows. Expected: 7 columns"):
        from_ximu3(log)


def test_cli_import_reports_devices(log: Path, tmp_path: Path) -> None:
    res = CliRunner().invoke(app, ["recording", "import", "ximu3", str(log), "--out", str(tmp_path / "out"), "--json"])
    assert res.exit_code == 0, res.output
    row = json.loads(res.stdout)["files"][0]
    assert row["ok"] and row["sensors"] == 2 and {d["device"]: d["lost"] for d in row["devices"]} == \
        {"Left Lower Leg": 3, "Pelvis": 0}
    assert (tmp_path / "out" / "log.npz").is_file()


def test_the_real_lower_body_log(real_sensors: Path) -> None:
    """Seven real x-IMU3s, 18.6 s: every device at its own ~50 Hz, UDP losses masked, and the
    declared conventions right: at the standing start the free acceleration is near 0."""
    rec = from_ximu3(real_sensors / "ximu3-lower-body")
    assert len(rec.sensors) == 7 and {s.info.site for s in rec.sensors} == {
        "pelvis", "left_thigh", "right_thigh", "left_shin", "right_shin", "left_foot", "right_foot"}
    lost = {d["device"]: d["lost"] for d in rec.meta["import"]["devices"]}
    samples = {d["device"]: d["samples"] for d in rec.meta["import"]["devices"]}
    assert lost == {"Left Foot": 8, "Left Lower Leg": 21, "Left Upper Leg": 8, "Right Foot": 23,
                    "Right Lower Leg": 11, "Right Upper Leg": 27, "Pelvis": 28}
    assert set(samples.values()) <= set(range(900, 922))  # the README's 900-921 rows per device
    for s in rec.sensors:
        assert 49.5 < s.info.rate < 50.5 and 18.5 < s.timestamps[-1] < 18.7
    can = rec.to_canonical()
    for s in can.sensors:
        first = s.acceleration[:40][s.valid[:40]]  # 0.8 s of the calibration stance
        assert float(np.linalg.norm(first, axis=1).mean()) < 0.3, s.info.name  # m/s^2: gravity removed right
