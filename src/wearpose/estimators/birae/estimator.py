"""``BiraeEstimator``: BiRAE behind the :class:`~wearpose.estimators.Estimator` protocol.

Input: kit ``mimu6`` (left/right wrist, left/right lower leg, head, root = lower spine), each
sensor's world orientation ``R_WS`` (DESIGN inertial canonical form; calibrated to its segment,
BiRAE Eq. 2). Only orientations are used (no accelerations, Sec. III-C). Dropped samples are
held at the sensor's last valid orientation; output frames resting on a dropped sample are
``valid = False``.

Output (:class:`~wearpose.estimators.PoseTrack`): local rotations of the 15 major joints from
the predicted exponential maps, every other joint (root included) the identity:
``extras["frame"] = "root"`` (BiRAE predicts the pose "less rotation and translation of root";
:meth:`with_root` puts the root sensor's orientation back). Uncertainty: per joint, the RMS over
the three exp-map components of the combined sigma (Eq. 7-8, MC-dropout with ``mc_samples``
passes), times the post-hoc calibration factor (:mod:`.uncertainty`), radians, in
``PoseTrack.uncertainty`` ``(T, 24)`` (0 for joints not predicted); the per-component sigmas
are in ``extras["sigma"]`` ``(T, 15, 3)`` (combined, calibrated), ``extras["sigma_aleatoric"]``
and ``extras["sigma_epistemic"]``, and ``extras["expmap"]`` ``(T, 15, 3)`` is the mean.

Modes:

- offline (:meth:`estimate`): the whole sequence through the Bi-LSTM end to end (Fig. 3a);
- online (:meth:`step`): a sliding window of ``past`` + 1 + ``future`` frames (Fig. 3b); the
  output for input frame ``t`` is the pose of frame ``t - future`` (``PoseFrame.timestamp`` is
  that frame's time), so latency = ``future / fps`` + compute (:attr:`latency_s`). The first
  ``future`` steps return ``valid=False`` placeholders. :meth:`estimate_windowed` runs the
  same windows over a recording in batches (for evaluation).
- online, streamed (``online="stream"``, :mod:`.streaming`): the same future window, the
  forward directions carried from frame to frame instead of re-run over the past (64 LSTM steps
  per frame instead of 644 at [130, 30]) and one deterministic pass: sigma is the aleatoric head
  times the calibration scale (``mc_samples`` does not apply). A different computation from the
  window mode (its first output frame is the same); :meth:`estimate_streamed` is its batched form.

Frame rate (Sec. V-E): the recurrent model accepts any input rate; :meth:`estimate` runs at the
recording's rate without resampling (the angular-rate input of ``3param_rate`` is in rad/s, so it
stays consistent); the online window is given in frames at the trained rate and scaled to the
input rate.
"""

from __future__ import annotations

import math
from collections import deque
from pathlib import Path
from typing import Any, Mapping

import numpy as np
import torch

from wearpose.errors import ShapeError
from wearpose.estimators.base import Estimator, PoseFrame, PoseTrack, SensorFrame
from wearpose.estimators.birae.config import BiraeConfig
from wearpose.estimators.birae.model import BiRAE
from wearpose.estimators.birae.representations import (
    SENSORS, angular_rate, features, relative_orientations, target_to_pose,
)
from wearpose.estimators.birae.streaming import StreamState, stream_predict, stream_step
from wearpose.estimators.birae.uncertainty import combine, mc_predict
from wearpose.estimators.checkpoint import Checkpoint, NetworkCheckpointing, load_checkpoint
from wearpose.estimators.inputs import InputSpec, OnlineInput, prepare
from wearpose.estimators.registry import register_estimator
from wearpose.body.skeleton import MAJOR_JOINTS, NUM_JOINTS
from wearpose.estimators.birae.data import augmentation_noise
from wearpose.estimators.birae.train import finetune, train_birae
from wearpose.estimators.seeding import init_seed, seeded
from wearpose.estimators.trainmix import mix_clause


@register_estimator("birae")
class BiraeEstimator(NetworkCheckpointing, Estimator):
    """BiRAE estimator (see module doc).

    Args:
        config: :class:`BiraeConfig` (default: ``cpu`` preset, 6-param input).
        device: torch device.
        window: online (past, future) frames at the trained rate (default ``config.window``).
        online: ``"window"`` (re-run the window each frame, MC-dropout) or ``"stream"``
            (incremental, aleatoric sigma; module doc).
    """

    name = "birae"
    causal = False
    lookahead = 30  # default future window at 60 Hz; the instance attribute follows the config

    def __init__(self, config: BiraeConfig | None = None, device: str | torch.device = "cpu",
                 window: tuple[int, int] | None = None, online: str = "window") -> None:
        self.config = config or BiraeConfig.preset("cpu")
        self.device = torch.device(device)
        self.kit_name = self.config.kit
        self.sensor_names = SENSORS
        self.body_asset_id = "none"  # joint rotations only: no body asset in the model or its data
        self.fps = float(self.config.rate)
        with seeded(init_seed(self.config.seed)):  # initial weights: a function of the seed (issue 24)
            self.model = BiRAE(self.config).to(self.device)
        self.sigma_scale = 1.0
        self.calibration: dict[str, Any] = {}
        self.data_fingerprint = ""
        self.train_command = ""
        self.meta: dict[str, Any] = {}
        self.mc_samples = self.config.mc_samples
        self.seed = 0
        self.set_window(*(window or self.config.window))
        self.set_online(online)
        self.reset()

    # ------------------------------------------------------------------ settings
    def set_window(self, past: int, future: int) -> None:
        """Online window in frames at the trained rate; ``lookahead`` = ``future``."""
        if past < 0 or future < 0:
            raise ShapeError(f"BiRAE window: expected (past, future) >= 0 frames, got ({past}, {future})")
        self.window = (int(past), int(future))
        self.lookahead = int(future)

    def set_online(self, mode: str) -> None:
        """``"window"`` or ``"stream"`` (module doc); resets the online state."""
        if mode not in ("window", "stream"):
            raise ShapeError(f"BiRAE online mode: expected 'window' or 'stream', got {mode!r}")
        self.online = mode
        self.reset()

    @property
    def latency_s(self) -> float:
        """Algorithmic latency of :meth:`step` (the future window), seconds, excluding compute."""
        return self.window[1] / self.fps

    # ------------------------------------------------------------------ checkpoints
    def to(self, device: str | torch.device) -> BiraeEstimator:
        """Move the network to ``device`` (BiRAE has no body model); returns the estimator."""
        self.device = torch.device(device)
        self.model.to(self.device)
        return self

    def checkpoint(self, meta: dict[str, Any] | None = None, train_state: dict[str, Any] | None = None) -> Checkpoint:
        """:meth:`NetworkCheckpointing.checkpoint` with the uncertainty scale and calibration in the meta."""
        return super().checkpoint({"sigma_scale": self.sigma_scale, "calibration": self.calibration, **(meta or {})},
                                  train_state)

    @classmethod
    def from_checkpoint(cls, ckpt: Checkpoint, *, kit: str | None = None, device: str | torch.device = "cpu",
                        path: str | Path = "<checkpoint>") -> BiraeEstimator:
        ckpt.check(method=cls.name, kit=kit, path=path)
        est = cls(BiraeConfig.from_dict(ckpt.config), device=device)
        ckpt.check(sensors=list(est.sensor_names), path=path)
        est.restore(ckpt)
        est.body_asset_id = ckpt.body_asset
        est.sigma_scale = float(ckpt.meta.get("sigma_scale", 1.0))
        est.calibration = dict(ckpt.meta.get("calibration") or {})
        return est

    @classmethod
    def load(cls, path: str | Path, *, kit: str | None = None, body: Any = None,
             map_location: str | torch.device = "cpu") -> BiraeEstimator:
        """Read a checkpoint (``body`` is accepted for the protocol; BiRAE's output does not
        depend on a body asset: it predicts joint rotations only)."""
        return cls.from_checkpoint(load_checkpoint(path, map_location), kit=kit, device=map_location, path=path)

    def fit(self, *args: Any, **kwargs: Any) -> Any:
        """Train (see :func:`wearpose.estimators.birae.train.train_birae`)."""
        return train_birae(self, *args, **kwargs)

    @classmethod
    def training_data_description(cls, config: Mapping[str, Any]) -> str | None:
        """The card sentence (:meth:`Estimator.training_data_description`) of
        :func:`wearpose.estimators.birae.data.build_split` and the two training phases."""
        cfg = BiraeConfig.from_dict(dict(config))
        walk = math.degrees(augmentation_noise(cfg).yaw_bias_walk)  # not a config field: read it where it is set
        text = (f"ideal {cfg.kit} segment orientations by forward kinematics ({cfg.rate:g} Hz), root-relative, "
                f"input representation {cfg.rep}, subsequences of {cfg.seq_len} frames (pieces under {cfg.min_len} "
                f"frames dropped)")
        if cfg.train_clips > 0:
            text += f", first {cfg.train_clips} train clips only"
        return text + (f"; phase 1 ideal, phase 2 one seeded augmented copy per clip: {cfg.aug_white_deg:g} deg white "
                       f"orientation noise, impulses (p={cfg.aug_impulse_prob:g} per frame, {cfg.aug_impulse_deg:g} deg), "
                       f"per-sensor yaw drift from a random yaw-rate bias (std {cfg.aug_yaw_bias_dps:g} deg/s, random "
                       f"walk {walk:.2g} deg/s/sqrt(s)), no magnetic disturbance (wearpose.estimators.birae.data)"
                       + mix_clause(cfg))

    def finetune(self, motions: Any, out_dir: str | Path, **kwargs: Any) -> Any:
        """Fine-tune on target-domain motions (see :func:`wearpose.estimators.birae.train.finetune`)."""
        return finetune(self, motions, out_dir, **kwargs)

    # ------------------------------------------------------------------ inputs
    @property
    def input_spec(self) -> InputSpec:
        """What :meth:`estimate` reads: the kit's MIMU (or IMU) orientations ``R_WS``, any rate."""
        return InputSpec.from_kit("BiRAE", self.kit_name, ("orientation",), sensor_names=tuple(self.sensor_names),
                                  kinds={"mimu": ("mimu", "imu"), "imu": ("mimu", "imu")})

    def _inputs(self, recording: Any) -> tuple[torch.Tensor, torch.Tensor, float, np.ndarray]:
        x = prepare(recording, self.input_spec)
        fps = float(recording.sensor(self.sensor_names[0]).info.rate)
        return x.channels["orientation"], x.valid.all(1), fps, x.timestamps

    def _features(self, R_world: torch.Tensor, fps: float) -> torch.Tensor:
        Rr = relative_orientations(R_world)
        rate = angular_rate(Rr, fps) if self.config.uses_rate else None
        return features(Rr, self.config.rep, rate, self.config.rate_scale)

    def _track(self, pred: dict[str, torch.Tensor], valid: torch.Tensor, fps: float, mode: str) -> PoseTrack:
        mu = pred["mu"].reshape(-1, 15, 3)
        sig = pred["sigma"].reshape(-1, 15, 3) * self.sigma_scale
        T = mu.shape[0]
        unc = torch.zeros(T, NUM_JOINTS)
        unc[:, list(MAJOR_JOINTS)] = sig.pow(2).mean(-1).sqrt()
        return PoseTrack(target_to_pose(mu), torch.zeros(10), None, valid, fps, uncertainty=unc,
                         extras={"frame": "root", "method": self.name, "mode": mode, "uncertainty_unit": "rad",
                                 "uncertainty_joints": list(MAJOR_JOINTS), "expmap": mu, "sigma": sig,
                                 "sigma_aleatoric": pred["sigma_a"].reshape(-1, 15, 3) * self.sigma_scale,
                                 "sigma_epistemic": pred["sigma_e"].reshape(-1, 15, 3) * self.sigma_scale,
                                 "sigma_scale": self.sigma_scale, "mc_samples": self.mc_samples,
                                 "rep": self.config.rep})

    # ------------------------------------------------------------------ offline
    @torch.no_grad()
    def predict(self, x: torch.Tensor, mc_samples: int | None = None) -> dict[str, torch.Tensor]:
        """Raw prediction for features ``(B, T, D)``: ``mu``, ``sigma`` (Eq. 8), ``sigma_a``, ``sigma_e`` ``(B, T, 45)``
        (uncalibrated). ``mc_samples`` 0 = deterministic pass, aleatoric only."""
        M = self.mc_samples if mc_samples is None else mc_samples
        self.model.eval()
        if M <= 0:
            out = self.model(x.to(self.device))
            sa = torch.exp(0.5 * out["logvar"]).cpu()
            return {"mu": out["mu"].cpu(), "sigma": sa, "sigma_a": sa, "sigma_e": torch.zeros_like(sa)}
        g = torch.Generator(device=self.device).manual_seed(self.seed)
        mus, lvs = mc_predict(self.model, x.to(self.device), M, generator=g)
        return {k: v.cpu() for k, v in combine(mus, lvs).items()}

    @torch.no_grad()
    def estimate(self, recording: Any, mc_samples: int | None = None) -> PoseTrack:
        """Offline, end-to-end bidirectional estimate of a whole recording (module doc)."""
        R, ok, fps, _ = self._inputs(recording)
        x = self._features(R, fps)[None]
        return self._track({k: v[0] for k, v in self.predict(x, mc_samples).items()}, ok, fps, "offline")

    @torch.no_grad()
    def estimate_windowed(self, recording: Any, window: tuple[int, int] | None = None, mc_samples: int | None = None,
                          frames: Any = None, batch: int = 64) -> PoseTrack:
        """What :meth:`step` would output, computed in batches: for every frame ``t`` the
        window ``[t - past, t + future]`` (clipped to the sequence) is run and its frame ``t``
        kept. ``frames``: optional subset of frame indices (others are marked invalid and hold
        the identity pose / zero sigma)."""
        R, ok, fps, _ = self._inputs(recording)
        past, fut = self._scaled_window(window or self.window, fps)
        x = self._features(R, fps)
        T = x.shape[0]
        idx = torch.arange(T) if frames is None else torch.as_tensor(frames, dtype=torch.long)
        mu = torch.zeros(T, 45)
        sg, sa, se = torch.zeros(T, 45), torch.zeros(T, 45), torch.zeros(T, 45)
        for a in range(0, len(idx), batch):
            ts = idx[a:a + batch]
            lo = (ts - past).clamp_min(0)
            hi = (ts + fut).clamp_max(T - 1)
            L = int((hi - lo).max()) + 1
            gather = (lo[:, None] + torch.arange(L)).clamp_max(T - 1)
            lengths = hi - lo + 1
            xb = x[gather]
            # Only the window is seen: frames beyond its end are excluded by packing.
            self.model.eval()
            M = self.mc_samples if mc_samples is None else mc_samples
            pred = self._predict_packed(xb, lengths, M)
            pos = ts - lo
            rows = torch.arange(len(ts))
            mu[ts] = pred["mu"][rows, pos]
            sg[ts], sa[ts], se[ts] = pred["sigma"][rows, pos], pred["sigma_a"][rows, pos], pred["sigma_e"][rows, pos]
        valid = ok.clone()
        if frames is not None:
            keep = torch.zeros(T, dtype=torch.bool)
            keep[idx] = True
            valid &= keep
        return self._track({"mu": mu, "sigma": sg, "sigma_a": sa, "sigma_e": se}, valid, fps, f"window{past},{fut}")

    @torch.no_grad()
    def estimate_streamed(self, recording: Any, frames: Any = None, batch: int = 256) -> PoseTrack:
        """What :meth:`step` outputs with ``online="stream"``, computed in batches (evaluation).
        ``frames``: optional subset of frame indices (others invalid, identity pose, zero sigma).
        Frames within ``future`` of the end use the future that exists."""
        R, ok, fps, _ = self._inputs(recording)
        _, fut = self._scaled_window(self.window, fps)
        x = self._features(R, fps)
        T = x.shape[0]
        idx = torch.arange(T) if frames is None else torch.as_tensor(frames, dtype=torch.long)
        self.model.eval()
        mu_k, lv_k = stream_predict(self.model, x.to(self.device), fut, idx, batch)
        mu, sa = torch.zeros(T, 45), torch.zeros(T, 45)
        mu[idx], sa[idx] = mu_k.cpu(), torch.exp(0.5 * lv_k).cpu()
        valid = ok.clone()
        if frames is not None:
            keep = torch.zeros(T, dtype=torch.bool)
            keep[idx] = True
            valid &= keep
        return self._track({"mu": mu, "sigma": sa, "sigma_a": sa, "sigma_e": torch.zeros_like(sa)}, valid, fps,
                           f"stream{fut}")

    def _predict_packed(self, xb: torch.Tensor, lengths: torch.Tensor, M: int) -> dict[str, torch.Tensor]:
        if M <= 0:
            out = self.model(xb.to(self.device), lengths)
            s = torch.exp(0.5 * out["logvar"]).cpu()
            return {"mu": out["mu"].cpu(), "sigma": s, "sigma_a": s, "sigma_e": torch.zeros_like(s)}
        g = torch.Generator(device=self.device).manual_seed(self.seed)
        mus, lvs = mc_predict(self.model, xb.to(self.device), M, lengths=lengths, generator=g)
        return {k: v.cpu() for k, v in combine(mus, lvs).items()}

    def _scaled_window(self, window: tuple[int, int], fps: float) -> tuple[int, int]:
        k = fps / self.fps
        return int(round(window[0] * k)), int(round(window[1] * k))

    def with_root(self, track: PoseTrack, recording: Any) -> PoseTrack:
        """The track with the root sensor's world orientation as root (sensor = pelvis segment)."""
        R, _, _, _ = self._inputs(recording)
        rot = track.local_rot.clone()
        rot[:, 0] = R[:, list(self.sensor_names).index("root")]
        return PoseTrack(rot, track.betas.clone(), track.trans, track.valid.clone(), track.fps, track.uncertainty,
                         {**track.extras, "frame": "world"})

    # ------------------------------------------------------------------ online
    def reset(self) -> None:
        self._buf: deque[tuple[float, torch.Tensor, bool]] = deque()
        self._input = OnlineInput(self.sensor_names, ("orientation",), who="BiRAE", nan_to_zero=("orientation",))
        self._prev_rel: torch.Tensor | None = None
        self._stream: StreamState | None = None

    @torch.no_grad()
    def step(self, frame: SensorFrame, fps: float | None = None) -> PoseFrame:
        """Feed one input frame; returns the pose of the frame ``future`` steps back (module doc).

        Args:
            frame: the newest :class:`SensorFrame` (``orientation`` channel, kit sensors).
            fps: input rate (default: the trained rate); scales the window and the angular rate.
        """
        fps = float(fps or self.fps)
        (R,), v = self._input(frame)
        Rr = relative_orientations(R)
        rate = None
        if self.config.uses_rate:
            rate = angular_rate(torch.stack([self._prev_rel if self._prev_rel is not None else Rr, Rr]), fps)[1]
        self._prev_rel = Rr
        past, fut = self._scaled_window(self.window, fps)
        self._buf.append((frame.timestamp, features(Rr, self.config.rep, rate, self.config.rate_scale), bool(v.all())))
        keep = (fut + 1) if self.online == "stream" else (past + fut + 1)
        while len(self._buf) > keep:
            self._buf.popleft()
        n = len(self._buf)
        k = n - 1 - fut  # position of the output frame in the buffer
        streamed = None
        if self.online == "stream":
            if self._stream is None or self._stream.future != fut:
                self._stream = StreamState(fut)
            self.model.eval()
            streamed = stream_step(self.model, self._buf[-1][1].to(self.device), self._stream)
        if k < 0:
            return PoseFrame(torch.eye(3).expand(NUM_JOINTS, 3, 3).clone(), torch.zeros(10), None, False,
                             frame.timestamp - fut / fps, extras={"frame": "root", "warming_up": True})
        if streamed is not None:
            mu = streamed[0].cpu().reshape(15, 3)
            sig = torch.exp(0.5 * streamed[1].cpu()).reshape(15, 3) * self.sigma_scale
        else:
            x = torch.stack([b[1] for b in self._buf])[None]
            pred = self.predict(x)
            mu = pred["mu"][0, k].reshape(15, 3)
            sig = pred["sigma"][0, k].reshape(15, 3) * self.sigma_scale
        unc = torch.zeros(NUM_JOINTS)
        unc[list(MAJOR_JOINTS)] = sig.pow(2).mean(-1).sqrt()
        return PoseFrame(target_to_pose(mu), torch.zeros(10), None, self._buf[k][2], self._buf[k][0], unc,
                         extras={"frame": "root", "expmap": mu, "sigma": sig, "latency_frames": fut, "online": self.online})
