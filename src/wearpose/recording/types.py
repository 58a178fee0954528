"""``Recording``: one container for every sensor modality (EM 6-DoF, IMU, MIMU, headset VIO).

A recording is a list of named sensors. Each sensor has static facts (:class:`SensorInfo`: kind,
body site, nominal rate, the conventions its data was written in) and a time series
(:class:`SensorStream`: timestamps, validity mask, per-kind channels). Streams are numpy arrays
(file readers and device drivers produce numpy; estimators convert to torch at their own edge).

Frames and units (see ``docs/formats.md`` for the field-by-field contract):

- ``position`` ``(N, 3)``: metres. EM: sensor origin in the EM source frame (or in a world frame
  when :attr:`SensorInfo.reference` is ``"world"``); VIO: headset position in its world frame.
- ``orientation`` ``(N, 3, 3)``: ``R_WS`` maps sensor-frame vectors to the reference frame
  (world for inertial/VIO, source for EM).
- ``acceleration`` ``(N, 3)``: canonical form is *free* acceleration (gravity removed) in the
  Y-up world, m/s^2. Other conventions are allowed when declared in :class:`SensorInfo` and are
  converted by :meth:`Recording.to_canonical` -- once, and nowhere else.
- ``angular_velocity`` ``(N, 3)``: sensor frame, rad/s (or declared deg/s).
- ``magnetic_field`` ``(N, 3)``: sensor frame, unit declared in :attr:`SensorInfo.mag_unit`.

Dropped frames are masked (``valid[i] = False``) and their channel values are NaN in memory; they
are never interpolated here.
"""

from __future__ import annotations

import copy
import difflib
import math
import re
from dataclasses import dataclass, field, fields, replace
from typing import Any, Iterable, Sequence

import numpy as np
import torch

from wearpose.errors import ShapeError, WearposeError
from wearpose.geometry import GRAVITY, Z_UP_TO_Y_UP, quat_to_matrix

KINDS: tuple[str, ...] = ("em6dof", "imu", "mimu", "vio")
#: Channels every kind must carry, and the ones it may carry.
REQUIRED_CHANNELS: dict[str, tuple[str, ...]] = {
    "em6dof": ("position", "orientation"),
    "imu": ("orientation", "acceleration"),
    "mimu": ("acceleration", "angular_velocity", "magnetic_field"),
    "vio": ("position", "orientation"),
}
OPTIONAL_CHANNELS: dict[str, tuple[str, ...]] = {
    "em6dof": (),
    "imu": ("angular_velocity", "magnetic_field"),
    "mimu": ("orientation",),
    "vio": ("angular_velocity",),
}
CHANNELS: tuple[str, ...] = ("position", "orientation", "acceleration", "angular_velocity", "magnetic_field")
#: Trailing shape of each channel (in memory; on disk orientation may also be a (N, 4) quaternion).
CHANNEL_SHAPES: dict[str, tuple[int, ...]] = {
    "position": (3,), "orientation": (3, 3), "acceleration": (3,), "angular_velocity": (3,), "magnetic_field": (3,),
}

_CHOICES: dict[str, tuple[str, ...]] = {
    "kind": KINDS,
    "acc_unit": ("m/s2", "g"),
    "acc_frame": ("world", "sensor"),
    "acc_gravity": ("removed", "included"),
    "world_up": ("y_up", "z_up"),
    "position_unit": ("m", "cm", "mm"),
    "gyro_unit": ("rad/s", "deg/s"),
    "reference": ("world", "source"),
}
_POSITION_SCALE = {"m": 1.0, "cm": 0.01, "mm": 0.001}
#: Standard gravity used to convert "g" to m/s^2 (the same magnitude as wearpose's GRAVITY).
G = 9.81
#: Sensor names become file keys (``sensors/<name>/<field>``): keep them path- and shell-safe.
NAME_RE = re.compile(r"^[A-Za-z0-9_.\-]{1,64}$")
#: Two sensors are "on the same grid" when their timestamps agree to this many seconds.
GRID_TOLERANCE_S = 1e-6


class RecordingError(WearposeError, ValueError):
    """A recording cannot do what was asked (e.g. sensors on different time grids)."""


class _Problem(Exception):
    """Internal: one validation failure, turned into ShapeError (memory) or InputFileError (file)."""

    def __init__(self, field: str, problem: str, expected: str):
        super().__init__(f"{field}: {problem}")
        self.field, self.problem, self.expected = field, problem, expected


@dataclass(frozen=True)
class SensorInfo:
    """Static facts about one sensor.

    Attributes:
        name: unique within the recording; ``[A-Za-z0-9_.-]{1,64}`` (it becomes a file key).
        kind: ``"em6dof"``, ``"imu"``, ``"mimu"`` or ``"vio"``.
        site: body site name, one of :func:`known_sites` (e.g. ``"left_forearm"``,
            ``"left_shin"``), or ``None`` when unknown/off-body.
        rate: nominal sample rate, Hz (checked against the timestamps on load).
        acc_unit: ``"m/s2"`` or ``"g"`` (1 g = 9.81 m/s^2).
        acc_frame: ``"world"`` or ``"sensor"`` (sensor-frame acceleration is rotated with
            ``orientation``).
        acc_gravity: ``"removed"`` (free acceleration) or ``"included"`` (accelerometer reading,
            i.e. specific force ``a - g``: reads +9.81 m/s^2 *up* at rest).
        world_up: up axis of the world the orientation/position/world-frame acceleration are
            expressed in: ``"y_up"`` (wearpose) or ``"z_up"`` (converted by a -90 deg rotation
            about X, :data:`wearpose.geometry.Z_UP_TO_Y_UP`).
        position_unit: ``"m"``, ``"cm"`` or ``"mm"``.
        gyro_unit: ``"rad/s"`` or ``"deg/s"``.
        mag_unit: free text unit of ``magnetic_field`` (``"uT"``, ``"a.u."``...); never converted.
        reference: frame ``position``/``orientation`` are relative to. EM: ``"source"`` (the EM
            source, EM canonical form; default) or ``"world"`` (a world/tracking frame, e.g. an
            optical tracker's, as in EM-POSE's released data). IMU/MIMU/VIO: always ``"world"``
            (the default for them). ``None`` means "the kind's default".
        source: EM only: name of the EM source (transmitter) the sensor is measured against.
        source_site: EM only: body site of that source (``"lower_back"``, ``"head"``...).
    """

    name: str
    kind: str
    site: str | None = None
    rate: float = 60.0
    acc_unit: str = "m/s2"
    acc_frame: str = "world"
    acc_gravity: str = "removed"
    world_up: str = "y_up"
    position_unit: str = "m"
    gyro_unit: str = "rad/s"
    mag_unit: str = "a.u."
    reference: str | None = None
    source: str | None = None
    source_site: str | None = None

    def __post_init__(self) -> None:
        try:
            _check_info(self)
        except _Problem as p:
            raise ShapeError(f"SensorInfo {p.field}: {p.problem}; expected {p.expected}") from None

    def to_json(self) -> dict[str, Any]:
        """A JSON-ready dict with every field (the on-disk form)."""
        return {f.name: getattr(self, f.name) for f in fields(self)}

    @classmethod
    def from_json(cls, d: Any) -> SensorInfo:
        """Inverse of :meth:`to_json`; unknown keys are an error (they are usually typos)."""
        if not isinstance(d, dict):
            raise _Problem("sensors", f"entry is a {type(d).__name__}", "a JSON object per sensor")
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(d) - known)
        name = d.get("name", "?")
        if unknown:
            raise _Problem(f"sensors/{name}", f"unknown key(s) {unknown}", f"only {sorted(known)}")
        for key in ("name", "kind"):
            if key not in d:
                raise _Problem(f"sensors/{name}", f"missing key {key!r}", "every sensor has 'name' and 'kind'")
        info = object.__new__(cls)
        defaults = cls.__dataclass_fields__
        for f in fields(cls):
            object.__setattr__(info, f.name, d.get(f.name, defaults[f.name].default))
        _check_info(info)
        return info

    @property
    def is_canonical(self) -> bool:
        """True when the data already uses every wearpose convention (nothing to convert)."""
        return (self.acc_unit == "m/s2" and self.acc_frame == "world" and self.acc_gravity == "removed"
                and self.world_up == "y_up" and self.position_unit == "m" and self.gyro_unit == "rad/s")


def _check_info(info: SensorInfo) -> None:
    where = f"sensors/{info.name}" if isinstance(info.name, str) else "sensors"
    if not isinstance(info.name, str) or not NAME_RE.match(info.name):
        raise _Problem(where, f"sensor name {info.name!r} is not allowed", "1-64 characters from [A-Za-z0-9_.-]")
    if info.reference is None and info.kind in KINDS:
        # Resolved here so the file always states the frame explicitly.
        object.__setattr__(info, "reference", "source" if info.kind == "em6dof" else "world")
    for key, choices in _CHOICES.items():
        value = getattr(info, key)
        if value not in choices:
            raise _Problem(f"{where}/{key}" if key != "kind" else f"{where}/kind",
                           f"{'unknown kind' if key == 'kind' else 'unknown value'} {value!r}", f"one of {list(choices)}")
    if info.kind != "em6dof" and info.reference != "world":
        raise _Problem(f"{where}/reference", f"{info.reference!r} for a {info.kind} sensor", "'world': only EM sensors measure relative to a source")
    for key in ("site", "source", "source_site"):
        v = getattr(info, key)
        if v is not None and not isinstance(v, str):
            raise _Problem(f"{where}/{key}", f"value {v!r}", "a string or null")
    if info.site is not None:
        unknown = _unknown_site(info.site)
        if unknown is not None:
            raise _Problem(f"{where}/site", *unknown)
    if not isinstance(info.mag_unit, str):
        raise _Problem(f"{where}/mag_unit", f"value {info.mag_unit!r}", "a string such as 'uT' or 'a.u.'")
    rate = info.rate
    if isinstance(rate, bool) or not isinstance(rate, (int, float)) or not math.isfinite(rate) or rate <= 0:
        raise _Problem(f"{where}/rate", f"value {rate!r}", "a positive number of samples per second (Hz)")


def known_sites() -> frozenset[str]:
    """Body sites a :attr:`SensorInfo.site` may name.

    The sites wearpose knows a bone segment for (:data:`wearpose.sensors.SITE_SEGMENT`: the 18
    sites of the embedded body asset, which include the 6 SMPL-file sites) and every site of a
    registered kit (sensor sites, their fallbacks, EM source sites), so a kit registered for a
    custom body asset brings its own sites.
    """
    # Imported here: wearpose.sensors sits above nothing recording needs at import time.
    # start-up: wearpose.sensors adds ~130 ms to import wearpose.recording
    from wearpose.sensors.kits import SITE_SEGMENT, get_kit, list_kits

    sites = set(SITE_SEGMENT)
    for name in list_kits():
        kit = get_kit(name)
        for spec in kit.sensors:
            sites.add(spec.site)
            sites.update(spec.fallback_sites)
        if kit.em_source_site is not None:
            sites.add(kit.em_source_site)
    return frozenset(sites)


def _unknown_site(site: str) -> tuple[str, str] | None:
    """``(problem, expected)`` for a site wearpose does not know, ``None`` for a known one.

    The commonest mix-up is a kit's *sensor name* for its site (``imu6``'s sensor
    ``left_lower_leg`` is worn on site ``left_shin``): that site is suggested first, then the
    nearest known names (difflib).
    """
    known = known_sites()
    if site in known:
        return None
    # start-up: wearpose.sensors adds ~130 ms to import wearpose.recording
    from wearpose.sensors.kits import get_kit, list_kits

    worn_on: dict[str, list[str]] = {}  # site -> kits having a sensor named `site` worn there
    for name in list_kits():
        for spec in get_kit(name).sensors:
            if spec.name == site:
                worn_on.setdefault(spec.site, []).append(name)
    if site.lower() in known:
        suggestions = [site.lower()]
    elif worn_on:
        suggestions = list(worn_on)
    else:
        suggestions = difflib.get_close_matches(site.lower(), sorted(known), n=3, cutoff=0.6)
    problem = f"unknown body site {site!r}"
    if worn_on:
        problem += " (" + "; ".join(f"the sensor {site!r} of kit{'s' if len(kits) > 1 else ''} {', '.join(kits)} is worn on site {where!r}"
                                   for where, kits in worn_on.items()) + ")"
    guess = ""
    if suggestions:
        names = [repr(x) for x in suggestions]
        guess = f"did you mean {names[0] if len(names) == 1 else ', '.join(names[:-1]) + ' or ' + names[-1]}? "
    expected = (f"a known body site ({guess}known: {', '.join(sorted(known))}; a kit registered with "
                "wearpose.sensors.register_kit adds its own), or null when the site is unknown")
    return problem, expected


@dataclass
class SensorStream:
    """One sensor's time series.

    Attributes:
        info: the sensor's :class:`SensorInfo`.
        timestamps: ``(N,)`` float64 seconds, strictly increasing, one per frame *including*
            dropped frames.
        valid: ``(N,)`` bool; ``False`` marks a dropped/unusable frame (its channel values are NaN).
        position: ``(N, 3)`` or ``None`` (units/frame: see module docstring and ``info``).
        orientation: ``(N, 3, 3)`` rotation matrices ``R_WS`` or ``None``.
        acceleration, angular_velocity, magnetic_field: ``(N, 3)`` or ``None``.

    Channels are float32 (wearpose default) unless given as float64. The constructor validates
    shapes, finiteness of valid frames, rotation matrices and the channels the kind requires.
    """

    info: SensorInfo
    timestamps: np.ndarray
    valid: np.ndarray
    position: np.ndarray | None = None
    orientation: np.ndarray | None = None
    acceleration: np.ndarray | None = None
    angular_velocity: np.ndarray | None = None
    magnetic_field: np.ndarray | None = None

    def __post_init__(self) -> None:
        try:
            _normalise_stream(self)
        except _Problem as p:
            raise ShapeError(f"SensorStream {p.field}: {p.problem}; expected {p.expected}") from None

    @property
    def name(self) -> str:
        return self.info.name

    @property
    def kind(self) -> str:
        return self.info.kind

    @property
    def num_frames(self) -> int:
        return int(self.timestamps.shape[0])

    def __len__(self) -> int:
        return self.num_frames

    def channels(self) -> dict[str, np.ndarray]:
        """The channels present, by name, in :data:`CHANNELS` order."""
        return {c: getattr(self, c) for c in CHANNELS if getattr(self, c) is not None}


# Tolerances for "is a rotation": float32 data written by devices is orthonormal to ~1e-6; 1e-2
# accepts slightly drifted/rounded matrices but rejects scaled, sheared or reflected ones.
ROTATION_TOL = 1e-2


def _normalise_stream(s: SensorStream, prefix: str | None = None) -> None:
    """Validate and normalise dtypes in place. Raises :class:`_Problem` with a file-style field."""
    info = s.info
    if not isinstance(info, SensorInfo):
        raise _Problem("info", f"got {type(info).__name__}", "a SensorInfo")
    where = prefix if prefix is not None else f"sensors/{info.name}"
    ts = _as_float_array(s.timestamps, f"{where}/timestamps", np.float64)
    if ts.ndim != 1:
        raise _Problem(f"{where}/timestamps", f"shape {ts.shape}", "(N,) seconds")
    n = ts.shape[0]
    if n == 0:
        raise _Problem(f"{where}/timestamps", "no frames", "at least one frame")
    if not np.all(np.isfinite(ts)):
        raise _Problem(f"{where}/timestamps", "contains NaN or infinite values", "finite seconds for every frame (dropped frames keep their timestamp and are masked in valid)")
    if n > 1 and not np.all(np.diff(ts) > 0):
        i = int(np.argmax(~(np.diff(ts) > 0)))
        raise _Problem(f"{where}/timestamps", f"not strictly increasing (frame {i + 1}: {ts[i + 1]!r} after {ts[i]!r})", "strictly increasing seconds")
    s.timestamps = ts
    valid = np.asarray(s.valid)
    if valid.dtype != np.bool_:
        if valid.dtype.kind in "iu" and valid.size and np.all((valid == 0) | (valid == 1)):
            valid = valid.astype(bool)
        elif valid.dtype.kind in "iu" and valid.size == 0:
            valid = valid.astype(bool)
        else:
            raise _Problem(f"{where}/valid", f"dtype {valid.dtype}", "(N,) bool (or integers 0/1)")
    if valid.shape != (n,):
        raise _Problem(f"{where}/valid", _length_problem(valid.shape, n), f"({n},) bool, one per timestamp")
    s.valid = valid
    kind = info.kind
    allowed = REQUIRED_CHANNELS[kind] + OPTIONAL_CHANNELS[kind]
    for c in CHANNELS:
        arr = getattr(s, c)
        if arr is None:
            if c in REQUIRED_CHANNELS[kind]:
                raise _Problem(f"{where}/{c}", f"missing; a {kind} sensor requires {list(REQUIRED_CHANNELS[kind])}", f"(N, {', '.join(map(str, CHANNEL_SHAPES[c]))}) array")
            continue
        if c not in allowed:
            raise _Problem(f"{where}/{c}", f"channel not allowed for a {kind} sensor", f"only {list(allowed)}")
        arr = _as_float_array(arr, f"{where}/{c}", None)
        tail = CHANNEL_SHAPES[c]
        if arr.ndim != 1 + len(tail) or tuple(arr.shape[1:]) != tail:
            raise _Problem(f"{where}/{c}", f"shape {arr.shape}", f"(N, {', '.join(map(str, tail))})")
        if arr.shape[0] != n:
            raise _Problem(f"{where}/{c}", _length_problem(arr.shape, n), f"{n} frames, one per timestamp")
        good = arr[valid]
        if not np.all(np.isfinite(good)):
            bad = int(np.flatnonzero(valid)[np.flatnonzero(~np.all(np.isfinite(good.reshape(good.shape[0], -1)), axis=1))[0]])
            raise _Problem(f"{where}/{c}", f"NaN or infinite value in valid frame {bad}", "finite values wherever valid is True (NaN only in frames with valid=False)")
        if c == "orientation" and good.shape[0]:
            _check_rotations(good, f"{where}/{c}", np.flatnonzero(valid))
        # A dropped frame carries no data: make that explicit so nobody uses a stale value.
        arr[~valid] = np.nan
        setattr(s, c, arr)


def _length_problem(shape: tuple[int, ...], n: int) -> str:
    got = shape[0] if len(shape) else 0
    if got < n:
        return f"only {got} frames for {n} timestamps (truncated?)"
    return f"{got} frames for {n} timestamps"


def _as_float_array(x: Any, where: str, dtype: Any) -> np.ndarray:
    if isinstance(x, torch.Tensor):
        x = x.detach().cpu().numpy()
    try:
        arr = np.asarray(x)
    except Exception as exc:  # noqa: BLE001 - ragged lists etc.
        raise _Problem(where, f"not an array ({exc})", "a numeric array") from None
    if arr.dtype.kind not in "fiu" or arr.dtype.kind == "b":
        raise _Problem(where, f"dtype {arr.dtype}", "a floating-point array")
    if dtype is None:
        dtype = np.float64 if arr.dtype == np.float64 else np.float32
    return np.array(arr, dtype=dtype, copy=True)


def _check_rotations(R: np.ndarray, where: str, frame_ids: np.ndarray) -> None:
    R64 = R.astype(np.float64)
    det = np.linalg.det(R64)
    ortho = np.abs(np.einsum("nji,njk->nik", R64, R64) - np.eye(3)).max(axis=(1, 2))
    bad = np.flatnonzero((np.abs(det - 1.0) > ROTATION_TOL) | (ortho > ROTATION_TOL))
    if bad.size:
        i = int(bad[0])
        raise _Problem(where, f"frame {int(frame_ids[i])} is not a rotation (det {det[i]:.4g}, max |R^T R - I| {ortho[i]:.3g})",
                       f"proper rotation matrices (det 1, orthonormal within {ROTATION_TOL}) or unit quaternions (w, x, y, z)")


def quaternions_to_matrices(q: np.ndarray, where: str, valid: np.ndarray) -> np.ndarray:
    """``(N, 4)`` (w, x, y, z) unit quaternions -> ``(N, 3, 3)``; invalid frames become NaN.

    Raises :class:`_Problem` when a valid frame's quaternion is not unit-norm within
    :data:`ROTATION_TOL` (a scaled quaternion usually means a wrong component order or unit).
    """
    q = np.asarray(q, dtype=np.float64)
    out = np.full((q.shape[0], 3, 3), np.nan)
    good = q[valid]
    if good.size:
        if not np.all(np.isfinite(good)):
            bad = int(np.flatnonzero(valid)[np.flatnonzero(~np.all(np.isfinite(good), axis=1))[0]])
            raise _Problem(where, f"NaN or infinite value in valid frame {bad}", "finite values wherever valid is True (NaN only in frames with valid=False)")
        norm = np.linalg.norm(good, axis=1)
        bad = np.flatnonzero(np.abs(norm - 1.0) > ROTATION_TOL)
        if bad.size:
            i = int(bad[0])
            raise _Problem(where, f"frame {int(np.flatnonzero(valid)[i])} quaternion has norm {norm[i]:.4g}",
                           "unit quaternions (w, x, y, z), or (N, 3, 3) rotation matrices")
        out[valid] = quat_to_matrix(torch.from_numpy(good)).numpy()
    return out


@dataclass
class CommonGrid:
    """Sensors stacked on one shared time grid (:meth:`Recording.on_common_grid`).

    Attributes:
        timestamps: ``(T,)`` seconds.
        names: ``(S,)`` sensor names, in recording order.
        valid: ``(T, S)`` bool per-sensor validity.
        all_valid: ``(T,)`` bool, frames where every sensor is valid (the joint mask).
        channels: field name -> ``(T, S, ...)`` array, for every channel at least one sensor
            has; NaN where a sensor lacks that channel or the frame is invalid.
        has: field name -> ``(S,)`` bool, which sensors carry that channel.
    """

    timestamps: np.ndarray
    names: tuple[str, ...]
    valid: np.ndarray
    all_valid: np.ndarray
    channels: dict[str, np.ndarray]
    has: dict[str, np.ndarray]


@dataclass
class Recording:
    """Every sensor of one capture, plus optional ground truth and metadata.

    Attributes:
        sensors: list of :class:`SensorStream` (names unique), in a fixed order.
        ground_truth: optional :class:`wearpose.motion.MotionSequence`, frame ``i`` at time
            ``ground_truth_start + i / ground_truth.fps`` on the sensors' clock.
        ground_truth_start: seconds, see above.
        subject: JSON-serialisable facts about the wearer: ``id``, ``height_m``, ``sex``,
            ``offsets`` (e.g. EM-POSE sensor-to-skin offsets) ...
        meta: JSON-serialisable provenance: ``source``, ``licence``, ``device`` ...
        origin: the file this recording was read from (:func:`~wearpose.recording.load_recording`
            sets it; copies made from it keep it), None for one made in memory. Not written to
            files and not compared: it only lets errors about the data name the file.
    """

    sensors: list[SensorStream]
    ground_truth: Any = None  # MotionSequence | None (imported lazily: motion is finished in parallel)
    ground_truth_start: float = 0.0
    subject: dict[str, Any] = field(default_factory=dict)
    meta: dict[str, Any] = field(default_factory=dict)
    origin: str | None = field(default=None, compare=False)

    def __post_init__(self) -> None:
        self.sensors = list(self.sensors)
        if not self.sensors:
            raise ShapeError("Recording: expected at least one sensor")
        seen: set[str] = set()
        for s in self.sensors:
            if not isinstance(s, SensorStream):
                raise ShapeError(f"Recording.sensors: expected SensorStream items, got {type(s).__name__}")
            if s.name in seen:
                raise ShapeError(f"Recording: sensor name {s.name!r} appears twice; names must be unique")
            seen.add(s.name)
        if self.ground_truth is not None:
            # start-up: wearpose.motion adds ~80 ms to import wearpose.recording
            from wearpose.motion.sequence import MotionSequence

            if not isinstance(self.ground_truth, MotionSequence):
                raise ShapeError(f"Recording.ground_truth: expected a MotionSequence or None, got {type(self.ground_truth).__name__}")
        if not isinstance(self.subject, dict) or not isinstance(self.meta, dict):
            raise ShapeError("Recording.subject and Recording.meta must be dicts")
        self.ground_truth_start = float(self.ground_truth_start)

    @classmethod
    def from_stacked(cls, infos: Sequence[SensorInfo], timestamps: Any, channels: dict[str, Any],
                     valid: Any = None, **kwargs: Any) -> Recording:
        """Build a recording from arrays stacked over sensors (the inverse of :meth:`on_common_grid`).

        Args:
            infos: ``S`` sensor infos, in column order.
            timestamps: ``(T,)`` seconds shared by every sensor.
            channels: field name -> ``(T, S, ...)`` array (e.g. a simulator's output). A sensor
                takes a channel when its kind allows it and its column is not entirely NaN.
            valid: ``(T, S)`` bool, default all True.
            **kwargs: ``ground_truth``, ``ground_truth_start``, ``subject``, ``meta``.
        """
        infos = list(infos)
        S = len(infos)
        ts = np.asarray(timestamps, dtype=np.float64)
        v = np.ones((ts.shape[0], S), bool) if valid is None else np.asarray(valid)
        if v.shape != (ts.shape[0], S):
            raise ShapeError(f"Recording.from_stacked: valid has shape {v.shape}, expected ({ts.shape[0]}, {S})")
        streams = []
        for j, info in enumerate(infos):
            allowed = REQUIRED_CHANNELS[info.kind] + OPTIONAL_CHANNELS[info.kind]
            ch = {}
            for c, arr in channels.items():
                if c not in CHANNELS:
                    raise ShapeError(f"Recording.from_stacked: unknown channel {c!r}; expected one of {list(CHANNELS)}")
                a = arr.detach().cpu().numpy() if isinstance(arr, torch.Tensor) else np.asarray(arr)
                if a.ndim < 2 or a.shape[1] != S:
                    raise ShapeError(f"Recording.from_stacked: channel {c!r} has shape {a.shape}, expected (T, {S}, ...)")
                col = a[:, j]
                if c in allowed and not np.all(np.isnan(col)):
                    ch[c] = col
            streams.append(SensorStream(info, ts, v[:, j], **ch))
        return cls(streams, **kwargs)

    @classmethod
    def from_simulation(cls, result: Any, motion: Any = None, subject: dict[str, Any] | str | None = None,
                        **kwargs: Any) -> Recording:
        """A recording of a :func:`wearpose.sensors.simulate` result (``motion`` becomes the
        ground truth); see :func:`wearpose.recording.simulated.recording_from_simulation`."""
        # cycle: wearpose.recording.simulated imports wearpose.recording.types
        from wearpose.recording.simulated import recording_from_simulation

        return recording_from_simulation(result, motion, subject, **kwargs)

    # ------------------------------------------------------------------ queries
    @property
    def names(self) -> tuple[str, ...]:
        return tuple(s.name for s in self.sensors)

    def sensor(self, name: str) -> SensorStream:
        """The stream of sensor ``name``; :class:`KeyError` naming the available sensors."""
        for s in self.sensors:
            if s.name == name:
                return s
        raise KeyError(f"no sensor {name!r} in this recording; sensors: {list(self.names)}")

    @property
    def kinds(self) -> tuple[str, ...]:
        """Distinct sensor kinds present, in :data:`KINDS` order."""
        present = {s.kind for s in self.sensors}
        return tuple(k for k in KINDS if k in present)

    @property
    def duration(self) -> float:
        """Seconds from the earliest to the latest timestamp over all sensors."""
        return float(max(s.timestamps[-1] for s in self.sensors) - min(s.timestamps[0] for s in self.sensors))

    @property
    def is_canonical(self) -> bool:
        return all(s.info.is_canonical for s in self.sensors)

    def select(self, names: Iterable[str]) -> Recording:
        """A recording with only the named sensors (in the given order); data is shared."""
        return replace(self, sensors=[self.sensor(n) for n in names])

    # ------------------------------------------------------------------ conventions
    def to_canonical(self) -> Recording:
        """A copy with every declared convention converted to wearpose's canonical form.

        Per sensor, in this order (each step needs the previous one):

        1. positions cm/mm -> m; angular velocity deg/s -> rad/s; acceleration g -> m/s^2;
        2. sensor-frame acceleration -> world frame: ``a_W = R_WS a_S`` (uses ``orientation``);
        3. Z-up world -> Y-up: ``C = Z_UP_TO_Y_UP`` applied as ``C R``, ``C p``, ``C a``;
        4. gravity removal: ``a_free = f + g`` with ``g = (0, -9.81, 0)``: an accelerometer
           reading ``f`` (specific force) is ``+9.81`` up at rest, free acceleration is 0.

        A MIMU sensor without ``orientation`` cannot be rotated to the world: its acceleration
        stays in the sensor frame with gravity included (still converted to m/s^2), and its info
        keeps declaring that. Angular velocity and magnetic field stay in the sensor frame by
        definition. Ground truth is untouched (MotionSequence is Y-up by construction).
        """
        out = []
        converted = []
        for s in self.sensors:
            info = s.info
            if info.is_canonical:
                out.append(copy.deepcopy(s))
                continue
            ch = {k: (None if v is None else v.astype(np.float64)) for k, v in s.channels().items()}
            converted.append(info.name)
            new, ch = canonical_arrays(info, ch)
            # Keep each channel's dtype (float32 by default): conversion precision is float64 above.
            ch = {k: v.astype(getattr(s, k).dtype) for k, v in ch.items()}
            out.append(SensorStream(replace(info, **new), s.timestamps.copy(), s.valid.copy(), **ch))
        meta = copy.deepcopy(self.meta)
        if converted:
            # Provenance: which sensors were converted from declared conventions.
            meta["converted_to_canonical"] = sorted(set(meta.get("converted_to_canonical", [])) | set(converted))
        return Recording(out, self.ground_truth, self.ground_truth_start, copy.deepcopy(self.subject), meta,
                         self.origin)

    def declared_as(self, position_unit: str = "m", gyro_unit: str = "rad/s", acc_unit: str = "m/s2",
                    acc_frame: str = "world", acc_gravity: str = "removed", world_up: str = "y_up") -> Recording:
        """The inverse of :meth:`to_canonical`: a canonical recording's data rewritten in the given
        conventions, each declared in the sensors' info (``declared_as(...).to_canonical()``
        gives the data back to float precision).

        What a device or a file in those conventions would hold: positions in ``position_unit``,
        angular velocity in ``gyro_unit``, accelerometer readings (``acc_gravity="included"``:
        specific force, +1 g up at rest) in ``acc_unit`` and ``acc_frame``, everything in a
        ``world_up`` world. A convention only applies to sensors carrying its channel;
        ``acc_frame="sensor"`` needs ``orientation``.

        Raises:
            RecordingError: the recording is not canonical, or sensor-frame acceleration is asked
                of a sensor without orientation.
        """
        if not self.is_canonical:
            raise RecordingError("declared_as needs a canonical recording; call to_canonical() first")
        C = Z_UP_TO_Y_UP.numpy().astype(np.float64)
        g = np.asarray(GRAVITY, dtype=np.float64)
        out = []
        for s in self.sensors:
            ch = {k: (None if v is None else v.astype(np.float64)) for k, v in s.channels().items()}
            new: dict[str, str] = {}
            R, acc, pos = ch.get("orientation"), ch.get("acceleration"), ch.get("position")
            # Steps of to_canonical undone in reverse order: gravity, up axis, acceleration frame, units.
            if acc is not None:
                if acc_gravity == "included":
                    acc = acc - g
                new.update(acc_gravity=acc_gravity, acc_unit=acc_unit, acc_frame=acc_frame)
            if world_up == "z_up":
                R = None if R is None else C.T @ R
                pos = None if pos is None else pos @ C
                acc = None if acc is None else acc @ C
                new["world_up"] = world_up
            if acc is not None:
                if acc_frame == "sensor":
                    if R is None:
                        raise RecordingError(f"sensor {s.info.name!r}: sensor-frame acceleration needs an "
                                             "'orientation' channel to rotate with")
                    acc = np.einsum("nji,nj->ni", R, acc)  # a_S = R_WS^T a_W
                ch["acceleration"] = acc / G if acc_unit == "g" else acc
            if pos is not None:
                ch["position"] = pos / _POSITION_SCALE[position_unit]
                new["position_unit"] = position_unit
            if ch.get("angular_velocity") is not None:
                if gyro_unit == "deg/s":
                    ch["angular_velocity"] = np.rad2deg(ch["angular_velocity"])
                new["gyro_unit"] = gyro_unit
            if R is not None:
                ch["orientation"] = R
            ch = {k: v.astype(getattr(s, k).dtype) for k, v in ch.items() if v is not None}
            out.append(SensorStream(replace(s.info, **new), s.timestamps.copy(), s.valid.copy(), **ch))
        return Recording(out, self.ground_truth, self.ground_truth_start, copy.deepcopy(self.subject),
                         copy.deepcopy(self.meta), self.origin)

    # ------------------------------------------------------------------ stacking
    def on_common_grid(self, names: Iterable[str] | None = None) -> CommonGrid:
        """Stack sensors into ``(T, S, ...)`` arrays when they share one time grid.

        Args:
            names: sensors to stack (default: all, in recording order).

        Raises:
            RecordingError: naming every sensor whose timestamps differ from the first sensor's
                (count or values beyond :data:`GRID_TOLERANCE_S`). Nothing is resampled: a
                different grid means the caller must decide how to align (and say so).
        """
        streams = [self.sensor(n) for n in names] if names is not None else list(self.sensors)
        if not streams:
            raise RecordingError("on_common_grid: no sensors selected")
        ref = streams[0]
        differ = []
        for s in streams[1:]:
            if s.num_frames != ref.num_frames:
                differ.append(f"{s.name} ({s.num_frames} frames vs {ref.num_frames})")
            elif np.max(np.abs(s.timestamps - ref.timestamps)) > GRID_TOLERANCE_S:
                k = int(np.argmax(np.abs(s.timestamps - ref.timestamps)))
                differ.append(f"{s.name} (frame {k}: t={s.timestamps[k]!r} vs {ref.timestamps[k]!r})")
        if differ:
            raise RecordingError(
                f"sensors do not share {ref.name!r}'s timestamps: {', '.join(differ)}. wearpose never resamples "
                "silently; resample/align them explicitly or stack a subset that shares a grid")
        T, S = ref.num_frames, len(streams)
        valid = np.stack([s.valid for s in streams], axis=1)
        chans: dict[str, np.ndarray] = {}
        has: dict[str, np.ndarray] = {}
        for c in CHANNELS:
            present = np.array([getattr(s, c) is not None for s in streams])
            if not present.any():
                continue
            dtype = np.result_type(*[getattr(s, c).dtype for s in streams if getattr(s, c) is not None])
            arr = np.full((T, S) + CHANNEL_SHAPES[c], np.nan, dtype=dtype)
            for j, s in enumerate(streams):
                if present[j]:
                    arr[:, j] = getattr(s, c)
            chans[c], has[c] = arr, present
        return CommonGrid(ref.timestamps.copy(), tuple(s.name for s in streams), valid, valid.all(axis=1), chans, has)

    # ------------------------------------------------------------------ files
    def save(self, path: Any) -> Any:
        """Write the versioned ``.npz`` format atomically; see :func:`save_recording`."""
        # cycle: wearpose.recording.fileformat imports wearpose.recording.types
        from wearpose.recording.fileformat import save_recording

        return save_recording(self, path)


def canonical_arrays(info: SensorInfo, ch: dict[str, np.ndarray]) -> tuple[dict[str, str], dict[str, np.ndarray]]:
    """The conversion of :meth:`Recording.to_canonical` for one sensor's channel arrays.

    Args:
        info: the sensor's declared conventions.
        ch: channel -> float64 array ``(N, ...)`` (``orientation`` ``(N, 3, 3)``) as declared.

    Returns:
        ``(fields, channels)``: the :class:`SensorInfo` fields that change (for ``replace``) and
        the converted arrays (steps in :meth:`Recording.to_canonical`). Live device frames use
        this too (``wearpose.stream.inputs.canonical_frame``), so a frame and a file convert alike.
    """
    ch = dict(ch)
    C = Z_UP_TO_Y_UP.numpy()
    g = np.asarray(GRAVITY)
    new = {"position_unit": "m", "gyro_unit": "rad/s", "acc_unit": "m/s2", "world_up": "y_up"}
    if ch.get("position") is not None:
        ch["position"] = ch["position"] * _POSITION_SCALE[info.position_unit]
    if ch.get("angular_velocity") is not None and info.gyro_unit == "deg/s":
        ch["angular_velocity"] = np.deg2rad(ch["angular_velocity"])
    acc, R = ch.get("acceleration"), ch.get("orientation")
    acc_frame, acc_gravity = info.acc_frame, info.acc_gravity
    if acc is not None:
        if info.acc_unit == "g":
            acc = acc * G
        if acc_frame == "sensor" and R is not None:
            acc = np.einsum("nij,nj->ni", R, acc)
            acc_frame = "world"
    if info.world_up == "z_up":
        if R is not None:
            R = C @ R
        if ch.get("position") is not None:
            ch["position"] = ch["position"] @ C.T
        if acc is not None and acc_frame == "world":
            acc = acc @ C.T
    if acc is not None and acc_gravity == "included" and acc_frame == "world":
        acc = acc + g
        acc_gravity = "removed"
    if acc is not None:
        ch["acceleration"] = acc
    if R is not None:
        ch["orientation"] = R
    new.update(acc_frame=acc_frame, acc_gravity=acc_gravity)
    return new, ch
