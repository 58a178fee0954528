"""BiRAE data synthesis (Sec. III-A): ideal sensor orientations from the motion corpus, augmented
copies (noise, impulses, yaw drift) and the evaluation disturbance scenarios.

Ideal sensors (Sec. III-A: "sensor-to-segment alignment is identity"): each ``mimu6`` sensor's
orientation is the global rotation of the bone its site rides on
(:data:`wearpose.sensors.SITE_SEGMENT`: forearm, shin, head, pelvis), i.e. what
``wearpose.sensors.simulate(..., imu_orientation="segment")`` produces, obtained here directly
by forward kinematics (rotations do not depend on body shape, and skipping the skinning keeps
the synthesis of the 97-minute corpus cheap). Errors are those of
:func:`wearpose.sensors.simulate_mimu` (BiRAE's model, see :mod:`wearpose.sensors.mimu`):

- training augmentation (second phase, Sec. III-A): white orientation noise, impulses and a
  per-sequence yaw drift from an integrated random bias; no magnetic disturbance;
- evaluation scenarios (:data:`SCENARIOS`): ``clean``; ``noise`` (Table 2 analogue, a
  "real sensor" level: 2 deg white noise, impulses, default yaw drift, no disturbance); and
  ``magnetic`` (Table 4 analogue: per-sensor 0.5 deg/s yaw-rate bias integrated from up to 60 s
  before the clip's first frame -- our clips are a few seconds long, the paper's DIP-IMU
  sequences minutes -- plus strong magnetic disturbance episodes drawn independently per
  sensor, ~one every 2 s, 1-4 s long, 0.5-1.5x the horizontal earth field). Every heading error
  is per sensor: a heading error common to all six sensors cancels exactly in Eq. 1 (tested).
  The magnitudes are assumptions (the paper gives none) and are recorded with every result.

Per-clip seeds derive from the clip id and a namespace (:func:`~wearpose.estimators.seeding.clip_seed`
in ``birae:<namespace>``), so data are deterministic and
training draws never repeat evaluation draws. The training split is cached frame-concatenated
under ``<corpus cache>/estimators/birae/`` keyed by a fingerprint of clip ids and settings.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Iterable, Iterator

import numpy as np
import torch

from wearpose.body.kinematics import forward_kinematics
from wearpose.body.skeleton import JOINT_INDEX, NUM_JOINTS
from wearpose.estimators.birae.config import BiraeConfig
from wearpose.estimators.birae.representations import SENSORS, angular_rate, features, pose_to_target, relative_orientations
from wearpose.estimators.clipstore import ClipData, cached_clips, concat_clips, split_source
from wearpose.estimators.seeding import clip_seed
from wearpose.motion import resample
from wearpose.motion.template import default_rest_joints
from wearpose.sensors import SITE_SEGMENT, MimuNoise, get_kit, simulate_mimu

DATA_VERSION = 1
#: Per-frame tensors of the cache, ``(F, ...)``.
DATA_KEYS = ("R_rel", "R_rel_aug", "rate", "rate_aug", "target")


def segment_joints() -> list[int]:
    """SMPL joint per ``mimu6`` sensor (kit order): the bone the sensor's site rides on."""
    kit = get_kit("mimu6")
    return [JOINT_INDEX[SITE_SEGMENT[kit.sensor(n).site]] for n in SENSORS]


def augmentation_noise(cfg: BiraeConfig) -> MimuNoise:
    """The training augmentation of the second phase (no magnetic disturbance, Sec. III-A)."""
    return replace(MimuNoise.none(), orientation_white=math.radians(cfg.aug_white_deg),
                   impulse_prob=cfg.aug_impulse_prob, impulse_sigma=math.radians(cfg.aug_impulse_deg),
                   yaw_bias=math.radians(cfg.aug_yaw_bias_dps), yaw_bias_walk=math.radians(0.01))


#: Evaluation scenarios: name -> MIMU error model (None = ideal). Magnitudes are assumptions.
SCENARIOS: dict[str, MimuNoise | None] = {
    "clean": None,
    "noise": replace(MimuNoise.none(), orientation_white=math.radians(2.0), impulse_prob=0.002,
                     impulse_sigma=math.radians(5.0), yaw_bias=math.radians(0.1), yaw_bias_walk=math.radians(0.01)),
    "magnetic": replace(MimuNoise.none(), orientation_white=math.radians(2.0), impulse_prob=0.002,
                        impulse_sigma=math.radians(5.0), yaw_bias=math.radians(0.5), yaw_bias_walk=math.radians(0.05),
                        mag_rate=0.5, mag_duration=(1.0, 4.0), mag_strength=(0.5, 1.5), yaw_elapsed=60.0),
    # The previous ``magnetic`` scenario (1 deg/s bias, drift from the clip's first frame only),
    # kept as a diagnostic.
    "magnetic_clipstart": replace(MimuNoise.none(), orientation_white=math.radians(2.0), impulse_prob=0.002,
                                  impulse_sigma=math.radians(5.0), yaw_bias=math.radians(1.0),
                                  yaw_bias_walk=math.radians(0.05), mag_rate=0.5, mag_duration=(1.0, 4.0),
                                  mag_strength=(0.5, 1.5)),
}


def scenario_settings(name: str) -> dict[str, Any]:
    """JSON-able description of scenario ``name`` (degrees, per second)."""
    n = SCENARIOS[name]
    if n is None:
        return {"name": name, "ideal": True}
    return {"name": name, "white_deg": math.degrees(n.orientation_white), "impulse_prob": n.impulse_prob,
            "impulse_deg": math.degrees(n.impulse_sigma), "yaw_bias_dps": math.degrees(n.yaw_bias),
            "yaw_bias_walk_dps_per_sqrt_s": math.degrees(n.yaw_bias_walk), "mag_episodes_per_s": n.mag_rate,
            "mag_duration_s": list(n.mag_duration), "mag_strength_x_horizontal_field": list(n.mag_strength),
            "drift_elapsed_before_clip_s": [0.0, n.yaw_elapsed], "per_sensor": True}


def sensor_orientations(pose: torch.Tensor) -> torch.Tensor:
    """Ideal ``mimu6`` orientations ``R_WS`` ``(T, 6, 3, 3)`` from SMPL local rotations ``(T, 24, 3, 3)``."""
    rest = torch.zeros(NUM_JOINTS, 3, dtype=pose.dtype)
    g, _ = forward_kinematics(pose, rest)
    return g[:, segment_joints()]


def sensor_positions(pose: torch.Tensor, trans: torch.Tensor) -> torch.Tensor:
    """Positions ``(T, 6, 3)`` m of the sensors' segment joints (FK on the default body's rest
    skeleton plus the root translation). Only the accelerometer channel depends on them, which
    BiRAE does not use; the skin site would sit a few centimetres away on the real body."""
    rest, _ = default_rest_joints(dtype=pose.dtype)
    _, p = forward_kinematics(pose, rest)
    return p[:, segment_joints()] + trans[:, None, :].to(pose)


def disturb(R_world: torch.Tensor, fps: float, noise: MimuNoise | None, generator: torch.Generator | None,
            positions: torch.Tensor | None = None) -> dict[str, torch.Tensor]:
    """Apply a MIMU error model to ideal orientations ``(T, 6, 3, 3)``
    (:func:`wearpose.sensors.simulate_mimu`; ``positions`` ``(T, 6, 3)`` m feed the inertial
    channels, zeros if omitted).

    Returns:
        simulate_mimu's dict (``orientation``, ``acceleration``, ``angular_velocity``,
        ``magnetic_field``, ``yaw_error`` ...).
    """
    T, S = R_world.shape[:2]
    p = positions if positions is not None else torch.zeros(T, S, 3, dtype=R_world.dtype)
    return simulate_mimu(R_world, p.to(R_world), fps, noise=noise, generator=generator)


def synthesize(motion: Any, rate: float, noise: MimuNoise | None = None, seed: int = 0,
               channels: bool = False) -> dict[str, torch.Tensor]:
    """One clip: resample to ``rate``, ideal sensors, optional errors, Eq. 1, targets.

    Args:
        channels: also simulate the inertial channels (positions by FK) for a full recording.

    Returns:
        ``R_world`` ``(T, 6, 3, 3)`` (measured), ``R_rel`` ``(T, 5, 3, 3)``, ``ang_rate``
        ``(T, 5, 3)`` rad/s, ``target`` ``(T, 15, 3)`` exp-map, ``pose`` ``(T, 24, 3, 3)``
        ground-truth local rotations, ``yaw_error`` ``(T, 6)`` rad, ``motion`` (resampled), and
        with ``channels`` the ``sim`` dict of :func:`disturb`.
    """
    m = motion if abs(motion.fps - rate) < 1e-9 else resample(motion, rate)
    pose = m.pose.float()
    pos = sensor_positions(pose, m.trans.float()) if channels else None
    sim = disturb(sensor_orientations(pose), rate, noise, torch.Generator().manual_seed(int(seed)), pos)
    Rw = sim["orientation"].float()
    Rr = relative_orientations(Rw)
    out = {"R_world": Rw, "R_rel": Rr, "ang_rate": angular_rate(Rr, rate), "target": pose_to_target(pose),
           "pose": pose, "yaw_error": sim["yaw_error"].float(), "motion": m}
    if channels:
        out["sim"] = sim
    return out


def make_recording(R_world: torch.Tensor, fps: float, sim: dict[str, torch.Tensor], motion: Any = None,
                   meta: dict[str, Any] | None = None) -> Any:
    """A ``mimu6`` :class:`~wearpose.recording.Recording` (world, Y up).

    Args:
        R_world: ``(T, 6, 3, 3)`` orientations (kit order).
        sim: the inertial channels of :func:`disturb` (``acceleration``, ``angular_velocity``,
            ``magnetic_field``: a MIMU stream requires them; BiRAE itself reads orientations only).
    """
    # start-up: wearpose.recording adds ~40 ms to importing this module
    from wearpose.recording import Recording, SensorInfo

    kit = get_kit("mimu6")
    infos = [SensorInfo(n, "mimu", kit.sensor(n).site, float(fps), mag_unit="T") for n in SENSORS]
    T = R_world.shape[0]
    ts = np.arange(T, dtype=np.float64) / float(fps)
    ch = {"orientation": R_world.detach().cpu().numpy().astype(np.float32)}
    for c in ("acceleration", "angular_velocity", "magnetic_field"):
        ch[c] = sim[c].detach().cpu().numpy().astype(np.float32)
    return Recording.from_stacked(infos, ts, ch, ground_truth=motion, meta=dict(meta or {}))


@dataclass(kw_only=True)
class BiraeData(ClipData):
    """One split, frame-concatenated.

    Attributes:
        R_rel ``(F, 5, 3, 3)`` clean and R_rel_aug ``(F, 5, 3, 3)`` augmented root-relative
        orientations; rate / rate_aug ``(F, 5, 3)`` rad/s; target ``(F, 15, 3)``; starts,
        lengths ``(C,)``; clip_ids; fingerprint.
    """

    R_rel: torch.Tensor
    R_rel_aug: torch.Tensor
    rate: torch.Tensor
    rate_aug: torch.Tensor
    target: torch.Tensor

    def windows(self, seq_len: int, min_len: int) -> torch.Tensor:
        """``(W, 2)`` (first frame, length) of consecutive non-overlapping subsequences (Sec. IV-E),
        dropping pieces shorter than ``min_len`` (a clip shorter than ``min_len`` is dropped)."""
        out = []
        for c in range(len(self.clip_ids)):
            L, s0 = int(self.lengths[c]), int(self.starts[c])
            for s in range(0, L, seq_len):
                n = min(seq_len, L - s)
                if n >= min_len:
                    out.append((s0 + s, n))
        return torch.tensor(out, dtype=torch.long).reshape(-1, 2)

    def batch(self, win: torch.Tensor, seq_len: int, augmented: bool, cfg: BiraeConfig) -> dict[str, torch.Tensor]:
        """Padded batch: ``x (B, L, D)``, ``y (B, L, 45)``, ``rate (B, L, 15)`` (scaled), ``mask (B, L)``, ``lengths``."""
        L = int(win[:, 1].max())
        idx = win[:, :1] + torch.arange(L)
        mask = torch.arange(L)[None] < win[:, 1:2]
        idx = torch.where(mask, idx, win[:, :1])  # padding repeats the first frame (masked out)
        Rr = (self.R_rel_aug if augmented else self.R_rel)[idx]
        w = (self.rate_aug if augmented else self.rate)[idx]
        x = features(Rr, cfg.rep, w, cfg.rate_scale)
        return {"x": x, "y": self.target[idx].flatten(-2), "rate": (w * cfg.rate_scale).flatten(-2),
                "mask": mask, "lengths": win[:, 1].clone()}

    def iter_batches(self, cfg: BiraeConfig, augmented: bool, generator: torch.Generator | None = None,
                     shuffle: bool = True, skip: int = 0, batch_size: int | None = None) -> Iterator[dict[str, torch.Tensor]]:
        w = self.windows(cfg.seq_len, cfg.min_len)
        bs = batch_size or cfg.batch_size
        order = torch.randperm(len(w), generator=generator) if shuffle else torch.arange(len(w))
        for i in range(skip, math.ceil(len(w) / bs)):
            yield self.batch(w[order[i * bs:(i + 1) * bs]], cfg.seq_len, augmented, cfg)


def data_settings(cfg: BiraeConfig) -> dict[str, Any]:
    """Everything that changes the synthesised data (part of the fingerprint)."""
    return {"version": DATA_VERSION, "kit": cfg.kit, "rate": cfg.rate, "seed": cfg.seed,
            "segments": segment_joints(), "aug": {k: getattr(cfg, k) for k in
                                                  ("aug_white_deg", "aug_impulse_prob", "aug_impulse_deg", "aug_yaw_bias_dps")}}


def build_from_motions(motions: Iterable[Any], ids: list[str], cfg: BiraeConfig, namespace: str = "train",
                       progress: Any = None) -> dict[str, Any]:
    """Synthesise clean + augmented data for ``motions`` (``ids`` seed them). Returns the tensor dict."""
    aug = augmentation_noise(cfg)

    def one(clip: tuple[Any, str]) -> dict[str, torch.Tensor]:
        m, cid = clip
        clean = synthesize(m, cfg.rate, None)
        noisy = synthesize(m, cfg.rate, aug, clip_seed(cid, cfg.seed, f"birae:{namespace}"))
        return {"R_rel": clean["R_rel"], "R_rel_aug": noisy["R_rel"], "rate": clean["ang_rate"],
                "rate_aug": noisy["ang_rate"], "target": clean["target"]}

    return concat_clips(zip(motions, ids), one, DATA_KEYS, total=len(ids), progress=progress)


def build_split(split: str, cfg: BiraeConfig, *, store: Any = None, limit: int | None = None,
                cache_root: str | Path | None = None, progress: Any = None) -> BiraeData:
    """Synthesise (or load from the cache) one corpus split (first ``limit`` sorted clip ids)."""
    settings = data_settings(cfg)
    store, ids, fp, root = split_source(split, settings, "birae", store=store, limit=limit, cache_root=cache_root,
                                        cfg=cfg)
    path = root / f"{split}-{fp[:16]}.pt"
    d = cached_clips(path, ids, fp, lambda: build_from_motions((store.load(c) for c in ids), ids, cfg,
                                                                "train" if split == "train" else split, progress))
    return BiraeData(**{k: d[k] for k in (*DATA_KEYS, "starts", "lengths")}, clip_ids=d["clip_ids"], fingerprint=fp)
