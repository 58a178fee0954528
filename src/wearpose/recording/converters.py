"""Converters from public dataset layouts to :class:`~wearpose.recording.Recording`.

Each converter reads the layout as its dataset publishes it, *declares* the conventions the data
is in (units, frames, gravity, world up axis) in :class:`SensorInfo` rather than converting in
place -- conversion happens once, in :meth:`Recording.to_canonical` -- masks frames the dataset
marks as missing (NaN rows, EM-POSE's ``sensor_masks``) and never fills them in, and records its
provenance in ``meta``. Every malformed input raises :class:`wearpose.errors.InputFileError`
naming the file and the key/line.

What each layout is based on is cited in the converter's docstring.
"""

from __future__ import annotations

import io
import json
import pickle
import re
from pathlib import Path
from typing import Any, Sequence

import numpy as np
import torch

from wearpose.errors import InputFileError, ShapeError
from wearpose.fileio import npz_problem
from wearpose.geometry import axis_angle_to_matrix
from wearpose.recording.devicelog import sample_grid
from wearpose.recording.types import Recording, SensorInfo, SensorStream, _Problem, quaternions_to_matrices

# --------------------------------------------------------------------------------------- DIP-IMU
#: DIP-IMU's 17 sensors in file order, as given by the dataset's ``overview_of_published_data.txt``
#: ("[head, spine2, belly, lchest, rchest, lshoulder, rshoulder, lelbow, relbow, lhip, rhip, lknee,
#: rknee, lwrist, lwrist, lankle, rankle]", quoted in eth-ait/dip18 issue #16; the second
#: "lwrist" is a typo for the right wrist), mapped to wearpose sensor names / sites.
DIP_IMU_SENSORS: tuple[str, ...] = (
    "head", "spine2", "belly", "left_chest", "right_chest", "left_shoulder", "right_shoulder",
    "left_elbow", "right_elbow", "left_hip", "right_hip", "left_knee", "right_knee",
    "left_wrist", "right_wrist", "left_ankle", "right_ankle",
)
#: The 6 sensors DIP/TransPose/PIP use: indices ``[7, 8, 11, 12, 0, 2]`` (TransPose
#: ``preprocess.py``: ``imu_mask = [7, 8, 11, 12, 0, 2]``), i.e. the sensors on the forearms
#: ("elbow"), lower legs ("knee"), head and pelvis ("belly"), which TransPose simulates at SMPL
#: vertices 1961, 5424, 1176, 4662, 411, 3021. Index -> (sensor name of the ``imu6`` kit, body site).
DIP_IMU_SIX: dict[int, tuple[str, str]] = {
    7: ("left_forearm", "left_forearm"), 8: ("right_forearm", "right_forearm"),
    11: ("left_lower_leg", "left_shin"), 12: ("right_lower_leg", "right_shin"),
    0: ("head", "head"), 2: ("pelvis", "pelvis"),
}
DIP_IMU_FPS = 60.0


class _NumpyOnlyUnpickler(pickle.Unpickler):
    """Unpickles numpy arrays and plain containers only: a pkl can run arbitrary code on load,
    and a dataset file should never need to."""

    _ALLOWED = {
        ("numpy.core.multiarray", "_reconstruct"), ("numpy._core.multiarray", "_reconstruct"),
        ("numpy.core.multiarray", "scalar"), ("numpy._core.multiarray", "scalar"),
        ("numpy.core.numeric", "_frombuffer"), ("numpy._core.numeric", "_frombuffer"),
        ("numpy", "ndarray"), ("numpy", "dtype"), ("copy_reg", "_reconstructor"), ("copyreg", "_reconstructor"),
        ("__builtin__", "object"), ("builtins", "object"),
        # Protocol-2 pickles (Python 2 era, like DIP-IMU) encode raw array bytes via _codecs.encode.
        ("_codecs", "encode"),
    }

    def find_class(self, module: str, name: str) -> Any:
        if (module, name) in self._ALLOWED:
            return super().find_class(module, name)
        raise pickle.UnpicklingError(f"refusing to unpickle {module}.{name} (only numpy arrays are expected)")


def _read_pkl(path: Path, expected: str) -> dict[str, Any]:
    if not path.is_file():
        raise InputFileError(path, "file not found", expected)
    try:
        with open(path, "rb") as fh:
            # latin1: DIP-IMU was pickled by Python 2; latin1 maps its byte strings 1:1.
            data = _NumpyOnlyUnpickler(io.BufferedReader(fh), encoding="latin1").load()
    except Exception as exc:  # noqa: BLE001 - any unpickling failure is a file problem
        raise InputFileError(path, f"not a readable pickle of numpy arrays ({type(exc).__name__}: {exc})", expected) from exc
    if not isinstance(data, dict):
        raise InputFileError(path, f"top-level object is a {type(data).__name__}", expected)
    return data


def _array(path: Path, d: dict[str, Any], key: str, shape_ok: Any, expected: str) -> np.ndarray:
    if key not in d:
        raise InputFileError(path, "missing key", expected, field=key)
    try:
        a = np.asarray(d[key])
    except Exception as exc:  # noqa: BLE001
        raise InputFileError(path, f"not an array ({exc})", expected, field=key) from None
    if a.dtype.kind not in "fiu" or not shape_ok(a.shape):
        raise InputFileError(path, f"shape {a.shape} dtype {a.dtype}", expected, field=key)
    return a


def _smpl_motion(path: Path, pose_aa: np.ndarray, betas: np.ndarray, trans: np.ndarray, fps: float,
                 meta: dict[str, Any], field: str) -> Any:
    """SMPL axis-angle ``(T, 3J)`` with J = 22 (SMPL-H body) or 24 -> MotionSequence (Y-up)."""
    # start-up: wearpose.motion adds ~80 ms to import wearpose.recording
    from wearpose.motion.sequence import MotionSequence

    T, n = pose_aa.shape[0], pose_aa.shape[1] // 3
    R = torch.eye(3, dtype=torch.float64).repeat(T, 24, 1, 1)
    aa = torch.from_numpy(pose_aa[:, : 3 * min(n, 24)].astype(np.float64)).reshape(T, min(n, 24), 3)
    # SMPL-H body files have 22 joints; SMPL's hand joints 22/23 stay at identity (as read_amass does).
    R[:, : min(n, 24)] = axis_angle_to_matrix(aa)
    try:
        return MotionSequence(R.float(), torch.from_numpy(np.asarray(betas[:10], dtype=np.float32)),
                              torch.from_numpy(trans.astype(np.float32)), fps, meta)
    except ShapeError as exc:
        raise InputFileError(path, str(exc), "a valid SMPL motion", field=field) from None


def _finite_rows(*arrays: np.ndarray) -> np.ndarray:
    """``(T, S)`` bool: rows where every value of every ``(T, S, ...)`` array is finite."""
    ok = None
    for a in arrays:
        f = np.isfinite(a.reshape(a.shape[0], a.shape[1], -1)).all(axis=2)
        ok = f if ok is None else ok & f
    return ok


def from_dip_imu(path: str | Path, sensors: str | Sequence[int] = "six", fps: float = DIP_IMU_FPS,
                 with_ground_truth: bool = True) -> Recording:
    """Read a DIP-IMU ``.pkl`` (one motion of one subject, e.g. ``s_09/01.pkl``).

    Layout (DIP-IMU's ``DIP_IMU`` release, as read by TransPose's ``preprocess.py``,
    ``process_dipimu``, github.com/Xinyu-Yi/TransPose): a pickled dict with

    - ``imu_ori`` ``(T, 17, 3, 3)``: calibrated sensor orientations ``R_WS`` in DIP's world;
    - ``imu_acc`` ``(T, 17, 3)``: calibrated accelerations in the same world, m/s^2;
    - ``gt`` ``(T, 72)``: SMPL pose, axis-angle radians, 24 joints (no translation);
    - frames where a sensor dropped out are NaN (TransPose fills them with neighbours; we mask).

    Conventions declared (not converted here): world Y up -- TransPose rotates AMASS by
    ``[[1,0,0],[0,0,1],[0,-1,0]]`` "to align AMASS global frame with DIP", i.e. DIP's world is
    Y up like ours; acceleration in the world frame, gravity removed -- TransPose and PIP train on
    synthetic *free* world accelerations and evaluate on ``imu_acc`` unchanged. 60 Hz.

    Args:
        path: the ``.pkl``.
        sensors: ``"six"`` (DIP/TransPose/PIP's 6, :data:`DIP_IMU_SIX`, named as in the ``imu6`` kit), ``"all"``
            (17, :data:`DIP_IMU_SENSORS`) or a list of indices into the 17.
        fps: sample rate, Hz (DIP-IMU: 60).
        with_ground_truth: attach ``gt`` as a :class:`MotionSequence` (zero translation, zero betas:
            DIP-IMU has neither).

    Returns:
        A recording of ``imu`` sensors, timestamps ``i / fps``.
    """
    path = Path(path)
    expected = "a DIP-IMU pickle: dict with imu_ori (T, 17, 3, 3), imu_acc (T, 17, 3), gt (T, 72)"
    d = _read_pkl(path, expected)
    ori = _array(path, d, "imu_ori", lambda s: len(s) == 4 and s[1:] == (17, 3, 3), "(T, 17, 3, 3) rotation matrices")
    T = ori.shape[0]
    acc = _array(path, d, "imu_acc", lambda s: s == (T, 17, 3), f"({T}, 17, 3) m/s^2, matching imu_ori")
    if T == 0:
        raise InputFileError(path, "no frames", "at least one frame", field="imu_ori")
    if sensors == "six":
        picks = [(i, DIP_IMU_SIX[i][0]) for i in DIP_IMU_SIX]
    elif sensors == "all":
        picks = list(enumerate(DIP_IMU_SENSORS))
    else:
        idx = list(sensors)  # type: ignore[arg-type]
        if any(not isinstance(i, (int, np.integer)) or not 0 <= i < 17 for i in idx):
            raise ShapeError(f"from_dip_imu: sensors must be 'six', 'all' or indices in [0, 17), got {sensors!r}")
        picks = [(int(i), DIP_IMU_SIX[int(i)][0] if int(i) in DIP_IMU_SIX else DIP_IMU_SENSORS[int(i)]) for i in idx]
    ok = _finite_rows(ori.astype(np.float64), acc.astype(np.float64))
    ts = np.arange(T, dtype=np.float64) / fps
    streams = []
    for i, name in picks:
        site = DIP_IMU_SIX[i][1] if i in DIP_IMU_SIX else None
        info = SensorInfo(name=name, kind="imu", site=site, rate=float(fps), acc_unit="m/s2", acc_frame="world",
                          acc_gravity="removed", world_up="y_up")
        streams.append(_stream(path, f"imu_ori[:, {i}]", info, ts, ok[:, i],
                               orientation=ori[:, i].astype(np.float32), acceleration=acc[:, i].astype(np.float32)))
    gt = None
    if with_ground_truth and "gt" in d:
        pose = _array(path, d, "gt", lambda s: s == (T, 72), f"({T}, 72) SMPL axis-angle, radians")
        if not np.all(np.isfinite(pose)):
            raise InputFileError(path, "contains NaN or infinite values", "finite SMPL axis-angle", field="gt")
        gt = _smpl_motion(path, pose, np.zeros(10), np.zeros((T, 3)), fps,
                          {"source_file": str(path), "source_format": "dip-imu", "note": "DIP-IMU has no translation or shape; both zero"}, "gt")
    subject = {"id": path.parent.name} if path.parent.name else {}
    meta = {"source": "DIP-IMU", "source_file": str(path), "device": "Xsens MTw",
            "licence": "DIP-IMU licence (non-commercial research; see dip.is.tuebingen.mpg.de)",
            "source_sensor_indices": {name: i for i, name in picks}}
    return Recording(streams, gt, 0.0, subject, meta)


def _stream(path: Path, field: str, info: SensorInfo, ts: np.ndarray, valid: np.ndarray, **channels: np.ndarray) -> SensorStream:
    """Build a stream, turning validation problems into InputFileError on the *source* file."""
    try:
        return SensorStream(info, ts, valid, **channels)
    except ShapeError as exc:
        raise InputFileError(path, f"sensor {info.name!r}: {exc}", "valid sensor data (see docs/formats.md)", field=field) from None


# ------------------------------------------------------------------------------ TotalCapture
#: TotalCapture Xsens sensor names (13 sensors) -> (wearpose sensor name, body site). Names follow
#: the ``imu6`` kit (``left_forearm``, ``left_lower_leg``...), sites the body asset's site names.
TOTALCAPTURE_SITES: dict[str, tuple[str, str]] = {
    "Head": ("head", "head"), "Sternum": ("sternum", "sternum"), "Pelvis": ("pelvis", "pelvis"),
    "L_UpArm": ("left_upper_arm", "left_upper_arm"), "R_UpArm": ("right_upper_arm", "right_upper_arm"),
    "L_LowArm": ("left_forearm", "left_forearm"), "R_LowArm": ("right_forearm", "right_forearm"),
    "L_UpLeg": ("left_upper_leg", "left_thigh"), "R_UpLeg": ("right_upper_leg", "right_thigh"),
    "L_LowLeg": ("left_lower_leg", "left_shin"), "R_LowLeg": ("right_lower_leg", "right_shin"),
    "L_Foot": ("left_foot", "left_foot"), "R_Foot": ("right_foot", "right_foot"),
}
TOTALCAPTURE_FPS = 60.0


def _tc_name(tc: str) -> tuple[str, str | None]:
    if tc in TOTALCAPTURE_SITES:
        return TOTALCAPTURE_SITES[tc]
    return re.sub(r"[^A-Za-z0-9_.\-]", "_", tc.lower())[:64], None


def from_totalcapture(path: str | Path, fps: float = TOTALCAPTURE_FPS, sensors: Sequence[str] | None = None) -> Recording:
    """Read a TotalCapture Xsens text file: ``<seq>_Xsens.sensors`` or ``<Seq>_Xsens_AuxFields.sensors``.

    Layout (from the public readers of the dataset: gait-tech/gaittoolbox
    ``+mocapdb/@XsensBody/loadSensorFile.m`` and the MATLAB ``readXsens.m`` found by code search):

    - line 1: ``<num_sensors> <num_frames>`` (tab separated);
    - per frame: a line with the 1-based frame number, then one line per sensor:
      ``<Name>`` followed by the quaternion ``w x y z`` (sensor -> world), the accelerometer
      ``x y z`` and, in ``_AuxFields`` files only, gyroscope ``x y z`` and magnetometer ``x y z``
      (so 7 or 13 numbers).
    - accelerometer, gyroscope and magnetometer are in the *sensor* frame (gaittoolbox: "For the
      TCD dataset, the accelerometer, gyroscope, magnetometer are in the sensor frame"); the
      accelerometer includes gravity and the world is Z up (``readXsens.m`` removes gravity as
      ``accel - rotateframe(quat, [0 0 9.8])``). Units: m/s^2, rad/s, magnetometer arbitrary
      (Xsens normalised units). 60 Hz.

    Declared accordingly (``acc_frame="sensor"``, ``acc_gravity="included"``, ``world_up="z_up"``);
    :meth:`Recording.to_canonical` converts. A sensor line with NaN or a zero quaternion is a
    dropped frame (masked).

    Args:
        path: the ``.sensors`` file.
        fps: sample rate, Hz.
        sensors: TotalCapture sensor names to keep (default: all in the file).

    Returns:
        ``imu`` sensors (7-number files) or ``mimu`` sensors with orientation (13-number files),
        named as in the ``imu6`` kit with body-asset sites (:data:`TOTALCAPTURE_SITES`; unknown names are lower-cased, site None).
    """
    path = Path(path)
    expected = "TotalCapture .sensors text: '<num_sensors> <num_frames>', then per frame a frame-number line and one '<Name> qw qx qy qz ax ay az [gx gy gz mx my mz]' line per sensor"
    if not path.is_file():
        raise InputFileError(path, "file not found", expected)
    try:
        lines = path.read_text(encoding="utf-8", errors="strict").splitlines()
    except (OSError, UnicodeDecodeError) as exc:
        raise InputFileError(path, f"not a readable text file ({exc})", expected) from None
    lines = [ln for ln in lines if ln.strip()]
    if not lines:
        raise InputFileError(path, "empty file", expected, field="line 1")
    head = lines[0].split()
    try:
        n_sensors, n_frames = int(head[0]), int(head[1])
        if n_sensors <= 0 or n_frames <= 0:
            raise ValueError
    except (ValueError, IndexError):
        raise InputFileError(path, f"header {lines[0][:60]!r}", "'<num_sensors> <num_frames>' (two positive integers)", field="line 1") from None
    need = 1 + n_frames * (n_sensors + 1)
    if len(lines) < need:
        frames_present = max(0, (len(lines) - 1) // (n_sensors + 1))
        raise InputFileError(path, f"{len(lines)} non-empty lines; header promises {n_frames} frames of {n_sensors} sensors (truncated after about {frames_present} frames?)",
                             f"{need} non-empty lines", field=f"line {len(lines) + 1}")
    names: list[str] = []
    width = None
    values = None
    for f in range(n_frames):
        base = 1 + f * (n_sensors + 1)
        try:
            frame_no = int(lines[base].split()[0])
        except (ValueError, IndexError):
            raise InputFileError(path, f"expected a frame number, got {lines[base][:60]!r}", "a line with the frame number", field=f"line {base + 1}") from None
        if frame_no != f + 1:
            raise InputFileError(path, f"frame number {frame_no}", f"frame {f + 1} (frames numbered from 1, in order)", field=f"line {base + 1}")
        for k in range(n_sensors):
            ln = base + 1 + k
            tok = lines[ln].split()
            if not tok:
                raise InputFileError(path, "empty sensor line", "'<Name> <numbers>'", field=f"line {ln + 1}")
            name, nums = tok[0], tok[1:]
            if f == 0:
                if name in names:
                    raise InputFileError(path, f"sensor {name!r} twice in frame 1", "each sensor once per frame", field=f"line {ln + 1}")
                names.append(name)
                if width is None:
                    width = len(nums)
                    if width not in (7, 13):
                        raise InputFileError(path, f"{width} numbers after {name!r}", "7 (quaternion + acc) or 13 (+ gyro + mag) numbers", field=f"line {ln + 1}")
                    values = np.empty((n_frames, n_sensors, width), dtype=np.float64)
            elif name != names[k]:
                raise InputFileError(path, f"sensor {name!r} where frame 1 had {names[k]!r}", "the same sensor order in every frame", field=f"line {ln + 1}")
            if len(nums) != width:
                raise InputFileError(path, f"{len(nums)} numbers after {name!r}", f"{width} numbers, as in frame 1", field=f"line {ln + 1}")
            try:
                values[f, k] = [float(x) for x in nums]  # type: ignore[index]
            except ValueError:
                raise InputFileError(path, f"non-numeric value in {lines[ln][:80]!r}", "numbers", field=f"line {ln + 1}") from None
    assert values is not None and width is not None
    keep = list(range(n_sensors)) if sensors is None else []
    if sensors is not None:
        for s in sensors:
            if s not in names:
                raise ShapeError(f"from_totalcapture: sensor {s!r} not in {path}; it has {names}")
            keep.append(names.index(s))
    kind = "mimu" if width == 13 else "imu"
    ts = np.arange(n_frames, dtype=np.float64) / fps
    streams = []
    for k in keep:
        v = values[:, k]
        q = v[:, 0:4]
        ok = np.isfinite(v).all(axis=1) & (np.linalg.norm(np.nan_to_num(q), axis=1) > 0.5)
        try:
            R = quaternions_to_matrices(q, f"{names[k]} quaternion", ok)
        except _Problem as p:
            raise InputFileError(path, f"sensor {names[k]}: {p.problem}", p.expected, field=f"{names[k]} quaternion") from None
        wp_name, site = _tc_name(names[k])
        info = SensorInfo(name=wp_name, kind=kind, site=site, rate=float(fps), acc_unit="m/s2",
                          acc_frame="sensor", acc_gravity="included", world_up="z_up", gyro_unit="rad/s", mag_unit="a.u.")
        ch = {"orientation": R.astype(np.float32), "acceleration": v[:, 4:7].astype(np.float32)}
        if width == 13:
            ch["angular_velocity"] = v[:, 7:10].astype(np.float32)
            ch["magnetic_field"] = v[:, 10:13].astype(np.float32)
        streams.append(_stream(path, names[k], info, ts, ok, **ch))
    meta = {"source": "TotalCapture", "source_file": str(path), "device": "Xsens MTw",
            "licence": "TotalCapture licence (research use; cvssp.org/data/totalcapture)",
            "source_sensor_names": {_tc_name(names[k])[0]: names[k] for k in keep}}
    return Recording(streams, None, 0.0, {}, meta)


# ------------------------------------------------------------------------------------ EM-POSE
#: EM-POSE's 12 real sensors in the order of its ``*_clean.npz`` arrays (``S_ORDER`` in
#: facebookresearch/em-pose ``empose/helpers/configuration.py``: back, head, right lower arm,
#: right upper arm, right shoulder, right upper leg, right lower leg, then the same on the left),
#: named as in the ``em12`` kit.
EMPOSE_SENSORS: tuple[str, ...] = (
    "back", "head", "right_lower_arm", "right_upper_arm", "right_shoulder", "right_upper_leg", "right_lower_leg",
    "left_lower_arm", "left_upper_arm", "left_shoulder", "left_upper_leg", "left_lower_leg",
)
#: Body site of each (the body asset's site names; the lower-arm tracker sits at the wrist).
EMPOSE_SITES: tuple[str, ...] = (
    "back_upper", "head", "right_wrist", "right_upper_arm", "right_shoulder", "right_thigh", "right_shin",
    "left_wrist", "left_upper_arm", "left_shoulder", "left_thigh", "left_shin",
)
#: The 6-sensor configuration (``S_CONFIG_6 = [0, 1, 2, 6, 7, 11]``): back, head, wrists, lower legs.
EMPOSE_SIX: tuple[int, ...] = (0, 1, 2, 6, 7, 11)
#: EM-POSE paper, Sec. 4: "We downsample the magnetic data from 120 Hz to 30 Hz to match the RGB-D streams".
EMPOSE_FPS = 30.0


def from_empose(path: str | Path, sensors: str | Sequence[int] = "all", fps: float = EMPOSE_FPS,
                with_ground_truth: bool = True) -> Recording:
    """Read one sequence of the EM-POSE real dataset (``<subject>_<action>_clean.npz``).

    Layout (facebookresearch/em-pose, ``empose/data/data.py``, ``RealSample.from_npz_clean``):

    - ``sensor_pos`` ``(F, 12*3)`` (or ``(F, 12, 3)``): sensor positions, metres;
    - ``sensor_oris`` ``(F, 12*9)`` (or ``(F, 12, 3, 3)``): sensor orientations, rotation matrices;
    - ``sensor_masks`` ``(F, 12)``: True where the sensor's frame is available;
    - ``smpl_poses`` ``(F, 66+)``: SMPL(-H) axis-angle, root first (22 body joints used);
    - ``smpl_shape`` ``(10+,)``, ``smpl_trans`` ``(F, 3)`` metres;
    - ``offset_means`` ``(12, 3)``, ``offset_covs`` ``(12, 3, 3)``, ``offset_r`` ``(12, 3, 3)``:
      the subject's sensor-to-skin offsets (stored under ``subject["offsets"]``);
    - ``id``: sequence id.

    Frames: the paper (Sec. 4) calibrates "all sensing devices [to] the same tracking frame, which
    we chose to be the Optitrack frame", and the code normalises sensor positions with the SMPL
    root translation -- so positions/orientations are in that *world* frame, not relative to the
    EM source; declared as ``reference="world"``. The up axis is not documented; we assume Y up
    (OptiTrack's default) -- an assumption, check with a ``to_canonical`` + ground-truth overlay.
    Rate: 30 Hz (paper Sec. 4; the files carry no timestamps).

    Args:
        path: the ``*_clean.npz``.
        sensors: ``"all"`` (12), ``"six"`` (:data:`EMPOSE_SIX`) or indices into the 12.
        fps: frame rate, Hz.
        with_ground_truth: attach the SMPL reference as a :class:`MotionSequence`.
    """
    path = Path(path)
    expected = "an EM-POSE *_clean.npz with sensor_pos, sensor_oris, sensor_masks, smpl_poses, smpl_shape, smpl_trans"
    if not path.is_file():
        raise InputFileError(path, "file not found", expected)
    try:
        with np.load(path, allow_pickle=False) as z:
            d = {k: z[k] for k in z.files}
    except Exception as exc:  # noqa: BLE001
        raise InputFileError(path, npz_problem(path, exc), expected) from exc
    pos = _array(path, d, "sensor_pos", lambda s: len(s) in (2, 3) and s[0] > 0, "(F, 36) or (F, 12, 3) metres")
    F = pos.shape[0]
    pos = pos.reshape(F, -1)
    if pos.shape[1] % 3:
        raise InputFileError(path, f"shape {d['sensor_pos'].shape}", "(F, M*3) or (F, M, 3) metres", field="sensor_pos")
    M = pos.shape[1] // 3
    pos = pos.reshape(F, M, 3)
    ori = _array(path, d, "sensor_oris", lambda s: s[0] == F and int(np.prod(s[1:])) == M * 9, f"({F}, {M * 9}) or ({F}, {M}, 3, 3) rotation matrices").reshape(F, M, 3, 3)
    if "sensor_masks" not in d:
        raise InputFileError(path, "missing key", f"({F}, {M}) True where the sensor's frame is available", field="sensor_masks")
    mask_raw = np.asarray(d["sensor_masks"])
    if mask_raw.shape != (F, M) or mask_raw.dtype.kind not in "biuf":
        raise InputFileError(path, f"shape {mask_raw.shape} dtype {mask_raw.dtype}", f"({F}, {M}) True where available", field="sensor_masks")
    # EM-POSE uses the mask both as bool and as 1.0/0.0 floats (RealBatch compares == 1.0).
    mask = mask_raw.astype(bool) if mask_raw.dtype.kind == "b" else (mask_raw == 1)
    names = EMPOSE_SENSORS if M == 12 else tuple(f"sensor_{i}" for i in range(M))
    if sensors == "all":
        picks = list(range(M))
    elif sensors == "six":
        if M != 12:
            raise ShapeError(f"from_empose: the 6-sensor subset needs the 12-sensor layout; {path} has {M}")
        picks = list(EMPOSE_SIX)
    else:
        picks = [int(i) for i in sensors]  # type: ignore[union-attr]
        if any(not 0 <= i < M for i in picks):
            raise ShapeError(f"from_empose: sensor indices must be in [0, {M}), got {sensors!r}")
    ok = mask & _finite_rows(pos.astype(np.float64), ori.astype(np.float64))
    ts = np.arange(F, dtype=np.float64) / fps
    streams = []
    for i in picks:
        info = SensorInfo(name=names[i], kind="em6dof", site=EMPOSE_SITES[i] if M == 12 else None, rate=float(fps),
                          reference="world", source="empose_source", source_site="pelvis")
        streams.append(_stream(path, f"sensor_pos[:, {i}]", info, ts, ok[:, i],
                               position=pos[:, i].astype(np.float32), orientation=ori[:, i].astype(np.float32)))
    subject: dict[str, Any] = {"id": path.name.split("_")[0]}
    if all(k in d for k in ("offset_means", "offset_covs", "offset_r")):
        subject["offsets"] = {"sensors": [names[i] for i in range(M)],
                              "translation_mean_m": np.asarray(d["offset_means"], dtype=np.float64).tolist(),
                              "translation_cov_m2": np.asarray(d["offset_covs"], dtype=np.float64).tolist(),
                              "rotation": np.asarray(d["offset_r"], dtype=np.float64).tolist()}
    gt = None
    if with_ground_truth:
        poses = _array(path, d, "smpl_poses", lambda s: len(s) == 2 and s[0] == F and s[1] >= 66 and s[1] % 3 == 0, f"({F}, 66+) SMPL axis-angle")
        shape = _array(path, d, "smpl_shape", lambda s: int(np.prod(s)) >= 10, "(10+,) SMPL betas").reshape(-1)
        trans = _array(path, d, "smpl_trans", lambda s: s == (F, 3), f"({F}, 3) metres")
        for k, a in (("smpl_poses", poses), ("smpl_shape", shape), ("smpl_trans", trans)):
            if not np.all(np.isfinite(a)):
                raise InputFileError(path, "contains NaN or infinite values", "finite numbers", field=k)
        gt = _smpl_motion(path, poses[:, :66] if poses.shape[1] != 72 else poses, shape, trans, fps,
                          {"source_file": str(path), "source_format": "em-pose", "skeleton": "smplh-body"}, "smpl_poses")
    seq_id = str(d["id"]) if "id" in d and d["id"].dtype.kind in "US" else path.stem
    meta = {"source": "EM-POSE", "source_file": str(path), "sequence": seq_id, "device": "custom wireless EM tracker (EM-POSE)",
            "licence": "CC BY-NC-SA 4.0 (EM-POSE dataset)",
            "frame_note": "positions/orientations are in the capture's OptiTrack world frame, not the EM source frame"}
    return Recording(streams, gt, 0.0, subject, meta)


# --------------------------------------------------------------------------------------- AMASS
def amass_ground_truth(path: str | Path, rest_joints: torch.Tensor | None = None) -> Any:
    """Ground truth from an AMASS ``.npz`` as a Y-up :class:`MotionSequence`.

    Delegates to :func:`wearpose.motion.read_amass` (the one place AMASS's Z-up world is
    converted); attach it with ``dataclasses.replace(recording, ground_truth=seq,
    ground_truth_start=t0)``.
    """
    from wearpose.motion.amass import read_amass  # start-up: wearpose.motion adds ~80 ms to import wearpose.recording

    return read_amass(path, rest_joints=rest_joints)


# ----------------------------------------------------------------------------------- x-IMU3
#: x-IMU3 device names (the ``name`` in each device folder's ``Command.json``, lower-cased) ->
#: body site. Names that are not listed keep ``site=None`` (still imported).
XIMU3_SITES: dict[str, str] = {
    "pelvis": "pelvis", "head": "head", "sternum": "sternum",
    "left upper leg": "left_thigh", "right upper leg": "right_thigh",
    "left lower leg": "left_shin", "right lower leg": "right_shin",
    "left foot": "left_foot", "right foot": "right_foot",
    "left upper arm": "left_upper_arm", "right upper arm": "right_upper_arm",
    "left forearm": "left_forearm", "right forearm": "right_forearm",
    "left wrist": "left_wrist", "right wrist": "right_wrist",
}
#: A gap between two samples longer than this many nominal periods holds lost samples.
XIMU3_GAP_PERIODS = 1.5


def _ximu3_csv(path: Path, columns: int) -> np.ndarray:
    """The numeric rows of an x-IMU3 CSV (one header line), ``(N, columns)``."""
    if not path.is_file():
        raise InputFileError(path, "file not found", "the x-IMU3 log's Inertial.csv and Quaternion.csv in each device folder")
    try:
        data = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    except ValueError as exc:
        raise InputFileError(path, f"not numeric CSV ({exc})", f"a header line, then rows of {columns} numbers") from None
    if data.shape[1] != columns or len(data) < 2:
        raise InputFileError(path, f"{data.shape[1]} columns, {len(data)} rows", f"{columns} columns and at least 2 rows",
                             field="header")
    return data


def _ximu3_grid(stamps_us: np.ndarray, path: Path, t0_us: float) -> tuple[np.ndarray, np.ndarray, float]:
    """Slots on the device's nominal sample grid (:func:`wearpose.recording.devicelog.sample_grid`,
    the device's clock in microseconds): ``(slot of each sample, timestamps (K,) s from ``t0_us``,
    rate Hz)``."""
    return sample_grid(stamps_us, path, "Timestamp (us)", t0_us, 1e-6, row_offset=2)


#: Devices whose first samples lie further apart than this do not share a clock.
XIMU3_SHARED_CLOCK_US = 1e6


def _ximu3_first_stamp(folder: Path) -> float:
    return float(_ximu3_csv(folder / "Inertial.csv", 7)[0, 0])


def _ximu3_device(folder: Path, t0_us: float | None) -> tuple[SensorStream, dict[str, Any]]:
    """One device folder -> its stream (kind ``imu``) and what the import found about it.
    ``t0_us``: the shared clock's zero, or None to start this device's time at its first sample."""
    try:
        cmd = json.loads((folder / "Command.json").read_text(encoding="utf-8"))
        ping = next(c["ping"] for c in cmd if isinstance(c, dict) and "ping" in c)
        name, serial = str(ping["name"]), str(ping.get("sn", ""))
    except (OSError, ValueError, StopIteration, KeyError, TypeError):
        name, serial = re.sub(r"\s+[0-9A-F]{8}\s*\(.*\)$", "", folder.name), ""
    inertial = _ximu3_csv(folder / "Inertial.csv", 7)  # t (us), gyro (deg/s) x3, acc (g) x3
    quat = _ximu3_csv(folder / "Quaternion.csv", 5)  # t (us), w, x, y, z
    if not np.array_equal(inertial[:, 0], quat[:, 0]):
        raise InputFileError(folder / "Quaternion.csv", "its timestamps differ from Inertial.csv's",
                             "one Quaternion row per Inertial row, same timestamps (the device's own log)",
                             field="Timestamp (us)")
    slot, ts, rate = _ximu3_grid(inertial[:, 0], folder / "Inertial.csv", inertial[0, 0] if t0_us is None else t0_us)
    K = len(ts)
    valid = np.zeros(K, bool)
    valid[slot] = True
    gyro, acc, q = (np.full((K, n), np.nan) for n in (3, 3, 4))
    gyro[slot], acc[slot], q[slot] = inertial[:, 1:4], inertial[:, 4:7], quat[:, 1:5]
    key = re.sub(r"[^a-z0-9]+", "_", name.lower()).strip("_")
    info = SensorInfo(key, "imu", site=XIMU3_SITES.get(name.lower()), rate=rate, acc_unit="g", acc_frame="sensor",
                      acc_gravity="included", world_up="z_up", gyro_unit="deg/s")
    try:
        R = quaternions_to_matrices(q, f"{folder.name}/Quaternion.csv", valid)
    except _Problem as p:
        raise InputFileError(folder / "Quaternion.csv", p.problem, p.expected, field=p.field) from None
    stream = _stream(folder / "Inertial.csv", "Inertial.csv", info, ts, valid, orientation=R, acceleration=acc,
                     angular_velocity=gyro)
    found = {"device": name, "serial": serial, "folder": folder.name, "samples": int(len(slot)), "slots": K,
             "lost": int(K - len(slot)), "rate_hz": round(rate, 4), "clock_start_us": int(inertial[0, 0]),
             "magnetometer": "not imported (own clock and rate; would need resampling)"}
    return stream, found


def from_ximu3(path: str | Path) -> Recording:
    """An x-IMU3 log folder (the x-IMU3 software's layout: one sub-folder per device with
    ``Inertial.csv``, ``Quaternion.csv``, ``Command.json``) -> a :class:`Recording` of kind-``imu``
    sensors, one per device, named after the device (``"Left Lower Leg"`` -> ``left_lower_leg``).

    Declared as the files hold it (x-io's CSV headers): gyroscope deg/s, accelerometer in g in the
    sensor frame with gravity included, orientation the device AHRS's quaternion (w, x, y, z) in
    its Earth frame (North-West-Up: Z up, ``world_up="z_up"``; heading is magnetic).
    Each device stamps its own samples (microseconds). When the devices' first samples lie within
    :data:`XIMU3_SHARED_CLOCK_US` of each other their clocks are taken as one (x-IMU3 devices
    synchronise over the network; the shared log's first samples lie within 17 ms), time 0 at the
    earliest first sample; otherwise each device's time starts at its own first sample (the
    software starts all logs at once; left over: up to a sample period). ``meta["import"]`` says
    which. A sample lost over UDP is a masked slot on the device's own grid (nominal timestamp),
    never filled in.
    ``Magnetometer.csv`` has its own clock and rate and is not imported (``meta`` says so).

    Raises:
        InputFileError: no device folder, a missing or malformed CSV (file, column, the fix).
    """
    root = Path(path)
    devices = sorted(d for d in root.iterdir() if (d / "Inertial.csv").is_file()) if root.is_dir() else []
    if not devices:
        raise InputFileError(root, "no x-IMU3 device folders", "a folder holding one sub-folder per device, each with "
                             "Inertial.csv and Quaternion.csv (the x-IMU3 software's log)")
    starts = [_ximu3_first_stamp(d) for d in devices]
    shared = max(starts) - min(starts) <= XIMU3_SHARED_CLOCK_US
    streams, found = zip(*(_ximu3_device(d, min(starts) if shared else None) for d in devices))
    names = [s.info.name for s in streams]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise InputFileError(root, f"two devices are both named {dup}", "one name per device (rename one in the x-IMU3 software)")
    clock = ("shared device clock, t = 0 at the earliest first sample" if shared else
             "device clocks differ: each device's t = 0 at its own first sample")
    meta = {"source": "x-IMU3 log", "path": str(root), "import": {"devices": list(found), "clock": clock}}
    return Recording(list(streams), meta=meta)
