"""``MiposerEstimator``: MI-Poser behind the :class:`~wearpose.estimators.Estimator` protocol.

Input: a recording of kit ``miposer`` (or ``miposer1``): the AR-glasses headset (``vio``, world,
60 Hz) and wrist EM sensors relative to the head-worn source (120 Hz), each with a co-located
IMU (used only by MIM). Pipeline per recording:

1. optional **MIM** (``mim=True``, :mod:`wearpose.interference`): each wrist's EM stream is
   checked against its gyro and corrected at the EM rate before anything else (Sec. 3);
   per-frame interference flags, levels and "tracking degraded" notices go to
   ``extras["interference"]``;
2. wrist EM poses composed with the headset pose and sampled at the headset's 60 Hz instants
   (:func:`~wearpose.estimators.miposer.data.raw_inputs`); dropped samples held;
3. the **T-pose calibration** of Sec. 4.2 (:func:`wearpose.calibration.miposer_tpose`): from
   ``calibration=`` (a :class:`~wearpose.calibration.CalibrationResult`), else
   ``recording.meta["calibration"]`` (``wearpose calibrate --method miposer-tpose``), else from
   ``calibration_window=(t0, t1)``; ``calibration="none"`` keeps only the world alignment (the
   "without calibration" condition of Fig. 5); without any, identity (a warning);
4. the **IK network** on the 40-frame window ending at each frame (causal; the first frames see
   a window padded with the first frame), root translation anchored on the head.

Output: local rotations ``(T, 24, 3, 3)`` with the root in the calibrated world (subject facing
+Z at the T-pose, model scale; ``extras["frame"] = "calibrated"``), mean-shape betas, root
translation, ``valid`` = every input sensor valid at that frame.

Online: :meth:`step` takes one 60 Hz :class:`~wearpose.estimators.base.SensorFrame` (see
:func:`frames`), keeps the last 40 calibrated frames and runs the network on them; with MIM the
wrist streams are checked/corrected frame by frame at 60 Hz (``MIM.step``).
"""

from __future__ import annotations

import time
import warnings
from pathlib import Path
from typing import Any, Iterator, Mapping

import numpy as np
import torch

from wearpose.calibration import CalibrationResult, apply_miposer, calibrate, em_to_world
from wearpose.errors import ConfigError, ShapeError
from wearpose.estimators.base import Estimator, PoseFrame, PoseTrack, SensorFrame
from wearpose.estimators.checkpoint import Checkpoint, CheckpointMismatchError, NetworkCheckpointing, load_checkpoint
from wearpose.estimators.inputs import InputSpec, OnlineInput, canonical_input, on_first_grid
from wearpose.estimators.miposer.config import MiposerConfig
from wearpose.estimators.miposer.data import calibrated_inputs, input_spec, raw_inputs, uncalibrated
from wearpose.estimators.miposer.mim import mitigate_recording, step_mim
from wearpose.estimators.miposer.model import AvatarPoserNet, decode_pose, head_anchored_translation, window_features
from wearpose.estimators.miposer.train import train_miposer
from wearpose.estimators.registry import register_estimator
from wearpose.sensors import get_kit
from wearpose.estimators.seeding import init_seed, seeded
from wearpose.estimators.trainmix import mix_clause


def resolve_calibration(recording: Any, calibration: Any, window: tuple[float, float] | None, body: Any) -> Any:
    """The :class:`~wearpose.calibration.CalibrationResult` to use (module doc, step 3), or None."""
    if isinstance(calibration, CalibrationResult):
        return calibration
    stored = (recording.meta or {}).get("calibration") if recording is not None else None
    res = None
    if stored and stored.get("method") == "miposer-tpose":
        res = CalibrationResult.from_dict(stored)
    elif window is not None:
        res = calibrate(recording, "miposer-tpose", window=window, body=body)
    if calibration == "none":
        if res is None:
            return None
        return uncalibrated(res)
    return res


def window_batches(R: torch.Tensor, p: torch.Tensor, window: int, chunk: int = 512,
                   frames: torch.Tensor | None = None) -> Iterator[tuple[torch.Tensor, torch.Tensor, torch.Tensor]]:
    """Causal windows ending at every frame (or at ``frames``) of ``R`` ``(T, S, 3, 3)`` /
    ``p`` ``(T, S, 3)``, the start padded with the first frame: yields
    ``(frame_indices (B,), R (B, W, S, 3, 3), p (B, W, S, 3))``."""
    T = R.shape[0]
    Rp = torch.cat([R[:1].expand(window - 1, *R.shape[1:]), R])
    pp = torch.cat([p[:1].expand(window - 1, *p.shape[1:]), p])
    frames = torch.arange(T) if frames is None else torch.as_tensor(frames, dtype=torch.long)
    for a in range(0, len(frames), chunk):
        f = frames[a:a + chunk]
        idx = (f + window - 1)[:, None] - torch.arange(window - 1, -1, -1)
        yield f, Rp[idx], pp[idx]


def frames(recording: Any, kit: str = "miposer", rate: float = 60.0) -> Iterator[SensorFrame]:
    """Replay a MI-Poser recording as 60 Hz :class:`SensorFrame` s for :meth:`MiposerEstimator.step`.

    Sensors (names): the headset and the wrist EM sensors of ``kit``; channels ``position``
    ``(S, 3)``, ``orientation`` ``(S, 3, 3)`` in canonical form (headset in its world, EM relative
    to the source; declared units and up axes converted), plus ``angular_velocity`` /
    ``acceleration`` ``(S, 3)`` of each wrist's co-located IMU (NaN for the headset and when the
    kit has no IMU). Every sensor is taken at the headset's instants as offline
    (:func:`~wearpose.estimators.miposer.data.input_spec`, :func:`~wearpose.estimators.inputs.on_first_grid`).
    """
    spec = input_spec(kit, rate)
    recording = canonical_input(recording, spec)
    k = get_kit(kit)
    imus = {s.site: s.name for s in k.sensors if s.kind == "imu" and s.name in recording.names}
    wrist_imu = {n: imus.get(k.sensor(n).site) for n in spec.sensor_names[1:]}
    aligned = on_first_grid(recording, (*spec.sensor_names, *(u for u in wrist_imu.values() if u)))
    grid = aligned.on_common_grid(spec.sensor_names)
    T, S = grid.valid.shape
    gyr, acc = np.full((T, S, 3), np.nan, np.float32), np.full((T, S, 3), np.nan, np.float32)
    for j, n in enumerate(spec.sensor_names[1:], start=1):
        u = aligned.sensor(wrist_imu[n]) if wrist_imu[n] else None  # NaN beyond the grid tolerance
        if u is not None and u.angular_velocity is not None:
            gyr[:, j] = u.angular_velocity
        if u is not None and u.acceleration is not None:
            acc[:, j] = u.acceleration
    for t in range(T):
        yield SensorFrame(float(grid.timestamps[t]), grid.names, grid.valid[t],
                          {"position": grid.channels["position"][t], "orientation": grid.channels["orientation"][t],
                           "angular_velocity": gyr[t], "acceleration": acc[t]})


@register_estimator("miposer")
class MiposerEstimator(NetworkCheckpointing, Estimator):
    """MI-Poser (module doc).

    Args:
        config: :class:`MiposerConfig` (``model="avatarposer"``).
        body: :class:`~wearpose.body.BodyModel` (default: the embedded asset).
        device: torch device.
        mim: run metal-interference mitigation on the wrist EM streams (needs
            :mod:`wearpose.interference`).
        mim_config: a ``wearpose.interference.MIMConfig`` (None: detection + gyro rotation
            correction, EM position kept; :func:`~wearpose.estimators.miposer.mim.default_mim_config`).
    """

    name = "miposer"
    causal = True
    lookahead = 0

    def __init__(self, config: MiposerConfig | None = None, body: Any = None, device: str | torch.device = "cpu",
                 mim: bool = False, mim_config: Any = None) -> None:
        config = config or MiposerConfig.preset("cpu")
        if config.model != "avatarposer":
            raise ShapeError(f"MiposerEstimator needs model='avatarposer', got {config.model!r}")
        self.init_state(config, body, device)
        with seeded(init_seed(self.config.seed)):  # initial weights: a function of the seed (issue 24)
            self.model = AvatarPoserNet(self.config, 1 + self.config.wrists).to(self.device)
        #: ``(t0, t1)`` s of the wearer's T-pose :meth:`estimate` calibrates from when neither the
        #: call nor the recording gives a calibration (set from a recording's marked T-pose by
        #: :func:`wearpose.estimators.run.use_calibration_window`); None: no such window.
        self.calibration_window: tuple[float, float] | None = None
        self.mim = bool(mim)
        self.mim_config = mim_config
        self._calibration: Any = None
        self.reset()

    # ------------------------------------------------------------------ checkpoints
    # to / checkpoint / save: NetworkCheckpointing
    @classmethod
    def from_checkpoint(cls, ckpt: Checkpoint, *, kit: str | None = None, body: Any = None,
                        device: str | torch.device = "cpu", path: str | Path = "<checkpoint>", **kw: Any) -> MiposerEstimator:
        body = cls.check_checkpoint(ckpt, kit=kit, body=body, path=path)
        est = cls(MiposerConfig.from_dict(ckpt.config), body=body, device=device, **kw)
        if list(est.sensor_names) != list(ckpt.sensors):
            raise CheckpointMismatchError(f"{path}: checkpoint expects sensors {ckpt.sensors}, kit {est.kit_name!r} "
                                          f"has {list(est.sensor_names)}")
        return est.restore(ckpt)

    @classmethod
    def load(cls, path: str | Path, *, kit: str | None = None, body: Any = None,
             map_location: str | torch.device = "cpu", **kw: Any) -> MiposerEstimator:
        return cls.from_checkpoint(load_checkpoint(path, map_location), kit=kit, body=body, device=map_location,
                                   path=path, **kw)

    def fit(self, *args: Any, **kwargs: Any) -> Any:
        """Train (:func:`wearpose.estimators.miposer.train.train_miposer`)."""
        return train_miposer(self, *args, **kwargs)

    @classmethod
    def training_data_description(cls, config: Mapping[str, Any]) -> str | None:
        """The card sentence (:meth:`Estimator.training_data_description`) of
        :func:`wearpose.estimators.miposer.data.build_split` and the training windows."""
        cfg = MiposerConfig.from_dict(dict(config))
        wrists = "left-wrist" if cfg.wrists == 1 else "both wrists'"
        noise = {"default": "default noise: headset VIO drift, wrist EM noise and dropped frames",
                 "none": "no noise"}[cfg.train_noise]
        return (f"kit {cfg.kit} (headset VIO + {wrists} EM relative to the head-worn source, wearpose.sensors.simulate, "
                f"{noise}, a random subject's EM sensor offsets per clip) after a {cfg.tpose_s:g} s T-pose per clip "
                f"blended into it over {cfg.blend_s:g} s, calibrated with calibration.calibrate('miposer-tpose'); "
                f"{cfg.rate:g} Hz" + (", dropped samples held at the last valid value" if cfg.train_noise == "default" else "")
                + f"; windows of {cfg.window} frames every {cfg.stride}" + mix_clause(cfg))

    # ------------------------------------------------------------------ network
    @torch.no_grad()
    def infer(self, R: torch.Tensor, p: torch.Tensor, frames: torch.Tensor | None = None,
              chunk: int = 512) -> tuple[torch.Tensor, torch.Tensor]:
        """Poses from calibrated inputs ``R`` ``(T, S, 3, 3)``, ``p`` ``(T, S, 3)`` (causal windows).

        Args:
            frames: ``(N,)`` frame indices to estimate (default all ``T``); each estimate depends
                only on its own window, so a subset gives the same values at those frames.

        Returns:
            ``(local_rot (N, 24, 3, 3), trans (N, 3))`` in the calibrated world.
        """
        self.model.eval()
        W = self.config.window
        rots, trans = [], []
        for _, Rw, pw in window_batches(R.float(), p.float(), W, chunk, frames):
            x, C, _ = window_features(Rw.to(self.device), pw.to(self.device), self.fps)
            pose = decode_pose(*self.model(x), C)
            rots.append(pose.cpu())
            trans.append(head_anchored_translation(self.body, pose, pw[:, -1, 0].to(self.device)).cpu())
        return torch.cat(rots), torch.cat(trans)

    # ------------------------------------------------------------------ offline
    @property
    def input_spec(self) -> InputSpec:
        """What :meth:`estimate` reads: the headset pose at the trained rate and the wrist EM
        poses (relative to the head-worn source, or in the world), any EM rate. The kit's wrist
        IMUs (MIM's input) are optional and converted with the rest."""
        return input_spec(self.kit_name, self.fps)

    def estimate(self, recording: Any, calibration: Any = None,
                 calibration_window: tuple[float, float] | None = None, imu: dict[str, Any] | None = None) -> PoseTrack:
        """Offline estimate of a MI-Poser recording (module doc).

        Args:
            recording: a :class:`~wearpose.recording.Recording` with the kit's sensors.
            calibration: a ``miposer-tpose`` :class:`~wearpose.calibration.CalibrationResult`,
                ``None`` (use the recording's stored one or ``calibration_window``) or ``"none"``.
            calibration_window: ``(t0, t1)`` s of the T-pose, to calibrate here.
            imu: MIM's IMU inputs per wrist EM sensor, ``{name: (gyro (T, 3), acc (T, 3))}`` at the
                EM samples, relative to the source (default: derived from the recording,
                :func:`~wearpose.estimators.miposer.mim.relative_imu`).
        """
        extras: dict[str, Any] = {"frame": "calibrated", "method": self.name, "mim": self.mim}

        def mitigated(rec: Any) -> Any:  # MIM on the checked, canonical recording, before the grid

            rec, extras["interference"] = mitigate_recording(rec, self.kit_name, self.mim_config, imu)
            return rec

        raw = raw_inputs(recording, self.kit_name, self.fps, before_grid=mitigated if self.mim else None)
        res = resolve_calibration(raw["recording"], calibration, calibration_window or self.calibration_window, self.body)
        if res is None:
            warnings.warn("MI-Poser: no calibration (pass calibration=, calibration_window= or store one with "
                          "wearpose calibrate --method miposer-tpose); sensor poses are used as they are", stacklevel=2)
            R, p = raw["R"].float(), raw["p"].float()
        else:
            R, p = calibrated_inputs(raw, res)
            extras["calibration"] = res.to_dict()
        local_rot, trans = self.infer(R, p)
        return PoseTrack(local_rot, torch.zeros(10), trans, raw["valid"].all(1), self.fps, extras=extras)

    # ------------------------------------------------------------------ online
    def set_calibration(self, calibration: Any) -> None:
        """The ``miposer-tpose`` calibration :meth:`step` applies (None: sensor poses as they are)."""
        self._calibration = calibration

    def set_mim(self, on: bool) -> None:
        """Metal-interference mitigation on the wrist EM streams on or off (``mim`` of the
        constructor); resets the online state. ``wearpose bench latency miposer_cpu --set mim=true``
        times the step with it.

        Raises:
            ConfigError: ``on`` is not a bool.
        """
        if not isinstance(on, bool):
            raise ConfigError(f"MI-Poser mim: expected true or false, got {on!r}")
        self.mim = on
        self.reset()

    def reset(self) -> None:
        self._R: list[torch.Tensor] = []
        self._p: list[torch.Tensor] = []
        self._input = OnlineInput(self.input_spec.sensor_names, ("position", "orientation"), who="MI-Poser")
        self._mims: list[Any] | None = None
        self._prev_t: float | None = None

    @torch.no_grad()
    def step(self, frame: SensorFrame) -> PoseFrame:
        """One 60 Hz frame (:func:`frames`): headset + wrist EM (+ wrist gyro/accelerometer for MIM)."""
        names = self._input.sensor_names
        (p, R), v = self._input(frame)
        extras: dict[str, Any] = {"frame": "calibrated"}
        if self.mim:
            dt = 1.0 / self.fps if self._prev_t is None else max(1e-4, frame.timestamp - self._prev_t)
            if self._mims is None:
                self._mims = [None] * (len(names) - 1)
            t0 = time.perf_counter()
            R, p, extras["interference"] = step_mim(self._mims, frame, names, self._input.index(frame.names), R, p, dt,
                                                    self.mim_config)
            extras["mim_ms"] = 1000.0 * (time.perf_counter() - t0)  # MIM's share of the step (bench latency stages)
        self._prev_t = frame.timestamp
        wR, wp = em_to_world(R[:1].expand(len(names) - 1, 3, 3), p[:1].expand(len(names) - 1, 3), R[1:], p[1:])
        Rw = torch.cat([R[:1].double(), wR])
        pw = torch.cat([p[:1].double(), wp])
        if self._calibration is not None:
            Rw, pw = apply_miposer(self._calibration, Rw[None], pw[None])
            Rw, pw = Rw[0], pw[0]
        self._R.append(Rw.float())
        self._p.append(pw.float())
        W = self.config.window
        self._R, self._p = self._R[-W:], self._p[-W:]
        Rs, ps = torch.stack(self._R), torch.stack(self._p)
        if Rs.shape[0] < W:  # pad the stream start with the first frame
            k = W - Rs.shape[0]
            Rs, ps = torch.cat([Rs[:1].expand(k, *Rs.shape[1:]), Rs]), torch.cat([ps[:1].expand(k, *ps.shape[1:]), ps])
        self.model.eval()
        x, C, _ = window_features(Rs[None].to(self.device), ps[None].to(self.device), self.fps)
        pose = decode_pose(*self.model(x), C)
        trans = head_anchored_translation(self.body, pose, ps[-1:, 0].to(self.device))
        return PoseFrame(pose[0].cpu(), torch.zeros(10), trans[0].cpu(), bool(v.all()), frame.timestamp, extras=extras)
