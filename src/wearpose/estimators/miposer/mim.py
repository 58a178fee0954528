"""MI-Poser's metal-interference mitigation in the estimator: the glue between a MI-Poser
recording and :class:`wearpose.interference.MIM`.

MIM works per wrist EM sensor at the EM rate (120 Hz) on the EM pose relative to the head-worn
source and the co-located IMU expressed the same way: angular velocity of the sensor relative to
the source in the sensor frame, acceleration relative to the source in the source frame
(:class:`wearpose.interference.SensorStreams` convention). Those come either

- from the caller (``imu={em_sensor: (gyro (T, 3), acc (T, 3))}``, e.g. the interference
  simulator's IMU streams), or
- from the recording (:func:`relative_imu`): the wrist IMU's gyro rotated into the EM sensor
  frame (the subject offsets' sensor -> site rotation when present) minus the headset's angular
  velocity (finite differences of the 60 Hz VIO orientation, held to the EM instants); the wrist
  IMU's free world acceleration rotated into the source (head) frame. The head's own linear
  acceleration and the rotating-frame terms are *not* removed (the glasses' IMU is not part of
  the kit): an approximation that only the position correction feels.

:func:`mitigate_recording` returns a copy of the recording with corrected wrist EM streams and the
per-frame interference state; :func:`step_mim` is the online twin used by
:meth:`MiposerEstimator.step` (one MIM per wrist, at the frame rate it is fed).
"""

from __future__ import annotations

import copy
from dataclasses import replace
from typing import Any, Sequence

import numpy as np
import torch

from wearpose.errors import ConfigError
from wearpose.geometry import matrix_to_axis_angle


def default_mim_config() -> Any:
    """The estimator's MIM setting: detection (5 deg, gyro chain from 0.3 s before a detection) and
    gyro rotation correction, EM position kept (``position="none"``). Chosen on the *validation*
    split (``benchmarks/results/miposer_mim_val.json``, 29 clips, "standard" condition, head-worn
    source): upper-body MPJPE 3.77 cm without MIM, 3.74 cm with it, 3.73 cm with MIM's Kalman
    fusion position correction -- a tie, so the position stays EM's: the recording-derived IMU
    (:func:`relative_imu`) lacks the head's own linear acceleration, which only the position
    correction would feel."""
    # start-up: wearpose.interference adds ~490 ms to importing this module
    from wearpose.interference import MIMConfig

    return MIMConfig(position="none")


def make_mim(mim_config: Any = None) -> Any:
    """A :class:`wearpose.interference.MIM` (``mim_config`` or :func:`default_mim_config`); when the
    configured N-BEATS forecaster is not shipped (``ConfigError``), falls back to IMU odometry for
    the position and says so in ``.fallback``."""
    try:
        # start-up: wearpose.interference adds ~490 ms to importing this module
        from wearpose.interference import MIM
    except ImportError as exc:  # pragma: no cover - the module is part of the package
        raise ConfigError(f"MI-Poser MIM needs wearpose.interference ({exc})") from exc

    cfg = mim_config or default_mim_config()
    try:
        m = MIM(cfg)
        m.fallback = None
    except ConfigError as exc:
        m = MIM(replace(cfg, position="odometry"))
        m.fallback = f"position '{cfg.position}' unavailable ({exc}); using 'odometry'"
    return m


def _em_imu_pairs(recording: Any, kit: str) -> list[tuple[str, str | None]]:
    # start-up: wearpose.sensors adds ~90 ms to importing this module
    from wearpose.sensors import get_kit

    k = get_kit(kit)
    imus = {s.site: s.name for s in k.sensors if s.kind == "imu"}
    return [(s.name, imus.get(s.site)) for s in k.sensors if s.kind == "em6dof"]


def _rot_log(R: np.ndarray) -> np.ndarray:
    return matrix_to_axis_angle(torch.from_numpy(np.ascontiguousarray(R))).numpy()


def relative_imu(recording: Any, kit: str, em_name: str, imu_name: str | None) -> tuple[np.ndarray, np.ndarray]:
    """MIM's IMU inputs for one wrist EM sensor from a recording (module doc), at the EM samples.

    Returns:
        ``(gyro (T, 3) rad/s, acc (T, 3) m/s^2)``; zeros where the kit has no co-located IMU.
    """
    # start-up: wearpose.estimators.inputs adds ~140 ms to importing this module
    from wearpose.estimators.inputs import nearest_samples
    # start-up: wearpose.estimators.miposer.data adds ~610 ms to importing this module
    from wearpose.estimators.miposer.data import input_spec

    em = recording.sensor(em_name)
    ts = np.asarray(em.timestamps, dtype=np.float64)
    T = len(ts)
    if imu_name is None or imu_name not in recording.names:
        return np.zeros((T, 3)), np.zeros((T, 3))
    h = recording.sensor(input_spec(kit).sensor_names[0])
    u = recording.to_canonical().sensor(imu_name)
    i, _ = nearest_samples(np.asarray(u.timestamps, dtype=np.float64), ts)
    w_site = np.nan_to_num(np.asarray(u.angular_velocity, dtype=np.float64)[i])
    a_world = np.nan_to_num(np.asarray(u.acceleration, dtype=np.float64)[i])
    R_off = np.eye(3)
    off = (recording.subject or {}).get("offsets")
    if off and em_name in list(off.get("sensors", [])):
        R_off = np.asarray(off["rotation"], dtype=np.float64)[list(off["sensors"]).index(em_name)]
    w_s = w_site @ R_off  # R_off^T w (row vectors)
    hR = np.asarray(h.orientation, dtype=np.float64)
    hts = np.asarray(h.timestamps, dtype=np.float64)
    w_head = np.zeros((len(hts), 3))
    if len(hts) > 1:
        w_head[1:] = _rot_log(hR[1:] @ np.swapaxes(hR[:-1], -1, -2)) / np.diff(hts)[:, None]  # world frame
        w_head[0] = w_head[1]
    j, _ = nearest_samples(hts, ts)
    R_head = hR[j]
    R_em = np.nan_to_num(np.asarray(em.orientation, dtype=np.float64))
    R_ws = R_head @ R_em
    gyro = w_s - np.einsum("tji,tj->ti", R_ws, w_head[j])
    acc = np.einsum("tji,tj->ti", R_head, a_world)
    return gyro, acc


def mitigate_recording(recording: Any, kit: str, mim_config: Any = None,
                       imu: dict[str, tuple[np.ndarray, np.ndarray]] | None = None) -> tuple[Any, dict[str, Any]]:
    """Run MIM on every wrist EM stream of ``recording`` (module doc).

    Returns:
        ``(recording', info)``: a copy whose wrist EM ``position``/``orientation`` are MIM's output;
        ``info[em_sensor]`` = ``{"timestamps", "interfered", "corrected", "degraded", "level",
        "discrepancy"}`` arrays at the EM rate, plus ``info["fallback"]`` when the position method
        fell back to odometry.
    """
    rec = copy.deepcopy(recording)
    info: dict[str, Any] = {}
    for em_name, imu_name in _em_imu_pairs(recording, kit):
        s = rec.sensor(em_name)
        gyro, acc = imu[em_name] if imu and em_name in imu else relative_imu(recording, kit, em_name, imu_name)
        R = np.asarray(s.orientation, dtype=np.float64)
        p = np.asarray(s.position, dtype=np.float64)
        ok = np.asarray(s.valid) & np.isfinite(p).all(1)
        R = np.where(ok[:, None, None], np.nan_to_num(R), np.eye(3))
        p = np.nan_to_num(p)
        fps = float(s.info.rate)
        m = make_mim(mim_config)
        out = m.process(R, p, np.asarray(gyro, dtype=np.float64), np.asarray(acc, dtype=np.float64), fps)
        s.orientation = np.where(ok[:, None, None], out["R"], s.orientation).astype(s.orientation.dtype)
        s.position = np.where(ok[:, None], out["p"], s.position).astype(s.position.dtype)
        info[em_name] = {"timestamps": np.asarray(s.timestamps), **{k: out[k] for k in
                                                                 ("interfered", "corrected", "degraded", "level", "discrepancy")}}
        if m.fallback:
            info["fallback"] = m.fallback
    return rec, info


def step_mim(mims: list[Any], frame: Any, names: Sequence[str], cols: Sequence[int], R: torch.Tensor, p: torch.Tensor,
             dt: float, mim_config: Any = None) -> tuple[torch.Tensor, torch.Tensor, dict[str, Any]]:
    """Online MIM on one frame: ``names`` = (headset, wrist EM ...) rows of ``R`` ``(S, 3, 3)`` /
    ``p`` ``(S, 3)``, in the frame's columns ``cols`` (the estimator's
    :meth:`~wearpose.estimators.inputs.OnlineInput.index`); the frame's ``angular_velocity`` /
    ``acceleration`` rows of the wrists in MIM's convention (NaN -> 0). ``mims`` holds one MIM
    per wrist (created on first use)."""
    # float64 numpy copies made once per frame (not per wrist and per tensor row); outputs written
    # into them and converted back once: the same roundings as row by row.
    Rn = R.detach().cpu().numpy().astype(np.float64)
    pn = p.detach().cpu().numpy().astype(np.float64)
    n_cols = len(frame.names)
    nan = np.full((n_cols, 3), np.nan)
    gy = np.nan_to_num(np.asarray(frame.channels.get("angular_velocity", nan), dtype=np.float64))
    ac = np.nan_to_num(np.asarray(frame.channels.get("acceleration", nan), dtype=np.float64))
    info: dict[str, Any] = {}
    for j, n in enumerate(names[1:]):
        if mims[j] is None:
            mims[j] = make_mim(mim_config)
        k = int(cols[j + 1])
        o = mims[j].step(Rn[j + 1].copy(), pn[j + 1].copy(), gy[k], ac[k], dt)
        Rn[j + 1], pn[j + 1] = o["R"], o["p"]
        info[n] = {k2: o[k2] for k2 in ("interfered", "corrected", "degraded", "level")}
    return (torch.from_numpy(Rn).to(dtype=R.dtype, device=R.device),
            torch.from_numpy(pn).to(dtype=p.dtype, device=p.device), info)
