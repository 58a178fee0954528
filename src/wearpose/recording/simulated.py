"""Simulated sensors -> :class:`Recording`: the same container (and file) as a real capture.

:func:`recording_from_simulation` (also ``Recording.from_simulation``) turns the output of
:func:`wearpose.sensors.simulate` into a :class:`Recording`, so training data, test data and a
user's device all go through one reader and one set of conventions.

What goes where:

- one :class:`SensorStream` per kit sensor, in kit order, on its own time grid (kits such as
  ``miposer`` mix 60 and 120 Hz): timestamps in seconds from the motion's first frame, the
  simulator's validity mask (dropped EM frames are ``valid=False`` and NaN, never filled);
- channels in wearpose's canonical form, so every :class:`SensorInfo` keeps the canonical
  defaults: EM position (m) / orientation relative to the EM source frame
  (``reference="source"``, ``source="em_source"``, ``source_site`` = the kit's source site);
  IMU/MIMU orientation ``R_WS`` and free acceleration in the Y-up world (m/s^2, gravity
  removed), angular velocity in the sensor frame (rad/s), MIMU magnetic field in the sensor
  frame (``mag_unit="T"``); VIO position/orientation in the world;
- ``ground_truth``: the motion that was simulated (its own rate, ``ground_truth_start = 0``);
- ``subject``: ``id`` and, with EM sensors, ``offsets``: the sensor-to-skin offsets ``o_s``
  actually applied to this sequence (EM-POSE Eq. 4; ``rotation`` (S, 3, 3) sensor -> site frame,
  ``translation_mean_m`` (S, 3) site frame, m) under the same keys as
  :func:`wearpose.recording.from_empose` uses for a real subject. A simulated offset is constant
  over the sequence (the per-sequence jitter of EM-POSE supp. 2.2 is drawn once), so
  ``translation_mean_m`` is exact and there is no covariance;
- ``meta``: provenance (``source="simulation"``, kit, seed, noise models, body asset, site
  substitutions, the motion's clip id and licence) and, with EM sensors, ``em_source``: the
  ground-truth world pose of the EM source per EM rate (``position_m`` (T, 3), ``orientation_wxyz``
  (T, 4) unit quaternions, rounded to 1 micrometre / 1e-7), for calibration and evaluation. It is
  recomputable from the ground truth and the body model (the source site), so
  ``source_pose=False`` leaves it out and saves about a third of an ``em12`` file.

Not carried over: the simulator's diagnostic ``extras`` (world positions, distances, yaw
errors, segment orientations) and the raw specific force -- all derivable from the ground truth.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np
import torch

from wearpose.errors import ShapeError
from wearpose.geometry import matrix_to_quat
from wearpose.recording.tpose import CALIBRATION_WINDOW_KEY, prepend_tpose
from wearpose.recording.types import OPTIONAL_CHANNELS, REQUIRED_CHANNELS, Recording, SensorInfo, SensorStream

#: Name given to the EM source (transmitter) in :attr:`SensorInfo.source` of simulated EM sensors.
EM_SOURCE_NAME = "em_source"
#: Unit of the simulated MIMU magnetic field (tesla, :mod:`wearpose.sensors.mimu`).
SIM_MAG_UNIT = "T"


def _np(x: Any, dtype: Any) -> np.ndarray | None:
    if x is None:
        return None
    if isinstance(x, torch.Tensor):
        x = x.detach().cpu().numpy()
    return np.asarray(x).astype(dtype, copy=True)


def _noise_json(noise: Any) -> Any:
    """A NoiseConfig (dataclass of per-kind dataclasses or None) as plain JSON."""
    if noise is None:
        return None
    if dataclasses.is_dataclass(noise):
        return {f.name: _noise_json(getattr(noise, f.name)) for f in dataclasses.fields(noise)}
    if isinstance(noise, (list, tuple)):
        return [_noise_json(v) for v in noise]
    if isinstance(noise, float) and not math.isfinite(noise):
        return str(noise)
    return noise


def _quat_rows(R: torch.Tensor) -> list[list[float]]:
    q = matrix_to_quat(R.detach().to(torch.float64)).cpu().numpy()
    return np.round(q, 7).tolist()


def recording_from_simulation(result: Any, motion: Any = None, subject: dict[str, Any] | str | None = None, *,
                              source_pose: bool = True, dtype: Any = np.float32,
                              meta: dict[str, Any] | None = None) -> Recording:
    """A :class:`Recording` of a simulation (see the module docstring for the field mapping).

    Args:
        result: a :class:`wearpose.sensors.SimulationResult`.
        motion: the :class:`wearpose.motion.MotionSequence` that was simulated, stored as the
            ground truth (``None``: no ground truth). Its rate and length must match the
            simulation's ``meta["motion_fps"]`` / ``meta["motion_frames"]``.
        subject: a subject id (str) or a dict merged into ``Recording.subject`` (its keys win
            over the generated ones, except ``offsets``, which is what was simulated).
        source_pose: store the EM source's ground-truth world pose in ``meta["em_source"]``.
        dtype: channel dtype (float32 by default, as the DESIGN asks; float64 for tests).
        meta: extra provenance merged into ``Recording.meta`` (e.g. the clip id).

    Returns:
        the :class:`Recording`; ``save_recording``/``load_recording`` round-trip it.

    Raises:
        ShapeError: ``result`` is not a simulation result, or ``motion`` does not match it.
    """
    for attr in ("kit", "sensors", "seed", "noise"):
        if not hasattr(result, attr):
            raise ShapeError(f"Recording.from_simulation: expected a wearpose.sensors.SimulationResult, got "
                             f"{type(result).__name__} (no {attr!r})")
    kit = result.kit
    sim_meta = dict(getattr(result, "meta", {}) or {})
    if motion is not None:
        # start-up: wearpose.motion adds ~80 ms to import wearpose.recording
        from wearpose.motion.sequence import MotionSequence

        if not isinstance(motion, MotionSequence):
            raise ShapeError(f"Recording.from_simulation: motion must be a MotionSequence or None, got {type(motion).__name__}")
        fps, frames = sim_meta.get("motion_fps"), sim_meta.get("motion_frames")
        if (fps is not None and abs(float(fps) - motion.fps) > 1e-6) or (frames is not None and int(frames) != motion.num_frames):
            raise ShapeError(f"Recording.from_simulation: motion has {motion.num_frames} frames at {motion.fps:g} Hz but the "
                             f"simulation ran on {frames} frames at {fps} Hz; pass the motion given to simulate()")

    streams: list[SensorStream] = []
    for name, s in result.sensors.items():
        is_em = s.kind == "em6dof"
        info = SensorInfo(
            name=name, kind=s.kind, site=s.site, rate=float(s.rate),
            mag_unit=SIM_MAG_UNIT if s.magnetic_field is not None else SensorInfo.mag_unit,
            # The simulator states its frame per stream: "source" (EM) or "world".
            reference="source" if s.frame == "source" else "world",
            source=EM_SOURCE_NAME if is_em else None,
            source_site=kit.em_source_site if is_em else None,
        )
        allowed = REQUIRED_CHANNELS[s.kind] + OPTIONAL_CHANNELS[s.kind]
        ch = {c: _np(getattr(s, c), dtype) for c in allowed if getattr(s, c, None) is not None}
        valid = _np(s.valid, bool)
        for c, arr in ch.items():
            # The simulator fills dropped frames with NaN (or zeros, em_fill="zero"); a stream
            # must hold NaN there (the mask is the truth), and any non-finite value the
            # simulator produced in a frame it calls valid is a bug worth a clear error.
            arr[~valid] = np.nan
        streams.append(SensorStream(info, _np(s.timestamps, np.float64), valid, **ch))

    subj: dict[str, Any] = {"id": "synthetic"}
    if isinstance(subject, str):
        subj["id"] = subject
    elif isinstance(subject, dict):
        subj.update(subject)
    elif subject is not None:
        raise ShapeError(f"Recording.from_simulation: subject must be a str, a dict or None, got {type(subject).__name__}")
    em_names = [s.name for s in kit.sensors if s.kind == "em6dof"]
    off = getattr(result, "em_offsets", None)
    if off is not None and em_names:
        subj["offsets"] = {
            "sensors": em_names,
            "rotation": np.round(off.R.detach().cpu().numpy().astype(np.float64), 9).tolist(),
            "translation_mean_m": np.round(off.t.detach().cpu().numpy().astype(np.float64), 9).tolist(),
            "origin": "simulated: applied to every frame of this sequence (EM-POSE Eq. 4)",
        }

    rec_meta: dict[str, Any] = {
        "source": "simulation",
        "generator": "wearpose.sensors.simulate",
        "kit": kit.name,
        "kit_description": kit.description,
        "seed": int(result.seed),
        "noise": _noise_json(result.noise),
        "body_asset": sim_meta.get("body_asset"),
        "site_substitutions": dict(getattr(result, "site_substitutions", {}) or {}),
        "offsets_index": sim_meta.get("offsets_index"),
    }
    if motion is not None:
        # The motion's provenance travels with the ground truth (its meta is stored in the
        # file); the licence is repeated at the top because it binds the recording too.
        if "licence" in (motion.meta or {}):
            rec_meta["licence"] = motion.meta["licence"]
        rec_meta["motion"] = {k: motion.meta[k] for k in ("source", "subject", "clip", "split", "description")
                              if k in (motion.meta or {})}
    em_source = getattr(result, "em_source", {}) or {}
    if em_names:
        src: dict[str, Any] = {"name": EM_SOURCE_NAME, "site": kit.em_source_site, "frame": "world"}
        if source_pose:
            src["rates"] = {f"{float(r):g}": {
                "position_m": np.round(_np(d["position"], np.float64), 6).tolist(),
                "orientation_wxyz": _quat_rows(d["orientation"]),
            } for r, d in em_source.items()}
        rec_meta["em_source"] = src
    if meta:
        rec_meta.update(meta)
    return Recording(streams, motion, 0.0, subj, rec_meta)


def simulate_recording(motion: Any, kit: Any, body: Any, *, seed: int = 0, noise: Any = "default",
                       rate: float | None = None, offsets: str | None = "random", shape: Any = None,
                       tpose_s: float | None = None, subject: dict[str, Any] | str | None = None,
                       source_pose: bool = True, meta: dict[str, Any] | None = None) -> tuple[Recording, Any]:
    """A motion worn by a simulated kit, as a :class:`Recording`: the one path from a motion to
    simulated sensors (``wearpose simulate``, the latency bench).

    Args:
        motion: a :class:`wearpose.motion.MotionSequence`.
        kit, body, seed, noise, rate, offsets, shape: as :func:`wearpose.sensors.simulate`
            (``offsets="random"``: a random subject's EM sensor offsets; None: none).
        tpose_s: seconds of calibration T-pose held before the motion (IMU kits; marked in
            ``meta["calibration_window"]``, :func:`wearpose.recording.prepend_tpose`); None: none.
        subject, source_pose, meta: as :func:`recording_from_simulation`.

    Returns:
        ``(recording, result)``: the recording (ground truth = the motion as worn: re-fitted to
        the wearer's body when ``shape`` draws one) and the :class:`~wearpose.sensors.SimulationResult`.
    """
    from wearpose.sensors import simulate  # start-up: wearpose.sensors adds ~120 ms to import wearpose.recording

    extra = dict(meta or {})
    if tpose_s:
        motion, extra[CALIBRATION_WINDOW_KEY] = prepend_tpose(motion, tpose_s)
    with torch.no_grad():
        res = simulate(motion, kit, body, seed=seed, noise=noise, rate=rate, offsets=offsets, shape=shape)
    motion = res.motion if res.motion is not None else motion
    return recording_from_simulation(res, motion, subject, source_pose=source_pose, meta=extra), res
