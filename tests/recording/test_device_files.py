"""Device files through ``wearpose recording import``: Xsens MVNX, Movella DOT CSV exports and any
CSV with a YAML column map. Every file is tiny and synthetic, written here in the layout the
importer's docstring cites; each test checks what the import declares, that a lost sample is
masked (never filled), what it reports, and that bad input names the file, the field and the fix."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
import torch
from typer.testing import CliRunner

from wearpose.body.kinematics import forward_kinematics
from wearpose.body.skeleton import JOINT_INDEX
from wearpose.cli import app
from wearpose.errors import InputFileError
from wearpose.geometry import matrix_to_quat, rotation_y, rotation_z
from wearpose.motion.template import default_rest_joints
from wearpose.recording import from_csv, from_movella_dot, from_mvnx, load_recording

# ----------------------------------------------------------------------------------- MVNX
SEGMENTS = ["Pelvis", "L5", "L3", "T12", "T8", "Neck", "Head", "RightShoulder", "RightUpperArm", "RightForeArm",
            "RightHand", "LeftShoulder", "LeftUpperArm", "LeftForeArm", "LeftHand", "RightUpperLeg", "RightLowerLeg",
            "RightFoot", "RightToe", "LeftUpperLeg", "LeftLowerLeg", "LeftFoot", "LeftToe"]
SENSORS = ["Pelvis", "T8", "Head", "RightForeArm", "LeftForeArm", "RightLowerLeg", "LeftLowerLeg"]


def _q(R: torch.Tensor) -> str:
    return " ".join(f"{x:.8f}" for x in matrix_to_quat(R.double()).reshape(-1).tolist())


def _vec(a: np.ndarray) -> str:
    return " ".join(f"{x:.6f}" for x in np.asarray(a).reshape(-1))


def write_mvnx(path: Path, n: int = 30, lost: tuple[int, ...] = (), yaw_deg: float = 0.0, elbow_deg: float = 90.0,
               rate: float = 60.0, sensor_element: str = "sensorFreeAcceleration") -> Path:
    """An MVNX of a subject in the T-pose (MVN's identity pose: every segment frame aligned with the
    Z-up global frame, facing +X), turned by ``yaw_deg`` about up, the left forearm bent
    ``elbow_deg`` forward about up, the pelvis 1 m up moving 0.5 m/s along +X; every sensor's
    orientation that of its segment, free acceleration 0, magnetic field (1, 0, 0)."""
    yaw = rotation_z(torch.tensor(math.radians(yaw_deg), dtype=torch.float64))
    bend = rotation_z(torch.tensor(math.radians(-elbow_deg), dtype=torch.float64))  # left (+y) -> forward (+x)
    R = {s: yaw for s in SEGMENTS}
    R["LeftForeArm"] = R["LeftHand"] = yaw @ bend
    frames = []
    for kind, idx in (("identity", ""), ("tpose", "")):
        frames.append(f'<frame time="0" index="{idx}" tc="" ms="" type="{kind}"><orientation>'
                      f'{" ".join("1 0 0 0" for _ in SEGMENTS)}</orientation><position>{_vec(np.zeros(3 * len(SEGMENTS)))}</position></frame>')
    for k in range(n):
        if k in lost:
            continue
        pos = np.zeros((len(SEGMENTS), 3))
        pos[:, 0] = 0.5 * k / rate
        pos[:, 2] = 1.0
        acc_el = (f"<{sensor_element}>{_vec(np.zeros(3 * len(SENSORS)))}</{sensor_element}>" if sensor_element == "sensorFreeAcceleration"
                  else f"<{sensor_element}>{_vec(np.tile([0, 0, 9.81], len(SENSORS)))}</{sensor_element}>")
        frames.append(
            f'<frame time="{round(1000 * k / rate)}" index="{k}" tc="00:00:00:{k:02d}" ms="{1700000000000 + round(1000 * k / rate)}" type="normal">'
            f"<orientation>{' '.join(_q(R[s]) for s in SEGMENTS)}</orientation><position>{_vec(pos)}</position>"
            f"{acc_el}<sensorMagneticField>{_vec(np.tile([1, 0, 0], len(SENSORS)))}</sensorMagneticField>"
            f"<sensorOrientation>{' '.join(_q(R[s]) for s in SENSORS)}</sensorOrientation></frame>")
    segs = "".join(f'<segment label="{s}" id="{i + 1}"><points/></segment>' for i, s in enumerate(SEGMENTS))
    sens = "".join(f'<sensor label="{s}"/>' for s in SENSORS)
    xml = (f'<?xml version="1.0" encoding="UTF-8"?>\n<mvnx xmlns="http://www.xsens.com/mvn/mvnx" version="4">'
           f'<mvn version="2022.0.0" build="1"/><comment/><subject label="s01" frameRate="{rate:g}" segmentCount="{len(SEGMENTS)}">'
           f"<segments>{segs}</segments><sensors>{sens}</sensors>"
           f'<frames segmentCount="{len(SEGMENTS)}" sensorCount="{len(SENSORS)}" jointCount="22">{"".join(frames)}</frames>'
           f'</subject><securityCode code="x"/></mvnx>')
    path.write_text(xml, encoding="utf-8")
    return path


def _joints(seq) -> torch.Tensor:
    rest, _ = default_rest_joints()
    _, P = forward_kinematics(seq.pose.double(), rest)
    return P + seq.trans.double()[:, None]


def test_mvnx_sensors_declared_and_ground_truth_in_the_sensors_world(tmp_path: Path) -> None:
    rec = from_mvnx(write_mvnx(tmp_path / "take.mvnx", yaw_deg=30.0))
    assert rec.names == ("pelvis", "t8", "head", "right_forearm", "left_forearm", "right_lower_leg", "left_lower_leg")
    s = rec.sensor("left_forearm")
    assert (s.info.site, s.info.kind, s.info.world_up, s.info.acc_frame, s.info.acc_gravity, s.info.rate) == \
        ("left_forearm", "imu", "z_up", "world", "removed", 60.0)
    assert rec.sensor("t8").info.site == "sternum" and rec.sensor("left_lower_leg").info.site == "left_shin"
    assert s.magnetic_field is not None and rec.meta["import"]["lost_frames"] == 0
    assert rec.meta["import"]["calibration_poses"] == ["identity", "tpose"]
    gt = rec.ground_truth
    assert gt is not None and gt.num_frames == 30 and gt.fps == 60.0
    P = _joints(gt)
    # The canonical world of the sensors is the ground truth's: MVN (x, y, z) -> (x, z, -y).
    yaw = math.radians(30.0)
    fwd_mvn = np.array([math.cos(yaw), math.sin(yaw), 0.0])
    fwd = np.array([fwd_mvn[0], fwd_mvn[2], -fwd_mvn[1]])
    left = np.array([-math.sin(yaw), 0.0, -math.cos(yaw)])  # MVN's +y turned by the yaw, in the Y-up world
    d = lambda a, b: (P[0, JOINT_INDEX[b]] - P[0, JOINT_INDEX[a]]).numpy()  # noqa: E731
    unit = lambda v: v / np.linalg.norm(v)  # noqa: E731
    ry = lambda deg: rotation_y(torch.tensor(math.radians(deg), dtype=torch.float64))  # noqa: E731
    # A T-pose facing MVN's +x faces +x in the Y-up world (SMPL's zero pose faces +z): the root is
    # turned 90 + 30 deg about up; the left elbow bent forward is -90 deg about its joint's up axis;
    # every other joint keeps the T-pose.
    pose = gt.pose.double()
    np.testing.assert_allclose(pose[:, 0].numpy(), ry(120.0).expand(30, 3, 3).numpy(), atol=1e-5)
    np.testing.assert_allclose(pose[0, JOINT_INDEX["left_elbow"]].numpy(), ry(-90.0).numpy(), atol=1e-5)
    others = [j for j in range(1, 24) if j != JOINT_INDEX["left_elbow"]]
    np.testing.assert_allclose(pose[:, others].numpy(), np.broadcast_to(np.eye(3), (30, 22, 3, 3)), atol=1e-5)
    # the rest skeleton's hips and forearm are within 0.1 deg of its axes
    np.testing.assert_allclose(unit(d("right_hip", "left_hip")), left, atol=2e-3)
    np.testing.assert_allclose(unit(d("left_elbow", "left_wrist")), fwd, atol=2e-3)  # left forearm bent forward
    # the pelvis joint on MVN's pelvis origin: 1 m up, moving 0.5 m/s along MVN's x = the world's x
    np.testing.assert_allclose(P[:, 0].numpy(), np.stack([0.5 * np.arange(30) / 60, np.ones(30), np.zeros(30)], 1), atol=1e-5)
    can = rec.to_canonical().sensor("left_forearm")
    np.testing.assert_allclose(can.orientation[0] @ np.array([0, 1, 0]), fwd, atol=1e-5)  # segment's +y (left) bent forward
    out = tmp_path / "take.npz"
    rec.save(out)
    assert load_recording(out).ground_truth.num_frames == 30  # the convention checks pass on load


def test_mvnx_lost_frames_are_masked_and_ground_truth_left_out(tmp_path: Path) -> None:
    rec = from_mvnx(write_mvnx(tmp_path / "gappy.mvnx", lost=(5, 6, 20)))
    s = rec.sensor("pelvis")
    assert s.num_frames == 30 and int((~s.valid).sum()) == 3 and not s.valid[[5, 6, 20]].any()
    assert np.isnan(s.acceleration[5]).all() and s.timestamps[5] == pytest.approx(5 / 60)
    assert rec.ground_truth is None and "3 frame(s) lost" in rec.meta["import"]["ground_truth"]
    assert {d["device"]: d["lost"] for d in rec.meta["import"]["devices"]}["Pelvis"] == 3


def test_mvnx_old_sensor_acceleration_is_a_sensor_frame_reading(tmp_path: Path) -> None:
    rec = from_mvnx(write_mvnx(tmp_path / "v3.mvnx", sensor_element="sensorAcceleration"), with_ground_truth=False)
    s = rec.sensor("head")
    assert (s.info.acc_frame, s.info.acc_gravity) == ("sensor", "included") and rec.ground_truth is None
    c = rec.to_canonical().sensor("head")
    np.testing.assert_allclose(c.acceleration[c.valid], 0.0, atol=1e-4)  # 9.81 up, gravity removed: at rest


def test_mvnx_errors_name_the_element_and_the_fix(tmp_path: Path) -> None:
    bad = write_mvnx(tmp_path / "bad.mvnx")
    bad.write_text(bad.read_text().replace('frameRate="60"', 'frameRate="fast"'))
    with pytest.raises(InputFileError, match=r"bad.mvnx \[subject/@frameRate\]: frameRate 'fast'"):
        from_mvnx(bad)
    short = write_mvnx(tmp_path / "short.mvnx")
    short.write_text(short.read_text().replace('<sensor label="Head"/>', '<sensor label="Head"/><sensor label="Extra"/>', 1))
    with pytest.raises(InputFileError, match=r"short.mvnx \[frame 0/sensorOrientation\]: 28 numbers. Expected: 32"):
        from_mvnx(short)
    (tmp_path / "broken.mvnx").write_text("<mvnx><subject")
    with pytest.raises(InputFileError, match="not well-formed XML"):
        from_mvnx(tmp_path / "broken.mvnx")


# ----------------------------------------------------------------------------- Movella DOT
def write_dot(path: Path, tag: str, start_us: int, n: int = 120, lost: tuple[int, ...] = (), empty: tuple[int, ...] = (),
              columns: str = "quat+free", wrap_at: int | None = None) -> Path:
    """A DOT export at 60 Hz: level, turning about up at 1 rad/s (quaternion and gyro agree),
    free acceleration 0, the accelerometer 9.81 up."""
    t = np.arange(n) / 60.0
    heads = ["PacketCounter", "SampleTimeFine"]
    if "quat" in columns:
        heads += ["Quat_W", "Quat_X", "Quat_Y", "Quat_Z"]
    if "euler" in columns:
        heads += ["Euler_X", "Euler_Y", "Euler_Z"]
    heads += ["FreeAcc_X", "FreeAcc_Y", "FreeAcc_Z"] if "free" in columns else []
    heads += ["Acc_X", "Acc_Y", "Acc_Z", "Gyr_X", "Gyr_Y", "Gyr_Z"] if "acc" in columns else []
    lines = ["DOT Sdk version: 2023.6.0", f"Device tag: {tag}", "Firmware Version: 2.6.0", "Filter profile: General",
             ",".join(heads) + ","]
    for k in range(n):
        if k in lost:
            continue
        stamp = start_us + round(k * 1e6 / 60)
        if wrap_at is not None and k >= wrap_at:
            stamp -= 2 ** 32
        row = [str(k), str(stamp)]
        if "quat" in columns:
            row += [f"{math.cos(t[k] / 2):.7f}", "0", "0", f"{math.sin(t[k] / 2):.7f}"]
        if "euler" in columns:
            row += ["0", "0", f"{math.degrees(t[k]):.4f}"]
        row += ["0", "0", "0"] if "free" in columns else []
        row += ["0", "0", "9.81", "0", "0", f"{math.degrees(1.0):.4f}"] if "acc" in columns else []
        if k in empty:
            row[2] = ""
        lines.append(",".join(row) + ",")
    path.write_text("\n".join(lines) + "\n")
    return path


def test_movella_dot_session_clocks_losses_and_declarations(tmp_path: Path) -> None:
    ses = tmp_path / "session"
    ses.mkdir()
    write_dot(ses / "a.csv", "left_shin", 5_000_000, lost=(10, 11), empty=(40,), columns="quat+free+acc")
    write_dot(ses / "b.csv", "Pelvis DOT", 5_008_000, columns="quat+acc")
    rec = from_movella_dot(ses)
    assert rec.names == ("left_shin", "pelvis_dot")
    a, b = rec.sensor("left_shin"), rec.sensor("pelvis_dot")
    assert a.info.site == "left_shin" and b.info.site is None  # a tag that is a body site becomes the site
    assert (a.info.acc_frame, a.info.acc_gravity, a.info.world_up, a.info.gyro_unit) == ("world", "removed", "z_up", "deg/s")
    assert (b.info.acc_frame, b.info.acc_gravity) == ("sensor", "included")  # only Acc_*: the reading
    assert a.num_frames == 120 and not a.valid[[10, 11, 40]].any() and int((~a.valid).sum()) == 3
    assert a.info.rate == pytest.approx(60.0, rel=1e-3) and b.timestamps[0] == pytest.approx(0.008)  # one clock
    rows = {d["device"]: d for d in rec.meta["import"]["devices"]}
    assert rows["left_shin"]["lost"] == 2 and rows["left_shin"]["masked"] == 3 and rows["left_shin"]["empty_cell_rows"] == 1
    assert rows["left_shin"]["units"]["angular_velocity"] == "deg/s, sensor frame"
    for s in rec.to_canonical().sensors:  # at rest once converted: free acceleration 0
        np.testing.assert_allclose(s.acceleration[s.valid], 0.0, atol=1e-4)
    out = tmp_path / "ses.npz"
    rec.save(out)
    load_recording(out)  # the convention checks (gyro agrees with the quaternions, deg/s) pass


def test_movella_dot_clock_wrap_and_separate_clocks(tmp_path: Path) -> None:
    rec = from_movella_dot(write_dot(tmp_path / "w.csv", "w", 2 ** 32 - 500_000, wrap_at=60))
    s = rec.sensor("w")
    assert s.num_frames == 120 and s.valid.all() and np.all(np.diff(s.timestamps) > 0)
    assert rec.meta["import"]["devices"][0]["clock_wraps"] == 1
    d = tmp_path / "two"
    d.mkdir()
    write_dot(d / "a.csv", "a", 1_000_000)
    write_dot(d / "b.csv", "b", 90_000_000)
    rec2 = from_movella_dot(d)
    assert rec2.meta["import"]["clock"].startswith("device clocks differ") and rec2.sensor("b").timestamps[0] == 0.0


def test_movella_dot_errors_name_the_column_and_the_fix(tmp_path: Path) -> None:
    with pytest.raises(InputFileError, match=r"e.csv \[header\]: no Quat_W, Quat_X, Quat_Y, Quat_Z columns \(only Euler "
                                             r"angles\). Expected: quaternion orientation: export"):
        from_movella_dot(write_dot(tmp_path / "e.csv", "e", 0, columns="euler+free"))
    p = write_dot(tmp_path / "x.csv", "x", 0)
    p.write_text(p.read_text().replace("\n3,", "\n3,abc", 1))
    with pytest.raises(InputFileError, match=r"x.csv \[SampleTimeFine\]: line 9 holds 'abc"):
        from_movella_dot(p)
    with pytest.raises(InputFileError, match="no Movella DOT CSV files"):
        from_movella_dot(tmp_path / "nothing")


# ------------------------------------------------------------------------------ CSV + map
MAP = """
time: {column: t_ms, unit: ms}
world_up: z_up
sensors:
  left_wrist:
    site: left_wrist
    orientation: {columns: [qx, qy, qz, qw], order: xyzw}
    acceleration: {columns: [ax, ay, az], unit: g, frame: sensor, gravity: included}
    angular_velocity: {columns: [gx, gy, gz], unit: deg/s}
"""


def write_csv(path: Path, n: int = 200, lost: tuple[int, ...] = (), nan: tuple[int, ...] = ()) -> Path:
    """100 Hz, a sensor level in a Z-up world turning about z at 2 rad/s; quaternions written
    w-last, the accelerometer reading 1 g up in the sensor frame, gyro in deg/s."""
    lines = ["t_ms;qx;qy;qz;qw;ax;ay;az;gx;gy;gz"]
    for k in range(n):
        if k in lost:
            continue
        th = 2.0 * k / 100
        cells = [f"{10 * k}", "0", "0", f"{math.sin(th / 2):.8f}", f"{math.cos(th / 2):.8f}", "0", "0", "1",
                 "0", "0", f"{math.degrees(2.0):.5f}"]
        if k in nan:
            cells[5] = "nan"
        lines.append(";".join(cells))
    path.write_text("\n".join(lines) + "\n")
    return path


def test_csv_map_declares_conventions_and_masks_losses(tmp_path: Path) -> None:
    (tmp_path / "map.yaml").write_text(MAP)
    rec = from_csv(write_csv(tmp_path / "trial.csv", lost=(50, 51, 52), nan=(120,)), tmp_path / "map.yaml")
    s = rec.sensor("left_wrist")
    assert (s.info.acc_unit, s.info.acc_frame, s.info.acc_gravity, s.info.gyro_unit, s.info.world_up) == \
        ("g", "sensor", "included", "deg/s", "z_up")
    assert s.num_frames == 200 and not s.valid[[50, 51, 52, 120]].any() and int((~s.valid).sum()) == 4
    assert s.info.rate == pytest.approx(100.0) and s.timestamps[51] == pytest.approx(0.51)
    # w-last read as declared: R_WS turns about world z by 2 rad/s -> w-first matrix about z
    th = 2.0 * 10 / 100
    np.testing.assert_allclose(s.orientation[10], rotation_z(torch.tensor(th, dtype=torch.float64)).numpy(), atol=1e-6)
    assert any("order xyzw" in n for n in rec.meta["import"]["rewritten"])
    dev = rec.meta["import"]["devices"][0]
    assert dev["lost"] == 3 and dev["masked"] == 4 and dev["units"]["acceleration"] == "g, sensor frame, gravity included"
    c = rec.to_canonical().sensor("left_wrist")
    np.testing.assert_allclose(c.acceleration[c.valid], 0.0, atol=1e-4)
    out = tmp_path / "trial.npz"
    rec.save(out)
    load_recording(out)  # gyro vs orientation, units: the checks pass on load


def test_csv_map_wrong_order_is_refused_at_import(tmp_path: Path) -> None:
    """The same file declared w-first: the import's convention check names the field and the fix."""
    (tmp_path / "map.yaml").write_text(MAP.replace("[qx, qy, qz, qw], order: xyzw", "[qx, qy, qz, qw], order: wxyz"))
    write_csv(tmp_path / "trial.csv")
    res = CliRunner().invoke(app, ["recording", "import", "csv", str(tmp_path / "trial.csv"), "--map", str(tmp_path / "map.yaml"),
                                   "--out", str(tmp_path / "out"), "--json"])
    assert res.exit_code == 1, res.output
    row = json.loads(res.stdout)["files"][0]
    assert not row["ok"] and "sensors/left_wrist/orientation" in row["error"] and "(x, y, z, w)" in row["error"]
    assert not (tmp_path / "out" / "trial.npz").exists()


def test_csv_map_errors_name_the_key_or_column(tmp_path: Path) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text(MAP.replace("unit: g,", "unit: gee,"))
    with pytest.raises(InputFileError, match=r"bad.yaml \[sensors/left_wrist/acceleration/unit\]: value 'gee'. Expected: one of m/s2, g"):
        from_csv(write_csv(tmp_path / "t.csv"), bad)
    bad.write_text(MAP.replace("angular_velocity:", "angular_velocty:"))
    with pytest.raises(InputFileError, match=r"unknown key 'angular_velocty' \(did you mean 'angular_velocity'\?\)"):
        from_csv(tmp_path / "t.csv", bad)
    bad.write_text(MAP.replace("[gx, gy, gz]", "[gyro_x, gy, gz]"))
    with pytest.raises(InputFileError, match=r"t.csv \[header\]: no column 'gyro_x' \(asked for by the map's "
                                             r"sensors/left_wrist/angular_velocity/columns\)"):
        from_csv(tmp_path / "t.csv", bad)


def test_cli_imports_each_format_and_reports_devices(tmp_path: Path) -> None:
    (tmp_path / "m").mkdir()
    write_mvnx(tmp_path / "m" / "take.mvnx", lost=(3,))
    res = CliRunner().invoke(app, ["recording", "import", "mvnx", str(tmp_path / "m"), "--out", str(tmp_path / "out"), "--json"])
    assert res.exit_code == 0, res.output
    row = json.loads(res.stdout)["files"][0]
    assert row["ok"] and row["sensors"] == 7 and {d["device"]: d["lost"] for d in row["devices"]}["Head"] == 1
    assert (tmp_path / "out" / "take.npz").is_file()
    (tmp_path / "d").mkdir()
    write_dot(tmp_path / "d" / "a.csv", "a", 0, lost=(7,))
    res = CliRunner().invoke(app, ["recording", "import", "movella-dot", str(tmp_path / "d"), "--out", str(tmp_path / "out")])
    assert res.exit_code == 0, res.output
    assert "devices of d" in res.stdout and "lost" in res.stdout and (tmp_path / "out" / "d.npz").is_file()
    res = CliRunner().invoke(app, ["recording", "import", "csv", str(tmp_path / "d" / "a.csv"), "--out", str(tmp_path / "o2")])
    assert res.exit_code == 2 and "--map" in res.output
