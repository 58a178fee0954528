"""The versioned recording file: one ``.npz`` (zip of ``.npy`` arrays), documented in
``docs/formats.md``.

Why one ``.npz`` and not a directory: a recording moves around as one file (upload, attach,
``mv`` atomically), numpy alone writes it (``np.savez``) so any device script can produce one
without wearpose, it loads with ``allow_pickle=False`` (no code execution), and every array keeps
its exact dtype and shape. The JSON header lives inside as a 0-d string array.

Keys:

- ``format``: str ``"wearpose.recording"``; ``version``: int (this reader: 1).
- ``header``: str, JSON object ``{"sensors": [SensorInfo...], "subject": {...}, "meta": {...},
  "ground_truth": {"start": s, "fps": Hz, "meta": {...}} | null}``.
- ``sensors/<name>/timestamps`` ``(N,)`` float64 s; ``sensors/<name>/valid`` ``(N,)`` bool;
  ``sensors/<name>/<channel>`` for each channel (``orientation`` as ``(N, 4)`` (w, x, y, z)
  quaternions, or ``(N, 3, 3)`` matrices).
- ``ground_truth/pose_aa`` ``(T, 24, 3)`` axis-angle rad, ``ground_truth/betas`` ``(10,)``,
  ``ground_truth/trans`` ``(T, 3)`` m -- only when the header's ``ground_truth`` is not null.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import torch

from wearpose.fileio import NPZ_READ_ERRORS, atomic_savez, npz_declared_size_problem, npz_problem
from wearpose.errors import InputFileError, ShapeError
from wearpose.geometry import axis_angle_to_matrix, matrix_to_axis_angle, matrix_to_quat
from wearpose.recording.checks import check_recording
from wearpose.recording.types import (
    CHANNEL_SHAPES,
    CHANNELS,
    Recording,
    SensorInfo,
    SensorStream,
    _normalise_stream,
    _Problem,
    quaternions_to_matrices,
)

FORMAT_NAME = "wearpose.recording"
FORMAT_VERSION = 1
_EXPECTED_FILE = f"a {FORMAT_NAME} .npz (version {FORMAT_VERSION}) as documented in docs/formats.md"
_GT_KEYS = ("pose_aa", "betas", "trans")


def _quats(R: np.ndarray, valid: np.ndarray) -> np.ndarray:
    q = np.full((R.shape[0], 4), np.nan, dtype=np.float32 if R.dtype == np.float32 else np.float64)
    if valid.any():
        q[valid] = matrix_to_quat(torch.from_numpy(R[valid].astype(np.float64))).numpy()
    return q


def recording_arrays(rec: Recording) -> dict[str, np.ndarray]:
    """The exact ``name -> array`` mapping :func:`save_recording` writes (useful for streaming
    writers and for tests)."""
    gt = rec.ground_truth
    header: dict[str, Any] = {
        "sensors": [s.info.to_json() for s in rec.sensors],
        "subject": rec.subject,
        "meta": rec.meta,
        "ground_truth": None if gt is None else {"start": rec.ground_truth_start, "fps": float(gt.fps), "meta": gt.meta},
    }
    arrays: dict[str, np.ndarray] = {
        "format": np.array(FORMAT_NAME),
        "version": np.array(FORMAT_VERSION, dtype=np.int64),
        "header": np.array(json.dumps(header, sort_keys=True, default=_json_default)),
    }
    for s in rec.sensors:
        base = f"sensors/{s.name}"
        arrays[f"{base}/timestamps"] = s.timestamps.astype(np.float64)
        arrays[f"{base}/valid"] = s.valid.astype(bool)
        for c, v in s.channels().items():
            # Quaternions in files (DESIGN.md): 4 numbers per frame instead of 9, exact enough.
            arrays[f"{base}/{c}"] = _quats(v, s.valid) if c == "orientation" else v
    if gt is not None:
        arrays["ground_truth/pose_aa"] = matrix_to_axis_angle(gt.pose.detach().to(torch.float64)).to(torch.float32).numpy()
        arrays["ground_truth/betas"] = gt.betas.detach().to(torch.float32).numpy()
        arrays["ground_truth/trans"] = gt.trans.detach().to(torch.float32).numpy()
    return arrays


def _json_default(o: Any) -> Any:
    # numpy scalars/arrays in subject/meta (e.g. EM-POSE offsets) become plain JSON.
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, torch.Tensor):
        return o.tolist()
    return str(o)


def save_recording(rec: Recording, path: str | Path) -> Path:
    """Write ``rec`` to ``path`` (``.npz``) atomically: a temporary file in the same directory
    is renamed into place, so readers never see a half-written recording.

    Returns:
        the path written.
    """
    return atomic_savez(path, recording_arrays(rec))


def load_recording(path: str | Path, check_conventions: bool = True) -> Recording:
    """Read and validate a recording file.

    Every problem raises :class:`wearpose.errors.InputFileError` naming the file, the field
    (e.g. ``sensors/left_wrist/acceleration``), the problem and the expected form: missing or
    unreadable file, unknown format or newer version, malformed header, unknown kind or key,
    missing/extra arrays, wrong shape or dtype, truncated arrays (length differs from the
    timestamps), NaN/inf in a valid frame, non-increasing timestamps, orientations that are not
    rotations, unknown body sites, and (``check_conventions``) data that does not look like its
    declared units and conventions (:mod:`wearpose.recording.checks`: timestamps, positions,
    acceleration, gyro unit, quaternion order). No other exception type escapes.

    Returns:
        the :class:`Recording`, exactly as stored (declared conventions kept: call
        :meth:`Recording.to_canonical` to convert).
    """
    path = Path(path)
    try:
        return _load(path, check_conventions)
    except InputFileError:
        raise
    except _Problem as p:
        raise InputFileError(path, p.problem, p.expected, field=p.field) from None
    except Exception as exc:  # noqa: BLE001 - the documented contract: only InputFileError escapes
        # Safety net for malformed content no specific check anticipated (found by the fuzz test).
        raise InputFileError(path, f"malformed content ({type(exc).__name__}: {exc})", _EXPECTED_FILE) from exc


def _load(path: Path, check_conventions: bool) -> Recording:
    if not path.exists():
        raise InputFileError(path, "file not found", _EXPECTED_FILE)
    if not path.is_file():
        raise InputFileError(path, "not a regular file", _EXPECTED_FILE)
    try:
        forged = npz_declared_size_problem(path)
        if forged is not None:
            raise InputFileError(path, forged[1], "arrays of the size their headers declare (" + _EXPECTED_FILE + ")",
                                 field=forged[0])
        with np.load(path, allow_pickle=False) as npz:
            names = list(npz.files)
            d: dict[str, np.ndarray] = {}
            for k in names:
                d[k] = npz[k]
    except InputFileError:
        raise
    except NPZ_READ_ERRORS as exc:
        raise InputFileError(path, npz_problem(path, exc), _EXPECTED_FILE) from exc

    def need(key: str, expected: str) -> np.ndarray:
        if key not in d:
            raise InputFileError(path, "missing key", expected, field=key)
        return d[key]

    fmt = need("format", f"the string {FORMAT_NAME!r}")
    if fmt.shape != () or fmt.dtype.kind != "U" or str(fmt) != FORMAT_NAME:
        raise InputFileError(path, f"format is {_short(fmt)}", f"the string {FORMAT_NAME!r}", field="format")
    ver = need("version", "an integer format version")
    if ver.shape != () or ver.dtype.kind not in "iu":
        raise InputFileError(path, f"version is {_short(ver)}", f"the integer {FORMAT_VERSION}", field="version")
    version = int(ver)
    if version > FORMAT_VERSION:
        raise InputFileError(path, f"format version {version} is newer than this wearpose supports",
                             f"version <= {FORMAT_VERSION}; upgrade wearpose to read it", field="version")
    if version < 1:
        raise InputFileError(path, f"unknown format version {version}", f"version {FORMAT_VERSION}", field="version")
    hdr = need("header", "a JSON object string")
    if hdr.shape != () or hdr.dtype.kind != "U":
        raise InputFileError(path, f"header is {_short(hdr)}", "a JSON object string (0-d str array)", field="header")
    try:
        header = json.loads(str(hdr))
    except ValueError as exc:
        raise InputFileError(path, f"invalid JSON ({exc})", "a JSON object string", field="header") from None
    except RecursionError:
        # json.loads recurses per nesting level: ~1000 nested brackets exceed Python's stack.
        raise InputFileError(path, "JSON nested too deeply to read", "a JSON object of sensor infos, subject and meta "
                             "(a few levels deep)", field="header") from None
    if not isinstance(header, dict):
        raise InputFileError(path, f"header is a JSON {type(header).__name__}", "a JSON object", field="header")
    known_header = {"sensors", "subject", "meta", "ground_truth"}
    if set(header) - known_header:
        raise InputFileError(path, f"unknown key(s) {sorted(set(header) - known_header)}", f"only {sorted(known_header)}", field="header")
    sensors_json = header.get("sensors")
    if not isinstance(sensors_json, list) or not sensors_json:
        raise InputFileError(path, "no sensor list", "a non-empty JSON list of sensor infos", field="header/sensors")
    for key in ("subject", "meta"):
        if not isinstance(header.get(key, {}), dict):
            raise InputFileError(path, f"{key} is not an object", "a JSON object", field=f"header/{key}")
    infos = [SensorInfo.from_json(x) for x in sensors_json]
    seen: set[str] = set()
    for info in infos:
        if info.name in seen:
            raise InputFileError(path, f"sensor name {info.name!r} appears twice", "unique sensor names", field=f"sensors/{info.name}")
        seen.add(info.name)

    # Every array must belong to something we know: a stray key is usually a typo ("accel").
    gt_json = header.get("ground_truth")
    allowed = {"format", "version", "header"}
    for info in infos:
        allowed |= {f"sensors/{info.name}/{f}" for f in ("timestamps", "valid") + CHANNELS}
    if gt_json is not None:
        allowed |= {f"ground_truth/{k}" for k in _GT_KEYS}
    for k in d:
        if k not in allowed:
            parts = k.split("/")
            if len(parts) == 3 and parts[0] == "sensors" and parts[1] in seen:
                raise InputFileError(path, f"unknown field {parts[2]!r}", f"one of timestamps, valid, {', '.join(CHANNELS)}", field=k)
            if len(parts) >= 2 and parts[0] == "sensors":
                raise InputFileError(path, f"array for sensor {parts[1]!r} which the header does not list", "every sensor declared in header/sensors", field=k)
            raise InputFileError(path, "unknown key", "format, version, header, sensors/<name>/<field>, ground_truth/<field>", field=k)

    streams = []
    for info in infos:
        base = f"sensors/{info.name}"
        ts = need(f"{base}/timestamps", "(N,) float64 seconds, strictly increasing")
        if ts.ndim != 1 or ts.dtype.kind not in "fiu":
            raise InputFileError(path, f"shape {ts.shape} dtype {ts.dtype}", "(N,) float64 seconds", field=f"{base}/timestamps")
        n = ts.shape[0]
        valid = need(f"{base}/valid", f"({n},) bool")
        if valid.dtype.kind not in "biu" or (valid.dtype.kind != "b" and not np.all((valid == 0) | (valid == 1))):
            raise InputFileError(path, f"dtype {valid.dtype}", f"({n},) bool (or integers 0/1)", field=f"{base}/valid")
        if valid.ndim != 1 or valid.shape[0] != n:
            _check_lengths(path, base, ts, f"{base}/valid", valid)
            raise InputFileError(path, f"shape {valid.shape}", f"({n},) bool", field=f"{base}/valid")
        vmask = valid.astype(bool)
        ch: dict[str, np.ndarray] = {}
        for c in CHANNELS:
            key = f"{base}/{c}"
            if key not in d:
                continue
            arr = d[key]
            if arr.dtype.kind not in "fiu":
                raise InputFileError(path, f"dtype {arr.dtype}", "a floating-point array", field=key)
            if arr.ndim == 0:
                raise InputFileError(path, "a scalar", f"an (N, ...) array with N = {n}", field=key)
            _check_lengths(path, base, ts, key, arr)
            if c == "orientation":
                if arr.ndim == 2 and arr.shape[1] == 4:
                    arr = quaternions_to_matrices(arr, key, vmask)
                elif tuple(arr.shape[1:]) != (3, 3):
                    raise InputFileError(path, f"shape {arr.shape}", "(N, 4) unit quaternions (w, x, y, z) or (N, 3, 3) rotation matrices", field=key)
            elif tuple(arr.shape[1:]) != CHANNEL_SHAPES[c]:
                raise InputFileError(path, f"shape {arr.shape}", f"(N, {', '.join(map(str, CHANNEL_SHAPES[c]))})", field=key)
            ch[c] = arr
        stream = object.__new__(SensorStream)
        stream.info, stream.timestamps, stream.valid = info, ts, vmask
        for c in CHANNELS:
            setattr(stream, c, ch.get(c))
        # The same validation as the in-memory constructor; its problems carry file-style fields.
        _normalise_stream(stream)
        streams.append(stream)

    gt, gt_start = None, 0.0
    if gt_json is not None:
        gt, gt_start = _load_ground_truth(path, d, gt_json)
    rec = Recording(streams, gt, gt_start, header.get("subject", {}) or {}, header.get("meta", {}) or {}, str(path))
    if check_conventions:
        issues = check_recording(rec.sensors)
        if issues:
            # Report every suspicion about the first field at once (e.g. "looks like g" and
            # "looks like the sensor frame"): fixing one at a time would take several runs.
            first = issues[0]
            same = [i for i in issues if (i.sensor, i.field) == (first.sensor, first.field)]
            raise InputFileError(path, "; ".join(i.problem for i in same), "; ".join(i.expected for i in same),
                                 field=f"sensors/{first.sensor}/{first.field}")
    return rec


def _check_lengths(path: Path, base: str, ts: np.ndarray, key: str, arr: np.ndarray) -> None:
    n = ts.shape[0]
    if arr.ndim >= 1 and arr.shape[0] != n:
        problem = f"only {arr.shape[0]} frames for {n} timestamps (truncated?)" if arr.shape[0] < n else f"{arr.shape[0]} frames for {n} timestamps"
        raise InputFileError(path, problem, f"{n} frames, one per timestamp in {base}/timestamps", field=key)


def _short(a: np.ndarray) -> str:
    # Small in every dimension, not only in size: shape (2**31, 0) holds nothing, but .tolist()
    # would build 2**31 empty lists (MemoryError; found by the fuzz test).
    s = repr(a.tolist()) if a.size <= 4 and all(n <= 4 for n in a.shape) else f"array of shape {a.shape}"
    return f"{s[:60]} (dtype {a.dtype})"


def _load_ground_truth(path: Path, d: dict[str, np.ndarray], gt_json: Any) -> tuple[Any, float]:
    # start-up: wearpose.motion adds ~80 ms to import wearpose.recording
    from wearpose.motion.sequence import MotionSequence

    if not isinstance(gt_json, dict) or set(gt_json) - {"start", "fps", "meta"}:
        raise InputFileError(path, f"value {str(gt_json)[:80]}", 'null or {"start": seconds, "fps": Hz, "meta": {...}}', field="header/ground_truth")
    fps, start, meta = gt_json.get("fps"), gt_json.get("start", 0.0), gt_json.get("meta", {})
    if isinstance(fps, bool) or not isinstance(fps, (int, float)) or not math.isfinite(fps) or fps <= 0:
        raise InputFileError(path, f"fps {fps!r}", "a positive number (Hz)", field="header/ground_truth/fps")
    if isinstance(start, bool) or not isinstance(start, (int, float)) or not math.isfinite(start):
        raise InputFileError(path, f"start {start!r}", "seconds on the sensors' clock", field="header/ground_truth/start")
    if not isinstance(meta, dict):
        raise InputFileError(path, "meta is not an object", "a JSON object", field="header/ground_truth/meta")
    arrs = {}
    for k, exp in zip(_GT_KEYS, ("(T, 24, 3) float axis-angle, radians", "(10,) float SMPL betas", "(T, 3) float metres")):
        key = f"ground_truth/{k}"
        if key not in d:
            raise InputFileError(path, "missing key (header declares ground truth)", exp, field=key)
        a = d[key]
        if a.dtype.kind not in "fiu":
            raise InputFileError(path, f"dtype {a.dtype}", exp, field=key)
        if not np.all(np.isfinite(a)):
            raise InputFileError(path, "contains NaN or infinite values", exp, field=key)
        arrs[k] = a.astype(np.float64)
    aa, betas, trans = arrs["pose_aa"], arrs["betas"], arrs["trans"]
    if aa.ndim != 3 or aa.shape[1:] != (24, 3) or aa.shape[0] == 0:
        raise InputFileError(path, f"shape {aa.shape}", "(T, 24, 3) float axis-angle, radians", field="ground_truth/pose_aa")
    if trans.shape != (aa.shape[0], 3):
        problem = f"shape {trans.shape} for {aa.shape[0]} pose frames" + (" (truncated?)" if trans.ndim == 2 and trans.shape[0] < aa.shape[0] else "")
        raise InputFileError(path, problem, "(T, 3) float metres, one row per pose frame", field="ground_truth/trans")
    if betas.shape != (10,):
        raise InputFileError(path, f"shape {betas.shape}", "(10,) float SMPL betas", field="ground_truth/betas")

    try:
        pose = axis_angle_to_matrix(torch.from_numpy(aa)).to(torch.float32)
        seq = MotionSequence(pose, torch.from_numpy(betas).float(), torch.from_numpy(trans).float(), float(fps), meta)
    except ShapeError as exc:
        raise InputFileError(path, str(exc), "a valid SMPL-24 motion", field="ground_truth") from None
    return seq, float(start)
