"""Training data for EM-POSE: virtual EM sensors simulated from corpus clips, cached on disk.

Per clip (sorted clip ids of one split of :class:`~wearpose.motion.CorpusStore`):

1. resample to ``cfg.rate`` (30 Hz by default: the rate of the paper's test set, Sec. 4.2,
   and half the cost of 60 Hz);
2. draw a synthetic subject's offsets ``O_p`` for this sequence
   (:func:`wearpose.sensors.random_subject_offsets`, with the per-sequence translation draw of
   supp. Sec. 2.2) and simulate the kit with :func:`wearpose.sensors.simulate` (EM noise model
   ``cfg.train_noise``); seeds derive from the clip id, so the data are deterministic;
3. normalise (supp. Sec. 2.1): measurements are already relative to the EM source on the lower
   back (root translation removed, rotated into the body-fixed source frame at every frame); the
   ground-truth root orientation is expressed in the same source frame,
   ``R_root^n(t) = R_src(t)^T R_root(t)``, and the root translation set to zero;
4. dropped EM frames (NaN, ``valid`` False) are held at the sensor's last valid value
   (:func:`wearpose.estimators.inputs.hold_last_valid`), the same policy the estimator applies at run time.

Everything is stored frame-concatenated in one tensor file under
``<cache>/estimators/empose/<split>-<fingerprint[:16]>.pt`` keyed by the fingerprint of the clip
ids and all simulation settings, so epochs never re-simulate.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterator

import torch

from wearpose.estimators.clipstore import ClipData, cached_clips, concat_clips, kit_sites, num_batches, split_source
from wearpose.estimators.empose.config import EmposeConfig
from wearpose.estimators.inputs import hold_last_valid
from wearpose.estimators.seeding import clip_seed
from wearpose.estimators.trainmix import clip_body
from wearpose.geometry import matrix_to_rot6d, rot6d_to_matrix
from wearpose.motion import resample
from wearpose.recording import Recording
from wearpose.sensors import simulate
from wearpose.sensors.em import EMOffsets, random_subject_offsets
from wearpose.sensors.simulate import _generator

DATA_VERSION = 1
#: Per-frame tensors of the cache (``(F, ...)``; with ``clip`` ``(F,)``) and per-clip ones (``(C, ...)``).
FRAME_KEYS = ("position", "orientation", "valid", "pose6", "joints")
CLIP_KEYS = ("betas", "off_R", "off_t")


def rotation_only_offsets(num_sensors: int, seed: int) -> Any:
    """The synthetic subject that ``simulate(..., offsets="random", seed=seed)`` draws, with its
    translations (and their per-sequence jitter) set to zero: EM-POSE's "no t" training scheme
    (Table 3). Returns a :class:`~wearpose.sensors.em.EMOffsets`."""

    full = random_subject_offsets(num_sensors, _generator(seed, "subject"))
    return EMOffsets(full.R, torch.zeros_like(full.t))


def simulate_clip(motion: Any, cfg: EmposeConfig, body: Any, seed: int, noise: str | None = None,
                  offsets: Any = None) -> dict[str, Any]:
    """Simulate one clip for EM-POSE (module doc, steps 1-3).

    ``offsets`` (default ``cfg.offsets``): ``"random"`` a synthetic subject drawn from ``seed``,
    ``"rot"`` its rotations only (:func:`rotation_only_offsets`), ``"none"`` identity, or an
    :class:`~wearpose.sensors.em.EMOffsets` (e.g. a subject from another distribution, Table 4).

    Returns:
        dict: ``position`` ``(T, S, 3)`` m and ``orientation`` ``(T, S, 3, 3)`` source frame
        (raw, NaN where dropped), ``valid`` ``(T, S)``, ``pose`` ``(T, 24, 3, 3)`` local rotations
        with the root in the source frame, ``betas`` ``(10,)``, ``joints`` ``(T, 24, 3)`` (zero
        translation), ``off_R`` ``(S, 3, 3)``, ``off_t`` ``(S, 3)``, ``motion`` (resampled),
        ``sim`` the :class:`~wearpose.sensors.SimulationResult`.
    """

    m = motion if abs(motion.fps - cfg.rate) < 1e-9 else resample(motion, cfg.rate)
    noise = noise or cfg.train_noise
    offsets = offsets or cfg.offsets
    if isinstance(offsets, str):
        offsets = {"random": "random", "none": None}.get(offsets) if offsets != "rot" else \
            rotation_only_offsets(cfg.sensors, seed)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the kit's documented site substitutions warn per call
        sim = simulate(m, cfg.kit, body, seed=seed, noise=noise, offsets=offsets, rate=cfg.rate)
    names = list(sim.kit.sensor_names)
    pos = torch.stack([sim[n].position for n in names], 1).float()
    rot = torch.stack([sim[n].orientation for n in names], 1).float()
    valid = torch.stack([sim[n].valid for n in names], 1)
    src_R = sim.em_source[float(cfg.rate)]["orientation"].float()
    pose = m.pose.float().clone()
    pose[:, 0] = src_R.transpose(-1, -2) @ pose[:, 0]
    betas = m.betas.float()
    with torch.no_grad():
        joints = body(pose, betas, None, return_vertices=False).joints
    return {"position": pos, "orientation": rot, "valid": valid, "pose": pose, "betas": betas, "joints": joints,
            "off_R": sim.em_offsets.R.float(), "off_t": sim.em_offsets.t.float(), "motion": m, "sim": sim}


@dataclass(kw_only=True)
class EmposeData(ClipData):
    """One split, simulated and frame-concatenated.

    Attributes:
        position ``(F, S, 3)``, orientation ``(F, S, 3, 3)``: held measurements (source frame);
        valid ``(F, S)``; pose6 ``(F, 24, 6)`` ground-truth local rotations (root in the source
        frame) in 6D; joints ``(F, 24, 3)``; clip ``(F,)`` clip index; betas ``(C, 10)``;
        off_R ``(C, S, 3, 3)``; off_t ``(C, S, 3)``; starts ``(C,)`` first frame of each clip;
        lengths ``(C,)``; clip_ids; fingerprint; settings.
    """

    position: torch.Tensor
    orientation: torch.Tensor
    valid: torch.Tensor
    pose6: torch.Tensor
    joints: torch.Tensor
    clip: torch.Tensor
    betas: torch.Tensor
    off_R: torch.Tensor
    off_t: torch.Tensor

    def windows(self, seq_len: int, stride: int) -> torch.Tensor:
        """``(W, 2)`` (first frame, clip index) of every window of ``seq_len`` frames inside one clip."""
        out = []
        for c in range(len(self.clip_ids)):
            L = int(self.lengths[c])
            for s in range(0, L - seq_len + 1, max(1, stride)):
                out.append((int(self.starts[c]) + s, c))
        return torch.tensor(out, dtype=torch.long).reshape(-1, 2)

    def batch(self, win: torch.Tensor, seq_len: int) -> dict[str, torch.Tensor]:
        """Gather windows ``(B, 2)`` -> tensors ``(B, T, ...)`` (and per-clip ``(B, ...)``)."""
        idx = win[:, :1] + torch.arange(seq_len)
        c = win[:, 1]
        return {"position": self.position[idx], "orientation": self.orientation[idx], "valid": self.valid[idx],
                "pose": rot6d_to_matrix(self.pose6[idx]), "joints": self.joints[idx], "betas": self.betas[c],
                "off_R": self.off_R[c], "off_t": self.off_t[c]}

    def iter_batches(self, seq_len: int, stride: int, batch_size: int, generator: torch.Generator | None = None,
                     shuffle: bool = True, skip: int = 0) -> Iterator[dict[str, torch.Tensor]]:
        """Batches of windows (shuffled by ``generator``), skipping the first ``skip`` batches."""
        w = self.windows(seq_len, stride)
        order = torch.randperm(len(w), generator=generator) if shuffle else torch.arange(len(w))
        n = num_batches(len(w), batch_size)
        for i in range(skip, n):
            yield self.batch(w[order[i * batch_size:(i + 1) * batch_size]], seq_len)


def data_settings(cfg: EmposeConfig, body: Any) -> dict[str, Any]:
    """Everything that changes the simulated data (part of the fingerprint), including the
    sites the sensors resolve to (an asset can gain a site without changing its id)."""
    return {"version": DATA_VERSION, "kit": cfg.kit, "rate": cfg.rate, "noise": cfg.train_noise,
            "offsets": cfg.offsets, "seed": cfg.seed, "body_asset": body.asset_id, "root_frame": "em_source",
            "sites": kit_sites(cfg.kit, body)}


def build_split(split: str, cfg: EmposeConfig, body: Any, *, store: Any = None, limit: int | None = None,
                cache_root: str | Path | None = None, progress: Any = None) -> EmposeData:
    """Simulate (or load from the cache) one corpus split.

    Args:
        split: ``train`` / ``val`` / ``test``.
        cfg: data settings (``kit``, ``rate``, ``train_noise``, ``offsets``, ``seed``).
        body: the body model the sensors are simulated on.
        store: a :class:`~wearpose.motion.CorpusStore` (default: the prepared cache).
        limit: first ``limit`` clips (sorted ids) only.
        cache_root: directory of the tensor cache (default ``<corpus cache>/estimators/empose``).
        progress: optional callable ``progress(done, total)``.
    """
    settings = data_settings(cfg, body)
    store, ids, fp, root = split_source(split, settings, "empose", store=store, limit=limit, cache_root=cache_root,
                                        cfg=cfg, body=body)

    def one(cid: str) -> dict[str, torch.Tensor]:
        r = simulate_clip(store.load(cid), cfg, clip_body(store, cid, body), clip_seed(cid, cfg.seed))
        return {"position": hold_last_valid(r["position"], r["valid"]),
                "orientation": hold_last_valid(r["orientation"], r["valid"]), "valid": r["valid"],
                "pose6": matrix_to_rot6d(r["pose"]), "joints": r["joints"],
                "betas": r["betas"], "off_R": r["off_R"], "off_t": r["off_t"]}

    d = cached_clips(root / f"{split}-{fp[:16]}.pt", ids, fp,
                     lambda: concat_clips(ids, one, FRAME_KEYS, clip_keys=CLIP_KEYS, clip_column=True, progress=progress))
    return EmposeData(**{k: d[k] for k in (*FRAME_KEYS, "clip", *CLIP_KEYS, "starts", "lengths")},
                      clip_ids=d["clip_ids"], fingerprint=fp, settings=settings)


def recording_from_clip(r: dict[str, Any], cfg: EmposeConfig) -> Any:
    """The :class:`~wearpose.recording.Recording` of a :func:`simulate_clip` result
    (:meth:`Recording.from_simulation`): EM sensors in the source frame, the applied offsets in
    ``subject["offsets"]`` (what a calibration gives the estimator), the resampled motion as
    ground truth."""

    return Recording.from_simulation(r["sim"], r["motion"])
