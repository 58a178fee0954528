"""Weights or a checkpoint -> a pose for a recording, and that pose in wearpose's world.

The one path every command takes (``wearpose estimate``, ``serve``, ``view-recording``, the
demos): :func:`open_model` resolves a ``--model`` (shipped weights, a checkpoint file, or a
weight-free estimator such as ``segments``) reading its checkpoint once; :func:`fit_rate`
brings a recording to the rate the weights were trained at; :func:`use_calibration_window`
points an estimator's own T-pose calibration at the window a recording marks;
:func:`estimate_recording` runs all of it; :func:`place_in_world` puts the estimate where a user
expects a body to stand.

**In the world**: upright, facing +Z, feet on the floor (Y up, floor y = 0).
Estimators return poses in the frame their sensors give: EM-POSE relative to the EM source
(``extras["frame"] == "em_source"``), PIP and BiRAE in the calibrated IMU world with a root
translation that starts at the origin (or none), MI-Poser in the headset's calibrated world.
:func:`place_in_world` is the one step that puts any of them where a user expects a body to
stand before it is exported or drawn; ``extras["placement"]`` says how it was placed.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Callable

import numpy as np
import torch

from wearpose.body import BodyModel, LowestPoint
from wearpose.errors import ConfigError, InputFileError
from wearpose.estimators.base import Estimator, PoseTrack
from wearpose.estimators.checkpoint import Checkpoint, load_checkpoint
from wearpose.estimators.registry import get_estimator
from wearpose.geometry import quat_to_matrix
from wearpose.recording import Recording, RecordingError, calibration_window, decimate
from wearpose.estimators.registry import list_estimators
from wearpose import weights as shipped  # the module, not its names: a test (or a plug-in) may replace them


@dataclass(frozen=True)
class ModelSource:
    """A resolved ``--model``: what it is, and how to make its estimator.

    Attributes:
        name: as the user gave it (weights name, checkpoint path, or estimator name).
        method: registry name of its estimator class (``wearpose.estimators.get_estimator``).
        checkpoint: the checkpoint, read once (None for weight-free estimators).
        path: the checkpoint file (None for weight-free estimators).
        kit, sensors, fps: the kit, its sensors (input order) and the rate (Hz) the weights were
            trained at; ``fps`` None when any rate is accepted.
        card: the shipped weights' card (``{}`` for a checkpoint file).
    """

    name: str
    method: str
    checkpoint: Checkpoint | None = None
    path: Path | None = None
    kit: str | None = None
    sensors: tuple[str, ...] = ()
    fps: float | None = None
    card: dict[str, Any] = field(default_factory=dict)

    @property
    def estimator_class(self) -> type[Estimator]:
        return get_estimator(self.method)

    def make(self) -> Estimator:
        """A fresh estimator (one per stream or recording) from the checkpoint already read."""
        cls = self.estimator_class
        if self.checkpoint is None:
            return cls()
        return cls.from_checkpoint(self.checkpoint, path=self.path or "<checkpoint>")

    @property
    def factory(self) -> Callable[[], Estimator]:
        """``() -> Estimator`` (what the stream server calls once per subject)."""
        return self.make


def open_model(model: str | Path, method: str | None = None) -> ModelSource:
    """Resolve ``model``: shipped weights (``wearpose.weights``, e.g. ``empose12_cpu``), a
    checkpoint file, or the name of a weight-free estimator (``segments``). A checkpoint is read
    here and only here; ``method`` overrides the registry name the checkpoint records.

    Raises:
        ConfigError: ``model`` is none of these (names the shipped weights and weight-free estimators).
        InputFileError: the checkpoint file cannot be read (from :func:`load_checkpoint`).
    """

    name = str(model)
    if name in shipped.list_weights():
        path, c = shipped.weight_path(name), shipped.card(name)
    elif Path(name).suffix == ".pt" or Path(name).is_file():
        path, c = Path(name), {}
    else:
        free = [n for n in list_estimators() if not getattr(get_estimator(n), "has_weights", True)]
        if name in free:
            return ModelSource(name=name, method=method or name)
        raise ConfigError(f"--model {name!r}: neither shipped weights ({', '.join(shipped.list_weights()) or 'none'}), a "
                          f"checkpoint file, nor a weight-free estimator ({', '.join(free)})")
    ck = load_checkpoint(path)
    fps = ck.config.get("rate") if isinstance(ck.config, dict) else None  # Hz the network was trained at
    return ModelSource(name=name, method=method or ck.method, checkpoint=ck, path=path, kit=ck.kit,
                       sensors=tuple(ck.sensors), fps=float(fps) if fps else None, card=c)


def fit_rate(source: ModelSource, path: str | Path, rec: Recording,
             resample: bool | None) -> tuple[Recording, str | None]:
    """Bring ``rec`` to the rate ``source`` was trained at by integer-factor decimation
    (:func:`wearpose.recording.decimate`: every k-th sample as recorded, never interpolated).

    ``resample``: ``None`` (auto) decimates when the weights' sensors in the recording share one
    rate that is an integer multiple of the trained rate, and returns a one-line note saying so;
    a ratio that does not decimate is left to the estimator, which refuses it with the fitting
    kit and rate. ``True`` does the same but makes a non-integer ratio an error naming both
    rates. ``False`` never changes the recording. Kits whose sensors run at different rates by
    design (MI-Poser: 60 Hz headset, 120 Hz EM) are left alone in auto mode.

    Returns:
        ``(recording, note)``; ``note`` is None when nothing changed.
    """
    path, target = Path(path), source.fps
    if resample is False or not target:
        return rec, None
    names = [n for n in source.sensors if n in rec.names] or list(rec.names)
    rates = sorted({float(rec.sensor(n).info.rate) for n in names})
    if all(abs(r - target) <= 1e-3 * target for r in rates):
        return rec, None
    if len(rates) > 1 and resample is None:
        return rec, None
    try:
        out = decimate(rec.select(names), float(target))
    except RecordingError as exc:
        if resample:
            raise InputFileError(path, f"--resample: {exc}", f"sensors at an integer multiple of {target:g} Hz") from None
        return rec, None
    k = {d["factor"] for d in out.meta.get("resampled", {}).values()}
    note = (f"{path.name}: {', '.join(f'{r:g}' for r in rates)} Hz decimated by {'/'.join(map(str, sorted(k)))} to "
            f"{source.name}'s {target:g} Hz (every k-th sample as recorded, dropped frames stay dropped; "
            "--no-resample refuses)")
    return out, note


def use_calibration_window(estimator: Any, recording: Recording) -> tuple[float, float] | None:
    """Point an estimator's built-in T-pose calibration at the window ``recording`` marks.

    Estimators that calibrate uncalibrated recordings themselves expose a
    ``calibration_window`` attribute (PIP: ``(0, 1)`` s by default; MI-Poser and the segment
    estimator: None, i.e. no window known); when the recording's meta marks its T-pose
    (:func:`wearpose.recording.calibration_window`), that window is used instead. Returns the
    window applied, or None (no mark, or an estimator without built-in calibration).
    """
    window = calibration_window(recording)
    if window is None or not hasattr(estimator, "calibration_window"):
        return None
    estimator.calibration_window = window
    return window


def use_subject_calibration(estimator: Any, recording: Any) -> bool:
    """Give ``estimator`` the subject calibration ``recording.subject`` holds (EM-POSE sensor
    offsets, read exactly as offline); ``recording`` needs only a ``subject`` dict (the stream
    server passes a subject's hello). Returns whether the recording's own calibration was applied.

    An estimator that takes offsets is given them here even when the recording has none, through
    the same reading as offline: it refuses now (EM-POSE with the refinement on raises
    :class:`~wearpose.errors.ConfigError`, so a server refuses the subject at its hello rather
    than failing every frame) or warns and uses identity offsets, as its first step would."""
    if not (hasattr(estimator, "set_offsets") and hasattr(estimator, "_offsets_from")):
        return False
    estimator.set_offsets(*estimator._offsets_from(recording))
    return bool((recording.subject or {}).get("offsets"))


def start_online(estimator: Any, recording: Recording) -> None:
    """Ready ``estimator`` to :meth:`~wearpose.estimators.base.Estimator.step` through
    ``recording``'s frames as the stream server readies one per subject: the subject's
    calibration (:func:`use_subject_calibration`), the marked T-pose window
    (:func:`use_calibration_window`), then ``reset()``."""
    use_subject_calibration(estimator, recording)
    use_calibration_window(estimator, recording)
    estimator.reset()


@dataclass
class RunResult:
    """What :func:`estimate_recording` made: the estimate as estimated and placed in the world."""

    estimator: Estimator
    recording: Recording  # as estimated (after rate fitting)
    estimated: PoseTrack  # in the frame the estimator gives
    track: PoseTrack  # in the world, feet on the floor (:func:`place_in_world`)
    body: BodyModel
    note: str | None  # the rate-fitting note, or None


def estimate_recording(source: ModelSource, rec: Recording, path: str | Path = "<recording>", *,
                       resample: bool | None = None, estimator: Estimator | None = None) -> RunResult:
    """``source``'s estimate of ``rec``, in the world: rate fitted (:func:`fit_rate`), the
    recording's marked T-pose used for calibration (:func:`use_calibration_window`), estimated
    offline, placed (:func:`place_in_world`). ``estimator`` reuses one made by ``source.make()``.

    Raises what the estimator raises for a recording that does not fit it (ShapeError naming the
    missing sensors or the rate, CalibrationError when it cannot calibrate).
    """
    rec, note = fit_rate(source, path, rec, resample)
    est = estimator if estimator is not None else source.make()
    use_calibration_window(est, rec)
    estimated = est.estimate(rec)
    # rotation-only estimators (BiRAE) keep no body model: place and export on the default asset
    body = getattr(est, "body", None) or BodyModel()
    return RunResult(est, rec, estimated, place_in_world(est, estimated, rec, body), body, note)


def place_in_world(est: Any, track: PoseTrack, recording: Recording, body: BodyModel | None = None) -> PoseTrack:
    """``track`` upright in the world with its feet on the floor (module doc).

    EM estimates (source frame) go through the recording's EM source pose
    (``meta["em_source"]``, as simulation stores it) when it has one; else the source is taken
    as oriented as at rest on the body, so an upright subject stands upright (its heading and
    travel are then unknown: the body turns and moves with the source). Then the track is set on
    the floor (:func:`on_the_floor`).

    Args:
        est: the estimator that made ``track`` (its ``sites`` name the EM source site).
        track: its estimate of ``recording``.
        body: the body the track plays on (default: ``est.body``, else the default body).
    """
    body = body if body is not None else (getattr(est, "body", None) or BodyModel())
    if track.extras.get("frame") == "em_source":
        track = _em_source_to_world(est, track, recording, body)
    return on_the_floor(track, body)


#: A frame is a contact frame when the joint carrying the body's lowest point moves slower than
#: this (m/s, world): a stance foot, a knee or a back on the floor. Chosen among 0.2 / 0.35 / 0.5 /
#: 0.75 on the validation split for the fewest frames under the floor or off it while the truth
#: stands (docs/placement.md); 0.75 was within 0.05 points of 0.5 on every EM-POSE model.
CONTACT_SPEED_M_S = 0.5
#: With fewer contact frames than this share of the track (a clip in the air, a track too short
#: to tell), the floor is the median over every frame.
MIN_CONTACT_SHARE = 0.1
#: ``extras["floor"]`` of a track without an estimated translation: every frame on the floor.
EVERY_FRAME_ON_THE_FLOOR = "every frame on y = 0 (no translation estimated)"


def contact_frames(low: LowestPoint, fps: float, speed: float = CONTACT_SPEED_M_S) -> torch.Tensor:
    """``(T,)`` bool: frames where the joint carrying the lowest point (``low.joint``) moves
    slower than ``speed`` m/s (central differences of ``low.joints`` at ``fps`` Hz; one-sided at
    the ends). A track of one frame is in contact."""
    T = int(low.height.shape[0])
    if T < 2:
        return torch.ones(T, dtype=torch.bool)
    prev = low.joints[torch.arange(T).sub(1).clamp(min=0), low.joint]
    nxt = low.joints[torch.arange(T).add(1).clamp(max=T - 1), low.joint]
    span = torch.full((T,), 2.0, dtype=low.joints.dtype)
    span[0] = span[-1] = 1.0
    return (nxt - prev).norm(dim=-1) * float(fps) / span < speed


def floor_height(low: LowestPoint, fps: float, speed: float | None = CONTACT_SPEED_M_S) -> tuple[torch.Tensor, str]:
    """Where the floor is under a track's lowest points (m, world y) and how it was found: the
    median over the contact frames at ``speed`` (:func:`contact_frames`), over every frame when
    fewer than :data:`MIN_CONTACT_SHARE` are in contact or ``speed`` is None."""
    if speed is not None:
        contact = contact_frames(low, fps, speed)
        if int(contact.sum()) >= max(1, MIN_CONTACT_SHARE * len(low.height)):
            return low.height[contact].median(), "median lowest point of the contact frames on y = 0"
        return low.height.median(), "median lowest point on y = 0 (too few contact frames)"
    return low.height.median(), "median lowest point on y = 0"


def on_the_floor(track: PoseTrack, body: BodyModel) -> PoseTrack:
    """``track`` moved vertically so that the body stands on the floor (y = 0).

    With a translation (the method estimates travel), one shift for the whole track, so jumps
    and stairs keep their heights: the median of the body's lowest point over the **contact
    frames** (:func:`contact_frames`: the lowest point's joint at rest in the world) at 0. The
    median, because one stretch's lowest point (the first second, a calibration stance) carries
    that stretch's error to the whole clip (an EM-POSE walk floated 9-16 cm when floored on its
    T-pose); over contact frames, because a run is in the air for most of its frames: the median
    over all frames put its flight on the floor and its stance feet up to 6.5 cm under it. The
    price: where the legs' error spans 7-12 cm over a run's stance frames, the stance feet now hover
    rather than sink (docs/placement.md has both counts). With fewer than
    :data:`MIN_CONTACT_SHARE` contact frames, the median over every frame.
    Without a translation, each frame's lowest point at 0. Lowest points:
    :meth:`BodyModel.lowest_point`.
    """
    rot, betas = track.local_rot.to(body.dtype), track.betas.to(body.dtype)
    if track.trans is not None:
        with torch.no_grad():
            low = body.lowest_point(rot, betas, track.trans.to(body.dtype))
        floor, how = floor_height(low, track.fps)
        trans = track.trans.clone()
        trans[:, 1] -= floor.to(trans.dtype)
        return replace(track, trans=trans, extras={**track.extras, "floor": how})
    with torch.no_grad():
        low = body.lowest_height(rot, betas, None)
    trans = torch.zeros(track.num_frames, 3, dtype=track.local_rot.dtype)
    trans[:, 1] = -low.to(trans.dtype)
    return replace(track, trans=trans, extras={**track.extras, "floor": EVERY_FRAME_ON_THE_FLOOR})


def _em_source_to_world(est: Any, track: PoseTrack, rec: Recording, body: BodyModel) -> PoseTrack:
    src = ((rec.meta or {}).get("em_source") or {}).get("rates", {}).get(f"{float(track.fps):g}")
    if src is not None and hasattr(est, "to_world") and len(src["position_m"]) == track.num_frames:
        R = quat_to_matrix(torch.as_tensor(np.asarray(src["orientation_wxyz"], np.float32)))
        out = est.to_world(track, R, torch.as_tensor(np.asarray(src["position_m"], np.float32)))
        return replace(out, extras={**out.extras, "placement": "world, via the recorded EM source pose"})
    site = (getattr(est, "sites", None) or {}).get("<em_source>")
    if site is None:
        return track
    with torch.no_grad():
        R_rest = body.sites(None, track.betas.to(body.dtype), None, [site]).rotations[0]
    rot = track.local_rot.clone()
    rot[:, 0] = R_rest.to(rot.dtype) @ rot[:, 0]
    return replace(track, local_rot=rot, extras={**track.extras, "frame": "world",
                                                 "placement": "upright: EM source as at rest on the body"})
