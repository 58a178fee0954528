"""Xsens MVNX (the XML export of MVN Analyze/Animate) -> :class:`~wearpose.recording.Recording`.

Layout relied on (Xsens "MVN User Manual" MV0319P, section "MVNX file format"; the MVNX XML
schema ``http://www.xsens.com/mvn/mvnx/schema.xsd``):

- ``<mvnx version=...>`` holds ``<subject label=... frameRate="60" segmentCount=...>``, whose
  ``<segments>`` list ``<segment label="Pelvis" id="1">`` (23 for a full body), ``<sensors>`` list
  ``<sensor label="Pelvis"/>`` (each sensor named after the segment it is on: 17 for a full
  body) and ``<frames>`` holds ``<frame time=ms index=n tc=... ms=unix-ms type=...>``;
- frames of type ``identity``, ``tpose``, ``tpose-isb`` (and ``npose``) come first: calibration
  poses, not data; data frames are ``type="normal"``; ``index`` is the frame number (a missing
  number is a lost frame), ``time`` ms from the start, ``ms`` the absolute time (unix ms) and
  ``tc`` the time code;
- per frame, space-separated numbers per element, segments (or sensors) in list order:
  ``orientation`` 4 per segment, q_GB = (q0, q1, q2, q3), q0 the real part, segment -> global;
  ``position`` 3 per segment, metres, global frame (segment origin);
  ``sensorOrientation`` 4 per sensor, q_GS (sensor -> global), q0 first;
  ``sensorFreeAcceleration`` 3 per sensor, m/s^2, global frame, gravity removed;
  ``sensorMagneticField`` 3 per sensor, sensor frame, arbitrary units (1 = the field at calibration);
  files of older MVN versions (MVNX 3) hold ``sensorAcceleration`` (sensor frame, the
  accelerometer reading, m/s^2) and ``sensorAngularVelocity`` (sensor frame, rad/s) instead;
- the global frame is right-handed, Z up, X along the subject's forward direction at calibration
  (by default; MVN may also align X with magnetic north); at the T-pose every segment frame is
  aligned with it (x forward, y left, z up).

Sensors are declared as the file holds them (``world_up="z_up"``; free acceleration in the world
frame or a sensor-frame reading with gravity) and converted once by
:meth:`Recording.to_canonical`. The segment kinematics become the ground truth: each SMPL joint
takes the global orientation of its Xsens segment (:data:`MVNX_SEGMENT_JOINTS`) re-expressed in
wearpose's world and SMPL's joint frame (:data:`wearpose.geometry.SMPL_TO_X_FORWARD_BODY`),
joints without a segment (SMPL's hands) keep their parent's; the root translation puts SMPL's
pelvis joint on the Xsens pelvis origin. Segment lengths are not retargeted (the pose is the
segments' orientations, played on the default body). A lost frame is a masked sensor slot; the
ground truth (which has no mask) is then left out, never filled.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

import numpy as np
import torch

from wearpose.errors import InputFileError
from wearpose.geometry import SMPL_TO_X_FORWARD_BODY, Z_UP_TO_Y_UP, quat_to_matrix
from wearpose.recording.devicelog import device_row, sensor_key
from wearpose.recording.types import Recording, SensorInfo, SensorStream, _Problem, quaternions_to_matrices

#: Xsens segment label -> SMPL joint whose global orientation it gives (L5 is folded into the
#: pelvis -> spine1 bone: SMPL has three spine joints for Xsens' four lumbar/thoracic segments).
MVNX_SEGMENT_JOINTS: dict[str, str] = {
    "Pelvis": "pelvis", "L3": "spine1", "T12": "spine2", "T8": "spine3", "Neck": "neck", "Head": "head",
    "RightShoulder": "right_collar", "RightUpperArm": "right_shoulder", "RightForeArm": "right_elbow",
    "RightHand": "right_wrist", "LeftShoulder": "left_collar", "LeftUpperArm": "left_shoulder",
    "LeftForeArm": "left_elbow", "LeftHand": "left_wrist", "RightUpperLeg": "right_hip",
    "RightLowerLeg": "right_knee", "RightFoot": "right_ankle", "RightToe": "right_foot",
    "LeftUpperLeg": "left_hip", "LeftLowerLeg": "left_knee", "LeftFoot": "left_ankle", "LeftToe": "left_foot",
}
#: Xsens sensor label (the segment it is strapped to) -> body site. MVN's T8 sensor is worn on
#: the sternum; the hand sensors on the back of the hand, the nearest site is the wrist.
MVNX_SENSOR_SITES: dict[str, str] = {
    "Pelvis": "pelvis", "T8": "sternum", "Head": "head",
    "RightShoulder": "right_shoulder", "RightUpperArm": "right_upper_arm", "RightForeArm": "right_forearm",
    "RightHand": "right_wrist", "LeftShoulder": "left_shoulder", "LeftUpperArm": "left_upper_arm",
    "LeftForeArm": "left_forearm", "LeftHand": "left_wrist", "RightUpperLeg": "right_thigh",
    "RightLowerLeg": "right_shin", "RightFoot": "right_foot", "LeftUpperLeg": "left_thigh",
    "LeftLowerLeg": "left_shin", "LeftFoot": "left_foot",
}
#: Sensor elements read, and how each is declared.
_SENSOR_ELEMENTS = ("sensorOrientation", "sensorFreeAcceleration", "sensorAcceleration", "sensorAngularVelocity",
                    "sensorMagneticField")
_EXPECTED = ("an MVNX file (Xsens MVN's XML export): <mvnx><subject frameRate=...><segments>, <sensors>, "
             "<frames> with <frame type=\"normal\" index=...> elements")


def _local(tag: str) -> str:
    return tag.rsplit("}", 1)[-1]


def _numbers(path: Path, text: str | None, n: int, where: str) -> np.ndarray:
    try:
        a = np.array((text or "").split(), dtype=np.float64)
    except ValueError:
        raise InputFileError(path, "holds something that is not a number", f"{n} space-separated numbers", field=where) from None
    if a.size != n:
        raise InputFileError(path, f"{a.size} numbers", f"{n} (per segment or sensor, as the file's lists declare)", field=where)
    return a


def _read(path: Path) -> dict[str, Any]:
    """Stream the XML once: subject attributes, segment and sensor labels, calibration poses and
    the data of every normal frame (elements cleared as read, so a long file stays small)."""
    out: dict[str, Any] = {"subject": {}, "segments": [], "sensors": [], "frames": [], "calibration": {}, "version": None}
    try:
        for _, el in ET.iterparse(path, events=("end",)):
            tag = _local(el.tag)
            if tag == "segment" and el.get("label") is not None:
                out["segments"].append(el.get("label"))
            elif tag == "sensor" and el.get("label") is not None:
                out["sensors"].append(el.get("label"))
            elif tag == "frame":
                kids = {_local(c.tag): c.text for c in el}
                kind = el.get("type", "normal")
                if kind == "normal":
                    out["frames"].append((el.get("index"), el.get("time"), el.get("ms"), el.get("tc"), kids))
                else:
                    out["calibration"][kind] = kids
                el.clear()
            elif tag == "subject":
                out["subject"] = dict(el.attrib)
            elif tag == "mvnx":
                out["version"] = el.get("version")
    except ET.ParseError as exc:
        raise InputFileError(path, f"not well-formed XML ({exc})", _EXPECTED) from None
    except OSError as exc:
        raise InputFileError(path, f"cannot be read ({exc})", _EXPECTED) from None
    return out


def _frame_slots(path: Path, frames: list[tuple]) -> tuple[np.ndarray, list[str | None]]:
    """Slot of each normal frame (its ``index`` minus the first) and the first frame's clock."""
    try:
        idx = np.array([int(f[0]) for f in frames], dtype=np.int64)
    except (TypeError, ValueError):
        bad = next(i for i, f in enumerate(frames) if not str(f[0]).lstrip("-").isdigit())
        raise InputFileError(path, f"normal frame {bad} has index {frames[bad][0]!r}", "an integer frame number",
                             field="frame/@index") from None
    if np.any(np.diff(idx) <= 0):
        k = int(np.flatnonzero(np.diff(idx) <= 0)[0]) + 1
        raise InputFileError(path, f"frame index {idx[k]} is not after {idx[k - 1]}", "normal frames in increasing index order",
                             field="frame/@index")
    return idx - idx[0], [frames[0][2], frames[0][3]]


def _sensor_streams(path: Path, data: dict[str, Any], slot: np.ndarray, rate: float, K: int, clock: str
                    ) -> tuple[list[SensorStream], list[dict[str, Any]]]:
    labels = data["sensors"]
    S = len(labels)
    frames = data["frames"]
    present = [e for e in _SENSOR_ELEMENTS if frames[0][4].get(e) is not None]
    if "sensorOrientation" not in present or not ({"sensorFreeAcceleration", "sensorAcceleration"} & set(present)):
        raise InputFileError(path, f"the frames hold {present or 'no sensor data'}",
                             "sensorOrientation and sensorFreeAcceleration (or sensorAcceleration) per frame: export "
                             "them in MVN (File > Export > MVNX, sensor data options)", field="frame/sensorOrientation")
    width = {"sensorOrientation": 4}
    raw = {e: np.full((K, S * width.get(e, 3)), np.nan) for e in present}
    for k, f in zip(slot, frames):
        for e in present:
            raw[e][k] = _numbers(path, f[4].get(e), S * width.get(e, 3), f"frame {f[0]}/{e}")
    free = "sensorFreeAcceleration" in present
    acc_key = "sensorFreeAcceleration" if free else "sensorAcceleration"
    ts = np.arange(K, dtype=np.float64) / rate
    streams, rows = [], []
    for j, label in enumerate(labels):
        q = raw["sensorOrientation"][:, 4 * j: 4 * j + 4]
        acc = raw[acc_key][:, 3 * j: 3 * j + 3]
        valid = np.zeros(K, bool)
        valid[slot] = True
        valid &= np.isfinite(q).all(1) & np.isfinite(acc).all(1) & (np.linalg.norm(q, axis=1) > 0.5)
        ch: dict[str, np.ndarray] = {"acceleration": acc}
        try:
            ch["orientation"] = quaternions_to_matrices(q, f"frame/sensorOrientation[{label}]", valid)
        except _Problem as p:
            raise InputFileError(path, p.problem, p.expected, field=p.field) from None
        if "sensorAngularVelocity" in present:
            ch["angular_velocity"] = raw["sensorAngularVelocity"][:, 3 * j: 3 * j + 3]
        if "sensorMagneticField" in present:
            ch["magnetic_field"] = raw["sensorMagneticField"][:, 3 * j: 3 * j + 3]
        for c in ch.values():
            c[~valid] = np.nan
        name = "right_forearm" if label == "RightForeArm" else "left_forearm" if label == "LeftForeArm" else sensor_key(label)
        info = SensorInfo(name, "imu", site=MVNX_SENSOR_SITES.get(label), rate=rate, acc_unit="m/s2",
                          acc_frame="world" if free else "sensor", acc_gravity="removed" if free else "included",
                          world_up="z_up", gyro_unit="rad/s", mag_unit="a.u.")
        try:
            s = SensorStream(info, ts, valid, **{k: v.astype(np.float32) for k, v in ch.items()})
        except Exception as exc:  # noqa: BLE001 - ShapeError from validation, named on the file
            raise InputFileError(path, f"sensor {label!r}: {exc}", "valid sensor data", field=f"sensor {label}") from None
        streams.append(s)
        rows.append(device_row(s, label, len(slot), clock, element=acc_key))
    return streams, rows


def _ground_truth(path: Path, data: dict[str, Any], rate: float) -> Any:
    """The segments' orientations and pelvis position as an SMPL :class:`MotionSequence`."""
    # start-up: wearpose.body adds ~25 ms to import wearpose.recording
    from wearpose.body.kinematics import global_to_local
    # start-up: wearpose.body adds ~20 ms to import wearpose.recording
    from wearpose.body.skeleton import JOINT_INDEX, PARENTS
    # start-up: wearpose.motion adds ~80 ms to import wearpose.recording
    from wearpose.motion.sequence import MotionSequence
    # start-up: wearpose.motion adds ~100 ms to import wearpose.recording
    from wearpose.motion.template import default_rest_joints

    segs = data["segments"]
    n = len(segs)
    T = len(data["frames"])
    q = np.stack([_numbers(path, f[4].get("orientation"), 4 * n, f"frame {f[0]}/orientation") for f in data["frames"]])
    p = np.stack([_numbers(path, f[4].get("position"), 3 * n, f"frame {f[0]}/position") for f in data["frames"]])
    q = torch.from_numpy(q.reshape(T, n, 4))
    R_gb = quat_to_matrix(q)  # (T, n, 3, 3) segment -> MVN global (Z up)
    C = Z_UP_TO_Y_UP.to(R_gb)
    A = SMPL_TO_X_FORWARD_BODY.to(R_gb)
    G = torch.full((T, 24, 3, 3), float("nan"), dtype=torch.float64)
    for j, label in enumerate(segs):
        if label in MVNX_SEGMENT_JOINTS:
            G[:, JOINT_INDEX[MVNX_SEGMENT_JOINTS[label]]] = C @ R_gb[:, j] @ A
    for j in range(24):  # joints without a segment keep their parent's orientation (identity local)
        if torch.isnan(G[0, j, 0, 0]):
            G[:, j] = G[:, PARENTS[j]] if PARENTS[j] >= 0 else torch.eye(3, dtype=torch.float64)
    rest, _ = default_rest_joints()
    pelvis = torch.from_numpy(p.reshape(T, n, 3)[:, segs.index("Pelvis")]) @ C.T
    return MotionSequence(global_to_local(G).float(), torch.zeros(10), (pelvis - rest[0]).float(), rate,
                          {"source_file": str(path), "source_format": "mvnx",
                           "note": "Xsens segment orientations on SMPL joints; segment lengths not retargeted"})


def from_mvnx(path: str | Path, with_ground_truth: bool = True) -> Recording:
    """Read an Xsens MVNX file (layout and conventions in the module doc).

    Args:
        path: the ``.mvnx``.
        with_ground_truth: attach the segment kinematics as SMPL ground truth (needs the
            ``orientation`` and ``position`` elements and a ``Pelvis`` segment; left out, with
            the reason in ``meta["import"]``, when frames were lost).

    Returns:
        One kind-``imu`` sensor per MVNX sensor (named after its segment: ``RightForeArm`` ->
        ``right_forearm``, sites :data:`MVNX_SENSOR_SITES`) at the subject's ``frameRate``,
        ``meta["import"]`` the report (devices, rate, lost frames, clock, calibration poses).

    Raises:
        InputFileError: not MVNX, no frame rate, no normal frames, a sensor or segment list that
            does not match the numbers per frame (the file, the element and the fix).
    """
    path = Path(path)
    if not path.is_file():
        raise InputFileError(path, "file not found", _EXPECTED)
    data = _read(path)
    if data["version"] is None:
        raise InputFileError(path, "no <mvnx> root element", _EXPECTED)
    try:
        rate = float(data["subject"]["frameRate"])
        if not rate > 0:
            raise ValueError
    except (KeyError, ValueError):
        raise InputFileError(path, f"frameRate {data['subject'].get('frameRate')!r}", "a positive frame rate in Hz",
                             field="subject/@frameRate") from None
    if len(data["frames"]) < 2:
        raise InputFileError(path, f"{len(data['frames'])} normal frame(s)", "at least 2 frames of type 'normal'", field="frames")
    if not data["sensors"]:
        raise InputFileError(path, "no <sensor> in <sensors>", "the sensor list (an MVNX of a recording with sensors)",
                             field="subject/sensors")
    slot, (ms0, tc0) = _frame_slots(path, data["frames"])
    K = int(slot[-1]) + 1
    streams, rows = _sensor_streams(path, data, slot, rate, K, f"ms {ms0}" if ms0 else "frame 0")
    lost = K - len(slot)
    gt, gt_note = None, "not asked for"
    if with_ground_truth:
        has = data["frames"][0][4]
        if lost:
            gt_note = f"left out: {lost} frame(s) lost, and ground truth has no mask (wearpose never fills frames)"
        elif has.get("orientation") is None or has.get("position") is None or "Pelvis" not in data["segments"]:
            gt_note = "left out: the frames hold no segment orientation/position, or there is no Pelvis segment"
        else:
            gt = _ground_truth(path, data, rate)
            gt_note = f"segment kinematics of {sum(s in MVNX_SEGMENT_JOINTS for s in data['segments'])} segments on SMPL joints"
    subject = {"id": data["subject"].get("label", path.stem)}
    meta = {"source": "Xsens MVNX", "source_file": str(path), "device": "Xsens MVN",
            "import": {"devices": rows, "rate_hz": rate, "frames": len(slot), "lost_frames": lost,
                       "clock": f"one MVN clock; frame 0 at ms={ms0} (unix ms), tc={tc0}",
                       "mvnx_version": data["version"], "segments": len(data["segments"]),
                       "calibration_poses": sorted(data["calibration"]), "ground_truth": gt_note}}
    return Recording(streams, gt, 0.0, subject, meta)
