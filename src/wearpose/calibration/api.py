"""``calibrate(recording, method=...)``: run a calibration on a :class:`wearpose.recording.Recording`.

The recording-level entry the CLI (``wearpose calibrate``) calls. Each method reads what it needs
from the recording, runs the tensor-level procedure of its module, and returns a
:class:`CalibrationResult`; :func:`store_calibration` puts it in ``recording.meta["calibration"]``
(JSON, saved with the recording) and :func:`apply_calibration` turns a ``tpose``/``ipose``
calibration into a recording of bone orientations.
"""

from __future__ import annotations

import copy
from dataclasses import replace
from typing import Any, Sequence

import numpy as np
import torch

from wearpose.body import BodyModel
from wearpose.calibration._common import F64, G_VEC, CalibrationError, chordal_mean, t64, window_mask
from wearpose.calibration.empose import empose_offsets
from wearpose.calibration.handeye import solve_axyb
from wearpose.calibration.miposer import em_to_world, miposer_tpose
from wearpose.calibration.result import METHODS, CalibrationResult
from wearpose.calibration.segment import bone_orientations, heading_reset, segment_calibration

#: Timestamps closer than this (s) are "the same instant" when pairing streams.
PAIR_TOLERANCE = 1e-6


def _body(body: Any) -> Any:
    if body is not None:
        return body

    return BodyModel(dtype=torch.float64)


def _pick(recording: Any, sensors: Sequence[str] | None, kinds: tuple[str, ...], need: str, method: str) -> list[Any]:
    if sensors is not None:
        streams = [recording.sensor(n) for n in sensors]
    else:
        streams = [s for s in recording.sensors if s.kind in kinds]
    if not streams:
        raise CalibrationError(f"calibrate({method}): the recording has no {'/'.join(kinds)} sensor; it has {list(recording.names)}")
    missing = [s.name for s in streams if getattr(s, need) is None]
    if missing:
        raise CalibrationError(f"calibrate({method}): sensor(s) {missing} have no {need!r} channel")
    return streams


def _window_stack(streams: list[Any], window: tuple[float, float], channel: str, method: str) -> tuple[torch.Tensor, torch.Tensor]:
    """``(N, S, ...)`` values and ``(N, S)`` validity of ``channel`` inside ``window``; streams must share timestamps there."""
    masks = [window_mask(s.timestamps, window, f"calibrate({method}) sensor {s.name!r}") for s in streams]
    ref = streams[0].timestamps[masks[0]]
    for s, m in zip(streams[1:], masks[1:]):
        ts = s.timestamps[m]
        if ts.shape != ref.shape or np.max(np.abs(ts - ref)) > PAIR_TOLERANCE:
            raise CalibrationError(f"calibrate({method}): sensor {s.name!r} does not share {streams[0].name!r}'s timestamps in the "
                                   "calibration window; resample them to one grid first")
    vals = torch.stack([t64(getattr(s, channel)[m]) for s, m in zip(streams, masks)], 1)
    valid = torch.stack([torch.from_numpy(s.valid[m].copy()) for s, m in zip(streams, masks)], 1)
    return vals, valid


def _mean_pose(stream: Any, window: tuple[float, float], method: str) -> tuple[torch.Tensor, torch.Tensor]:
    m = window_mask(stream.timestamps, window, f"calibrate({method}) sensor {stream.name!r}") & stream.valid
    if not m.any():
        raise CalibrationError(f"calibrate({method}): sensor {stream.name!r} has no valid frame in the window {window}")
    return chordal_mean(t64(stream.orientation[m])), t64(stream.position[m]).mean(0)


def calibrate(recording: Any, method: str, *, body: Any = None, window: tuple[float, float] = (0.0, 1.0),
              sensors: Sequence[str] | None = None, **kwargs: Any) -> CalibrationResult:
    """Run calibration ``method`` on ``recording``.

    Args:
        recording: a :class:`wearpose.recording.Recording` (converted to canonical form first).
        method: ``"empose-offsets"`` (EM sensors + ``recording.ground_truth``: the reference poses
            of a calibration sequence; the whole sequence is used unless ``window`` is given
            explicitly via ``kwargs['use_window']=True``), ``"tpose"`` / ``"ipose"`` (IMU/MIMU
            orientations, static pose in ``window``), ``"miposer-tpose"`` (a ``vio`` headset and
            1-2 wrist EM sensors, T-pose in ``window``), ``"hand-eye"`` (``sensors=(a, b)``: two
            6-DoF streams rigidly linked, ``A_i X = Y B_i`` over their common timestamps).
        body: :class:`wearpose.body.BodyModel` (default: the embedded asset, float64).
        window: ``(start_s, stop_s)`` of the static calibration pose on the sensors' clock.
        sensors: sensor names to use (default: every sensor of the kinds the method needs).
        **kwargs: passed to the method's function (e.g. ``heading=``, ``normal_axis=``,
            ``betas=``, ``sigma_rotation=``; for ``tpose``/``ipose`` also ``resets=[(t0, t1), ...]``
            heading-reset events with ``facing=`` and ``interpolation=``).

    Returns:
        :class:`CalibrationResult` (``params["window"]`` records the window).
    """
    if method not in METHODS:
        raise CalibrationError(f"calibrate: unknown method {method!r}; expected one of {list(METHODS)}")
    rec = recording.to_canonical()
    window = (float(window[0]), float(window[1]))
    if method == "empose-offsets":
        return _empose(rec, _body(body), sensors, window if kwargs.pop("use_window", False) else None, **kwargs)
    if method in ("tpose", "ipose"):
        body = _body(body)
        resets = kwargs.pop("resets", None)
        reset_kw = {k: kwargs.pop(k) for k in ("facing", "interpolation", "reference_sensor_reset") if k in kwargs}
        streams = _pick(rec, sensors, ("imu", "mimu"), "orientation", method)
        R, valid = _window_stack(streams, window, "orientation", method)
        acc = None
        if all(s.acceleration is not None and s.info.acc_frame == "world" for s in streams):
            acc, _ = _window_stack(streams, window, "acceleration", method)
        sites = [s.info.site for s in streams]
        if any(x is None for x in sites):
            raise CalibrationError(f"calibrate({method}): sensor(s) {[s.name for s in streams if s.info.site is None]} have no site")
        res = segment_calibration(R, sites, body, acc=acc, valid=valid, names=[s.name for s in streams], pose=method, **kwargs)
        res.params["window"] = list(window)
        if resets:
            ts = streams[0].timestamps
            Rall = torch.stack([t64(s.orientation) for s in streams], 1)
            vall = torch.stack([torch.from_numpy(s.valid.copy()) for s in streams], 1)
            if "reference_sensor_reset" in reset_kw:
                reset_kw["reference_sensor"] = reset_kw.pop("reference_sensor_reset")
            res = heading_reset(Rall, ts, res, resets, body, valid=vall, betas=kwargs.get("betas"), **reset_kw)
        return res
    if method == "miposer-tpose":
        body = _body(body)
        vio = [s for s in rec.sensors if s.kind == "vio"]
        if len(vio) != 1:
            raise CalibrationError(f"calibrate(miposer-tpose): expected exactly one 'vio' headset sensor, found {[s.name for s in vio]}")
        wr = _pick(rec, sensors, ("em6dof",), "position", method)
        hR, hp = _mean_pose(vio[0], window, method)
        wRs, wps, targets = [], [], []
        for s in wr:
            eR, ep = _mean_pose(s, window, method)
            R, p = (em_to_world(hR, hp, eR, ep, kwargs.get("source_R"), kwargs.get("source_t"))
                    if s.info.reference == "source" else (eR, ep))
            wRs.append(R)
            wps.append(p)
            site = s.info.site or ""
            targets.append("left_wrist" if "left" in site else "right_wrist" if "right" in site else site)
        order = sorted(range(len(wr)), key=lambda i: 0 if targets[i] == "left_wrist" else 1)
        kw = {k: v for k, v in kwargs.items() if k not in ("source_R", "source_t")}
        res = miposer_tpose(hR[None], hp[None], torch.stack([wRs[i] for i in order])[None], torch.stack([wps[i] for i in order])[None],
                            body, wrists=[targets[i] for i in order], names=[vio[0].name, *[wr[i].name for i in order]],
                            wrist_sites=[wr[i].info.site for i in order], **kw)
        res.params["window"] = list(window)
        return res
    # hand-eye
    if sensors is None or len(sensors) != 2:
        raise CalibrationError("calibrate(hand-eye): give sensors=(a, b): the reference tracker stream A and the sensor stream B")
    a, b = rec.sensor(sensors[0]), rec.sensor(sensors[1])
    for s in (a, b):
        if s.position is None or s.orientation is None:
            raise CalibrationError(f"calibrate(hand-eye): sensor {s.name!r} needs position and orientation (a 6-DoF stream)")
    ia, ib = _pair(a.timestamps, b.timestamps)
    keep = a.valid[ia] & b.valid[ib]
    ia, ib = ia[keep], ib[keep]
    A = (t64(a.orientation[ia]), t64(a.position[ia]))
    B = (t64(b.orientation[ib]), t64(b.position[ib]))
    res = solve_axyb(A, B, name=b.name, **kwargs)
    res.params.update(a=a.name, b=b.name)
    return res


def _pair(ta: np.ndarray, tb: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Indices of frames of two streams at the same instant (within :data:`PAIR_TOLERANCE`)."""
    j = np.clip(np.searchsorted(tb, ta), 1, len(tb) - 1) if len(tb) > 1 else np.zeros(len(ta), int)
    j = np.where(np.abs(tb[j - 1] - ta) < np.abs(tb[j] - ta), j - 1, j) if len(tb) > 1 else j
    ok = np.abs(tb[j] - ta) <= PAIR_TOLERANCE
    if not ok.any():
        raise CalibrationError("calibrate(hand-eye): the two streams share no timestamp; record them on one clock (or resample one)")
    return np.flatnonzero(ok), j[ok]


def _empose(rec: Any, body: Any, sensors: Sequence[str] | None, window: tuple[float, float] | None, **kwargs: Any) -> CalibrationResult:
    # start-up: wearpose.motion.resample adds ~60 ms to import wearpose.calibration
    from wearpose.motion.resample import resample

    gt = rec.ground_truth
    if gt is None:
        raise CalibrationError("calibrate(empose-offsets): the recording has no ground_truth; the calibration sequence's reference "
                               "poses (MotionSequence with the subject's betas) are required")
    streams = _pick(rec, sensors, ("em6dof",), "position", "empose-offsets")
    rate = float(streams[0].info.rate)
    ts = streams[0].timestamps
    for s in streams[1:]:
        if s.timestamps.shape != ts.shape or np.max(np.abs(s.timestamps - ts)) > PAIR_TOLERANCE:
            raise CalibrationError(f"calibrate(empose-offsets): EM sensor {s.name!r} is not on {streams[0].name!r}'s time grid")
    m = resample(gt, rate) if abs(gt.fps - rate) > 1e-9 else gt
    idx = np.rint((ts - rec.ground_truth_start) * rate).astype(np.int64)
    ok = (idx >= 0) & (idx < m.num_frames) & (np.abs(idx / rate + rec.ground_truth_start - ts) < 0.25 / rate)
    if window is not None:
        ok &= window_mask(ts, window, "calibrate(empose-offsets)")
    if ok.sum() < 2:
        raise CalibrationError("calibrate(empose-offsets): fewer than 2 sensor frames overlap the ground truth in time")
    sel = np.flatnonzero(ok)
    # start-up: wearpose.motion.sequence adds ~70 ms to import wearpose.calibration
    from wearpose.motion.sequence import MotionSequence

    mm = MotionSequence(m.pose[idx[sel]].to(F64), m.betas.to(F64), m.trans[idx[sel]].to(F64), rate, {})
    R = torch.stack([t64(s.orientation[sel]) for s in streams], 1)
    p = torch.stack([t64(s.position[sel]) for s in streams], 1)
    v = torch.stack([torch.from_numpy(s.valid[sel].copy()) for s in streams], 1)
    srcs = {s.info.source_site for s in streams if s.info.reference == "source"}
    if len(srcs) > 1:
        raise CalibrationError(f"calibrate(empose-offsets): EM sensors name different source sites {sorted(map(str, srcs))}")
    src = srcs.pop() if srcs else None
    if any(s.info.reference == "source" for s in streams) and src is None:
        raise CalibrationError("calibrate(empose-offsets): EM sensors are relative to the source but SensorInfo.source_site is not set")
    if src is not None and src not in body.site_names:
        raise CalibrationError(f"calibrate(empose-offsets): source site {src!r} is not a site of body asset {body.asset_id!r} "
                               f"(sites: {list(body.site_names)})")
    sites = [s.info.site for s in streams]
    unknown = [f"{s.name} ({s.info.site!r})" for s in streams if s.info.site not in body.site_names]
    if unknown:
        raise CalibrationError(f"calibrate(empose-offsets): sensor(s) {unknown} have no site of body asset {body.asset_id!r}; "
                               f"set SensorInfo.site to one of {list(body.site_names)}")
    res = empose_offsets(R, p, mm, body, sites, source_site=src, valid=v, names=[s.name for s in streams], **kwargs)
    if window is not None:
        res.params["window"] = list(window)
    return res


def store_calibration(recording: Any, result: CalibrationResult, *, subject_offsets: bool = True) -> Any:
    """A copy of ``recording`` with ``meta["calibration"] = result.to_dict()`` (saved with the file).

    An ``empose-offsets`` result is also written to ``subject["offsets"]`` (unless
    ``subject_offsets=False``), the place the EM-POSE estimator and the converters use for a
    subject's offsets; the previous value, if any, is kept under ``subject["offsets_previous"]``.
    """
    meta = copy.deepcopy(recording.meta)
    meta["calibration"] = result.to_dict()
    subject = copy.deepcopy(recording.subject)
    if result.method == "empose-offsets" and subject_offsets:
        if "offsets" in subject:
            subject["offsets_previous"] = subject["offsets"]
        subject["offsets"] = result.to_subject_offsets()
    return replace(recording, meta=meta, subject=subject)


def apply_calibration(recording: Any, result: CalibrationResult) -> Any:
    """Apply a ``tpose``/``ipose`` calibration: a recording of *bone* orientations in wearpose's world.

    Per calibrated sensor: ``orientation`` -> ``R^{WB}`` (BiRAE Eq. 2a-2b, with any heading
    reset), free ``acceleration`` -> ``R^{WM} (a - g) + g`` (the device's gravity model replaced
    by the true one, so a tilted sensor world no longer leaks gravity), ``angular_velocity`` ->
    bone frame ``R^{BS} w``. The sensor frame of the result *is* the bone frame, as TransPose/PIP
    synthesise it (``simulate(..., imu_orientation="segment")``); ``meta["calibration"]`` holds
    the result and ``meta["orientation_frame"] = "segment"``.
    """
    if result.method not in ("tpose", "ipose"):
        raise CalibrationError(f"apply_calibration: only tpose/ipose calibrations change the data; got {result.method!r} "
                               "(store it with store_calibration)")
    # start-up: wearpose.recording adds ~70 ms to import wearpose.calibration
    from wearpose.recording import SensorStream

    rec = recording.to_canonical()
    out = []
    for s in rec.sensors:
        if s.name not in result.sensors:
            out.append(s)
            continue
        j = result.index(s.name)
        ch: dict[str, Any] = {}
        if s.orientation is not None:
            sub = CalibrationResult(result.method, (s.name,), rotation=result.rotation[j:j + 1],
                                    world_rotation=result.world_rotation[j:j + 1],
                                    extras={k: (v[:, j:j + 1] if v.dim() == 2 else v) for k, v in result.extras.items()},
                                    params=result.params)
            ch["orientation"] = bone_orientations(t64(s.orientation)[:, None], sub, s.timestamps)[:, 0].numpy()
        if s.acceleration is not None:
            a = t64(s.acceleration)
            ch["acceleration"] = ((result.world_rotation[j] @ (a - G_VEC).unsqueeze(-1)).squeeze(-1) + G_VEC).numpy()
        if s.angular_velocity is not None:
            ch["angular_velocity"] = (result.rotation[j] @ t64(s.angular_velocity).unsqueeze(-1)).squeeze(-1).numpy()
        ch = {k: v.astype(getattr(s, k).dtype) for k, v in ch.items()}
        rest = {k: v for k, v in s.channels().items() if k not in ch}
        out.append(SensorStream(s.info, s.timestamps.copy(), s.valid.copy(), **rest, **ch))
    meta = copy.deepcopy(rec.meta)
    meta["calibration"] = result.to_dict()
    meta["orientation_frame"] = "segment"
    return replace(rec, sensors=out, meta=meta)


def fit_imu_noise(recording: Any, window: tuple[float, float], sensors: Sequence[str]) -> dict[str, float]:
    """:func:`wearpose.sensors.imu.fit_static_noise` of ``sensors`` held still in ``window`` (s):
    the recording's declared units converted, acceleration as sensor-frame specific force.
    ``rate_hz`` in the result is the sensors' mean rate."""
    # start-up: wearpose.sensors.imu adds ~100 ms to import wearpose.calibration
    from wearpose.sensors.imu import fit_static_noise

    rec = recording.to_canonical().declared_as(acc_frame="sensor", acc_gravity="included")
    data, rates = [], []
    for name in sensors:
        s = rec.sensor(name)
        if s.angular_velocity is None or s.acceleration is None or s.orientation is None:
            raise CalibrationError(f"fit_imu_noise: sensor {name!r} needs angular_velocity, acceleration and orientation")
        m = window_mask(s.timestamps, window, f"fit_imu_noise sensor {name!r}") & s.valid
        data.append((np.asarray(s.angular_velocity[m], np.float64), np.asarray(s.acceleration[m], np.float64),
                     np.asarray(s.orientation[m], np.float64)))
        rates.append(float(s.info.rate))
    return {**fit_static_noise(data, float(np.mean(rates))), "rate_hz": float(np.mean(rates))}
