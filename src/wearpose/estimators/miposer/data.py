"""MI-Poser data: corpus clips -> simulated headset + wrist EM sensors -> T-pose calibration ->
calibrated 6-DoF inputs, cached on disk.

Per clip (sorted ids of one :class:`~wearpose.motion.CorpusStore` split):

1. resample to ``cfg.rate`` (60 Hz, Sec. 4.2) and put ``cfg.tpose_s`` of the calibration T-pose
   in front, facing the clip's initial heading, blended into the first frame over
   ``cfg.blend_s`` (:func:`tpose_then`): the wearer's calibration of Sec. 4.2, then the motion;
2. simulate the kit (``miposer`` / ``miposer1``: head VIO, wrist EM relative to the head-worn
   source) with :func:`wearpose.sensors.simulate` (noise ``cfg.train_noise``, a random subject's
   EM sensor offsets; seed from the clip id) and wrap it in a
   :class:`~wearpose.recording.Recording`;
3. calibrate on the T-pose window with :func:`wearpose.calibration.calibrate`
   (``"miposer-tpose"``: arm-span scale, world alignment, per-sensor offsets) and map every
   frame through it (:func:`calibrated_inputs`): head and wrist target-joint poses in the
   calibrated world (subject facing +Z at the T-pose, model scale);
4. ground truth: the clip's local joint rotations with the root orientation expressed in the
   same calibrated world, ``R_root^cal = R^{WM} R_root`` (the VIO world is the corpus world up
   to its drift, so the calibration's alignment is also the ground truth's).

Training windows (:meth:`MiposerData.windows`) are the ``cfg.window`` frames ending at every
``cfg.stride``-th frame (the T-pose prefix gives the first clip frames a full history); the target
is the pose at the window's last frame (AvatarPoser predicts the current frame).
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterator, Sequence

import torch

from wearpose.calibration import CalibrationResult, apply_miposer, calibrate, em_to_world
from wearpose.estimators.clipstore import ClipData, cached_clips, concat_clips, kit_sites, num_batches, split_source
from wearpose.estimators.seeding import clip_seed
from wearpose.estimators.inputs import InputSpec, hold_last_valid, prepare
from wearpose.estimators.miposer.config import PREDICTED_JOINTS, MiposerConfig
from wearpose.estimators.trainmix import clip_body
from wearpose.geometry import matrix_to_rot6d
from wearpose.motion import resample
from wearpose.recording import Recording
from wearpose.recording.tpose import tpose_then
from wearpose.sensors import get_kit, simulate

DATA_VERSION = 1


def input_spec(kit: str, rate: float = 60.0) -> InputSpec:
    """What MI-Poser reads of ``kit``: the headset (``vio``, first) at ``rate`` Hz and the wrist EM
    sensors (kit order, relative to the head-worn source or in the world) at any rate, sampled at
    the headset's instants (``align="first"``: exact in simulation; a sample further than
    :data:`~wearpose.estimators.inputs.ALIGN_TOLERANCE_S` counts as dropped). The kit's wrist IMUs
    (MIM's input) are not required."""
    k = get_kit(kit)
    names = (*(s.name for s in k.sensors if s.kind == "vio"), *(s.name for s in k.sensors if s.kind == "em6dof"))
    return InputSpec.from_kit("MI-Poser", kit, ("position", "orientation"), sensor_names=names,
                              rates={"vio": float(rate)}, align="first")


def raw_inputs(recording: Any, kit: str, rate: float = 60.0,
               before_grid: Callable[[Any], Any] | None = None) -> dict[str, torch.Tensor]:
    """Headset and wrist sensor poses in the headset's world, on the headset's time grid.

    The recording goes through :func:`wearpose.estimators.inputs.prepare` (:func:`input_spec`;
    ``before_grid``: a step on the canonical recording first, e.g. MIM). Wrist EM poses relative
    to the head-worn source (DESIGN: EM canonical form) are composed with the headset pose
    (:func:`wearpose.calibration.em_to_world`), in float64. A wrist sample counts as dropped
    when the headset's is; dropped samples are then held at the last valid composed one
    (:func:`~wearpose.estimators.inputs.hold_last_valid`).

    Returns:
        ``{"t": (T,) s, "R": (T, S, 3, 3), "p": (T, S, 3) m, "valid": (T, S), "recording":
        the canonical recording the grid was taken from}``, head first.

    Raises:
        ShapeError: missing sensors, or a headset not at ``rate`` Hz (naming the recording).
    """
    spec = input_spec(kit, rate)
    x = prepare(recording, spec, hold=False, before_grid=before_grid, dtype=torch.float64)
    R, p, valid = x.channels["orientation"], x.channels["position"], x.valid.clone()
    valid[:, 1:] &= valid[:, :1]
    for j, n in enumerate(spec.sensor_names[1:], start=1):
        if (x.recording.sensor(n).info.reference or "source") == "source":
            R[:, j], p[:, j] = em_to_world(R[:, 0], p[:, 0], R[:, j], p[:, j])
    p, R = hold_last_valid(p, valid), hold_last_valid(R, valid)
    return {"t": torch.as_tensor(x.timestamps), "R": R, "p": p, "valid": valid, "recording": x.recording}


def uncalibrated(res: CalibrationResult) -> CalibrationResult:
    """The "without sensor-position calibration" condition of Fig. 5: ``res``'s world alignment
    (heading and origin) kept, but scale 1 and no per-sensor offsets (sensor poses taken as the
    target joints' poses)."""
    S = len(res.sensors)
    head = res.extras.get("head_position")
    wt = res.world_translation
    if head is not None:  # origin shift for scale 1: h - R p_head
        h = res.world_translation[0] + res.scale * (res.world_rotation[0] @ torch.as_tensor(head, dtype=wt.dtype))
        wt = (h - res.world_rotation[0] @ torch.as_tensor(head, dtype=wt.dtype)).expand(S, 3).clone()
    return CalibrationResult(res.method, res.sensors, rotation=torch.eye(3, dtype=res.rotation.dtype).expand(S, 3, 3).clone(),
                             translation=torch.zeros(S, 3, dtype=res.translation.dtype), world_rotation=res.world_rotation,
                             world_translation=wt, scale=1.0, extras=dict(res.extras), quality=dict(res.quality),
                             params={**res.params, "uncalibrated": True})


def calibrated_inputs(raw: dict[str, torch.Tensor], res: CalibrationResult) -> tuple[torch.Tensor, torch.Tensor]:
    """Target-joint poses ``(R (T, S, 3, 3), p (T, S, 3))`` float32 in the calibrated world from
    :func:`raw_inputs` (:func:`wearpose.calibration.apply_miposer`)."""
    R, p = apply_miposer(res, raw["R"], raw["p"])
    return R.float(), p.float()


def simulate_clip(motion: Any, cfg: MiposerConfig, body: Any, seed: int, noise: str | None = None,
                  native_rates: bool = False) -> dict[str, Any]:
    """Steps 1-4 of the module doc for one clip.

    Args:
        motion: the clip. cfg: data settings. body: the body the sensors are worn on.
        seed: simulation seed. noise: override ``cfg.train_noise``.
        native_rates: simulate the kit at its own rates (EM 120 Hz, as a device streams) instead
            of everything at ``cfg.rate`` (cheaper, for training).

    Returns:
        dict: ``recording`` (:class:`~wearpose.recording.Recording`, ground truth = the motion
        with its T-pose prefix), ``calibration``, ``raw`` (:func:`raw_inputs`), ``R``/``p``
        calibrated inputs ``(T, S, 3, 3)``/``(T, S, 3)``, ``valid`` ``(T, S)``, ``pose``
        ``(T, 24, 3, 3)`` local rotations with the root in the calibrated world, ``betas``,
        ``prefix`` frames before the clip, ``motion`` (with prefix, at ``cfg.rate``), ``sim``.
    """
    m = motion if abs(motion.fps - cfg.rate) < 1e-9 else resample(motion, cfg.rate)
    mm, prefix = tpose_then(m, cfg.tpose_s, cfg.blend_s)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sim = simulate(mm, cfg.kit, body, seed=seed, noise=noise or cfg.train_noise, offsets="random",
                       rate=None if native_rates else cfg.rate)
    rec = Recording.from_simulation(sim, mm)
    hold = int(round(cfg.tpose_s * cfg.rate))
    window = (min(0.1, 0.25 * cfg.tpose_s), max(hold - 1, 1) / cfg.rate)
    res = calibrate(rec, "miposer-tpose", window=window, body=body)
    raw = raw_inputs(rec, cfg.kit, cfg.rate)
    R, p = calibrated_inputs(raw, res)
    pose = mm.pose.float().clone()
    pose[:, 0] = res.world_rotation[0].float() @ pose[:, 0]
    return {"recording": rec, "calibration": res, "raw": raw, "R": R, "p": p, "valid": raw["valid"], "pose": pose,
            "betas": mm.betas.float(), "prefix": prefix, "motion": mm, "sim": sim}


@dataclass(kw_only=True)
class MiposerData(ClipData):
    """One split, simulated, calibrated and frame-concatenated.

    Attributes:
        R ``(F, S, 3, 3)``, p ``(F, S, 3)``: calibrated inputs (head first); valid ``(F, S)``;
        pose6 ``(F, 22, 6)`` ground-truth local rotations (root in the calibrated world);
        in_clip ``(F,)`` False on the T-pose prefix; clip ``(F,)``; starts, lengths ``(C,)``;
        clip_ids; fingerprint; settings.
    """

    R: torch.Tensor
    p: torch.Tensor
    valid: torch.Tensor
    pose6: torch.Tensor
    in_clip: torch.Tensor
    clip: torch.Tensor

    def windows(self, window: int, stride: int, clip_only: bool = False) -> torch.Tensor:
        """``(N,)`` last frame of every ``window``-frame window inside one clip, every ``stride``
        frames (``clip_only``: only windows ending on a clip frame, not on the T-pose prefix)."""
        out = []
        for c in range(len(self.clip_ids)):
            s, L = int(self.starts[c]), int(self.lengths[c])
            if L < window:  # a clip shorter than one window gives none
                continue
            out.append(torch.arange(s + window - 1, s + L, max(1, stride)))
        ends = torch.cat(out) if out else torch.zeros(0, dtype=torch.long)
        return ends[self.in_clip[ends]] if clip_only else ends

    def batch(self, ends: torch.Tensor, window: int) -> dict[str, torch.Tensor]:
        """Windows ending at ``ends`` ``(B,)``: ``R`` ``(B, W, S, 3, 3)``, ``p`` ``(B, W, S, 3)``,
        ``valid`` ``(B, W, S)``, ``pose6`` ``(B, W, 22, 6)``, ``in_clip`` ``(B, W)``."""
        idx = ends[:, None] - torch.arange(window - 1, -1, -1)
        return {"R": self.R[idx], "p": self.p[idx], "valid": self.valid[idx], "pose6": self.pose6[idx],
                "in_clip": self.in_clip[idx]}

    def iter_batches(self, window: int, stride: int, batch_size: int, generator: torch.Generator | None = None,
                     shuffle: bool = True, skip: int = 0, clip_only: bool = False) -> Iterator[dict[str, torch.Tensor]]:
        ends = self.windows(window, stride, clip_only)
        order = torch.randperm(len(ends), generator=generator) if shuffle else torch.arange(len(ends))
        for i in range(skip, num_batches(len(ends), batch_size) if shuffle else math.ceil(len(ends) / batch_size)):
            yield self.batch(ends[order[i * batch_size:(i + 1) * batch_size]], window)


def data_settings(cfg: MiposerConfig, body: Any) -> dict[str, Any]:
    """Everything that changes the simulated data (part of the fingerprint)."""
    return {"version": DATA_VERSION, "kit": cfg.kit, "rate": cfg.rate, "noise": cfg.train_noise, "seed": cfg.seed,
            "tpose_s": cfg.tpose_s, "blend_s": cfg.blend_s, "body_asset": body.asset_id, "sites": kit_sites(cfg.kit, body),
            "root_frame": "calibrated"}


def build_split(split: str, cfg: MiposerConfig, body: Any, *, store: Any = None, limit: int | None = None,
                clip_ids: Sequence[str] | None = None, cache_root: str | Path | None = None,
                progress: Any = None) -> MiposerData:
    """Simulate and calibrate (or load from the cache) one corpus split (module doc).

    Args:
        split: ``train`` / ``val`` / ``test``. cfg, body: data settings and body.
        store: :class:`~wearpose.motion.CorpusStore` (default: the prepared cache).
        limit: first ``limit`` clips (sorted ids). clip_ids: explicit clips instead of the split's.
        cache_root: tensor cache directory (default ``<corpus cache>/estimators/miposer``).
        progress: optional ``progress(done, total)``.
    """
    settings = data_settings(cfg, body)
    store, ids, fp, root = split_source(split, settings, "miposer", store=store, limit=limit, cache_root=cache_root,
                                        clip_ids=clip_ids, cfg=cfg, body=body)

    def one(cid: str) -> dict[str, torch.Tensor]:
        r = simulate_clip(store.load(cid), cfg, clip_body(store, cid, body), clip_seed(cid, cfg.seed, "miposer"))
        inc = torch.ones(r["R"].shape[0], dtype=torch.bool)
        inc[: r["prefix"]] = False
        return {"R": r["R"], "p": r["p"], "valid": r["valid"], "pose6": matrix_to_rot6d(r["pose"][:, :PREDICTED_JOINTS]),
                "in_clip": inc}

    return cached_split(root / f"{split}-{fp[:16]}.pt", ids, one, fp, settings, progress)


def cached_split(path: Path, ids: Sequence[str], clip_fn: Any, fp: str, settings: dict[str, Any],
                 progress: Any = None) -> MiposerData:
    """Load ``path`` or build it: ``clip_fn(clip_id)`` gives one clip's per-frame tensors
    (``R``, ``p``, ``valid``, ``pose6``, ``in_clip``); they are concatenated and saved atomically
    (:mod:`wearpose.estimators.clipstore`)."""
    frames = ("R", "p", "valid", "pose6", "in_clip")
    d = cached_clips(path, ids, fp, lambda: concat_clips(ids, clip_fn, frames, clip_column=True, progress=progress))
    return MiposerData(**{k: d[k] for k in (*frames, "clip", "starts", "lengths")}, clip_ids=d["clip_ids"],
                       fingerprint=fp, settings=settings)
