"""Training data for PIP: six virtual IMUs simulated from corpus clips, with the kinematics
module's targets, cached on disk.

Per clip (sorted clip ids of one split of :class:`~wearpose.motion.CorpusStore`):

1. resample to ``cfg.rate`` (60 Hz, PIP's rate);
2. simulate kit ``imu6`` with :func:`wearpose.sensors.simulate`: orientation = the global
   rotation of the bone the sensor is strapped to (``imu_orientation="segment"``, what
   TransPose/PIP synthesise and what a T-pose calibration produces on real IMUs,
   :func:`wearpose.calibration.apply_calibration`), free acceleration of the skin site by
   TransPose's smoothed second differences, IMU error model ``cfg.train_noise``; seeds derive
   from the clip id;
3. normalise (TransPose/PIP, :func:`imu_features`): accelerations relative to the pelvis
   sensor's and rotated into its frame, orientations of the 5 other sensors relative to the
   pelvis orientation, plus the pelvis orientation itself: ``x`` ``(T, 72)``;
4. targets in the root (pelvis joint) frame: leaf joint positions (wrists, ankles, head),
   all non-root joint positions, root-relative global joint rotations (6D), joint
   velocities by PIP Eq. 14 ``v(t) = R_root(t)^T (r(t) - r(t-1)) / dt``, and foot contact
   labels (module :class:`~wearpose.estimators.pip.config.PipConfig` doc).

Everything is stored frame-concatenated in one tensor file under
``<cache>/estimators/pip/<split>-<fingerprint[:16]>.pt`` keyed by the fingerprint of the clip
ids and all simulation settings, so epochs never re-simulate.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterator

import torch

from wearpose.body.skeleton import JOINT_INDEX
from wearpose.estimators.checkpoint import fingerprint
from wearpose.estimators.clipstore import ClipData, cached_clips, concat_clips, kit_sites, num_batches
from wearpose.estimators.seeding import clip_seed
from wearpose.estimators.trainmix import TrainingMix, clip_body, training_source
from wearpose.estimators.pip.config import PipConfig
from wearpose.estimators.pip.sitting import SITTING_PREFIX, STAND_HOLD_S, sitting_clip_id, sitting_motion
from wearpose.evaluate.metrics import root_relative_global_rotations
from wearpose.geometry import matrix_to_rot6d

DATA_VERSION = 2
#: Leaf joints of P_L (PIP Sec. 3.1: wrists, ankles and head), SMPL indices.
LEAF_JOINTS: tuple[int, ...] = (JOINT_INDEX["left_wrist"], JOINT_INDEX["right_wrist"], JOINT_INDEX["left_ankle"],
                                JOINT_INDEX["right_ankle"], JOINT_INDEX["head"])
#: Foot joints whose contact C_F predicts (left, right), SMPL indices (TransPose labels joints 10/11).
FOOT_JOINTS: tuple[int, int] = (JOINT_INDEX["left_foot"], JOINT_INDEX["right_foot"])
NUM_SENSORS = 6
#: Frames cut from each end of a simulated clip (:func:`simulate_clip`): TransPose's
#: acceleration stencil half-width at 60 Hz.
EDGE_FRAMES = 4
INPUT_DIM = NUM_SENSORS * 12
#: Seed namespace of PIP's augmentation draws (:class:`~wearpose.estimators.trainmix.TrainingStore`):
#: the one its shipped weights' augmented clips were drawn in.
AUG_NAMESPACE = "pip-speed"


def imu_features(acc: torch.Tensor, ori: torch.Tensor, acc_scale: float) -> torch.Tensor:
    """TransPose/PIP input normalisation.

    Args:
        acc: ``(..., 6, 3)`` free accelerations, world frame, m/s^2, kit ``imu6`` order (pelvis last).
        ori: ``(..., 6, 3, 3)`` bone orientations ``R_WB`` (after T-pose calibration).
        acc_scale: accelerations are divided by it (m/s^2).

    Returns:
        ``(..., 72)``: 18 accelerations ``R_root^T [a_i - a_root ..., a_root] / acc_scale`` then 54
        rotation-matrix entries ``[R_root^T R_i ..., R_root]`` (row-major).
    """
    Rr = ori[..., 5:, :, :]
    a = torch.cat([acc[..., :5, :] - acc[..., 5:, :], acc[..., 5:, :]], dim=-2)
    a = (Rr.transpose(-1, -2) @ a.unsqueeze(-1)).squeeze(-1) / acc_scale
    R = torch.cat([Rr.transpose(-1, -2) @ ori[..., :5, :, :], Rr], dim=-3)
    return torch.cat([a.flatten(-2), R.flatten(-3)], dim=-1)


def root_frame_targets(pose: torch.Tensor, joints: torch.Tensor, fps: float, cfg: PipConfig
                       ) -> dict[str, torch.Tensor]:
    """Kinematics targets of one sequence (module doc, step 4).

    Args:
        pose: ``(T, 24, 3, 3)`` local rotations (root = world orientation); joints ``(T, 24, 3)``
            world positions, m; fps: Hz.

    Returns:
        ``leaf`` ``(T, 15)`` m, ``joints`` ``(T, 69)`` m (joints 1..23, root frame), ``rot6``
        ``(T, 138)`` (root-relative global rotations of joints 1..23, 6D), ``vel`` ``(T, 72)``
        (Eq. 14, m/s divided by ``vel_scale``; frame 0 copies frame 1), ``contact`` ``(T, 2)``
        in {0, 1}.
    """
    T = pose.shape[0]
    RrT = pose[:, 0].transpose(-1, -2)
    rel = (RrT[:, None] @ (joints - joints[:, :1]).unsqueeze(-1)).squeeze(-1)
    glob = root_relative_global_rotations(pose)
    d = torch.zeros_like(joints)
    if T > 1:
        d[1:] = joints[1:] - joints[:-1]
        d[0] = d[1]
    vel = (RrT[:, None] @ d.unsqueeze(-1)).squeeze(-1) * fps / cfg.vel_scale
    feet = joints[:, list(FOOT_JOINTS)]
    speed = d[:, list(FOOT_JOINTS)].norm(dim=-1) * fps
    height = feet[..., 1] - feet[..., 1].min()
    contact = ((speed < cfg.contact_speed) & (height < cfg.contact_height)).float()
    return {"leaf": rel[:, list(LEAF_JOINTS)].flatten(1), "joints": rel[:, 1:].flatten(1),
            "rot6": matrix_to_rot6d(glob[:, 1:]).flatten(1), "vel": vel.flatten(1), "contact": contact}


def edge_cut(T: int, trim: int) -> slice | None:
    """The frames of a ``T``-frame clip kept after cutting ``trim`` at both ends (None: keep all;
    a clip of at most ``2 * trim + 2`` frames is not cut)."""
    return slice(trim, T - trim) if trim > 0 and T > 2 * trim + 2 else None


def simulate_clip(motion: Any, cfg: PipConfig, body: Any, seed: int, noise: str | None = None,
                  trim: int = EDGE_FRAMES, shape: str | None = None) -> dict[str, Any]:
    """Simulate one clip for PIP (module doc, steps 1-4).

    ``shape`` (default ``None``: the clip's own body): the wearer's body shape as
    :func:`wearpose.sensors.simulate` takes it (``"random"`` for training, ``"heldout"`` for
    evaluation); the clip is then re-fitted to that body and the result's ``motion``, ``pose``,
    ``trans``, ``betas`` and targets are the re-fitted motion's.

    ``trim`` frames are cut from both ends after simulating: the smoothed acceleration stencil
    is one-sided there, and many clips begin or end with a jump into or out of a rest pose
    (accelerations of hundreds of m/s^2 in the first frames of some CMU clips). ``motion`` in the
    result is trimmed too; ``sim`` is not.

    Returns:
        dict: ``x`` ``(T, 72)``, the targets of :func:`root_frame_targets`, ``acc`` ``(T, 6, 3)``,
        ``ori`` ``(T, 6, 3, 3)`` (raw simulated, kit order), ``pose`` ``(T, 24, 3, 3)``, ``trans``
        ``(T, 3)``, ``betas`` ``(10,)``, ``world_joints`` ``(T, 24, 3)``, ``motion`` (resampled),
        ``sim`` the :class:`~wearpose.sensors.SimulationResult`.
    """
    from wearpose.motion import resample  # start-up: wearpose.motion adds ~60 ms to importing this module
    # start-up: wearpose.sensors adds ~90 ms to importing this module
    from wearpose.sensors import simulate

    m = motion if abs(motion.fps - cfg.rate) < 1e-9 else resample(motion, cfg.rate)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the kit's documented site substitutions warn per call
        sim = simulate(m, cfg.kit, body, seed=seed, noise=noise or cfg.train_noise, rate=cfg.rate,
                       imu_orientation="segment", shape=shape)
    m = sim.motion if sim.motion is not None else m
    names = list(sim.kit.sensor_names)
    acc = torch.stack([sim[n].acceleration for n in names], 1).float()
    ori = torch.stack([sim[n].orientation for n in names], 1).float()
    pose, betas, trans = m.pose.float(), m.betas.float(), m.trans.float()
    with torch.no_grad():
        joints = body(pose, betas, trans, return_vertices=False).joints.float()
    cut = edge_cut(pose.shape[0], trim)
    if cut is not None:
        acc, ori, pose, trans, joints = acc[cut], ori[cut], pose[cut], trans[cut], joints[cut]
        m = m.slice(cut.start, cut.stop)
    tg = root_frame_targets(pose, joints, cfg.rate, cfg)
    return {"x": imu_features(acc, ori, cfg.acc_scale), **tg, "acc": acc, "ori": ori, "pose": pose, "trans": trans,
            "betas": betas, "world_joints": joints, "motion": m, "sim": sim}


TENSORS = ("x", "leaf", "joints", "rot6", "vel", "contact")


@dataclass(kw_only=True)
class PipData(ClipData):
    """One split, simulated and frame-concatenated: ``x`` ``(F, 72)`` and the targets of
    :func:`root_frame_targets` (``leaf``, ``joints``, ``rot6``, ``vel``, ``contact``), ``starts``
    / ``lengths`` ``(C,)`` per clip, ``clip_ids``, ``fingerprint``, ``settings``."""

    x: torch.Tensor
    leaf: torch.Tensor
    joints: torch.Tensor
    rot6: torch.Tensor
    vel: torch.Tensor
    contact: torch.Tensor

    def windows(self, seq_len: int, stride: int, min_len: int = 0, sitting_len: int = 0) -> torch.Tensor:
        """``(W, 2)`` (first frame, length) of the training windows.

        ``min_len == 0``: every window of exactly ``seq_len`` frames starting every ``stride``
        frames inside one clip (a clip shorter than ``seq_len`` gives none). ``min_len > 0``: as
        well, one more window ending at the clip's last frame when the stride leaves a tail out,
        and a clip of ``min_len <= L < seq_len`` frames is one window of length ``L`` (padded and
        masked in :meth:`batch`), so every frame of such clips is trained on. ``sitting_len > 0``:
        the synthetic sitting clips (:func:`~wearpose.estimators.pip.sitting.sitting_clip_id`) are
        cut into windows of ``sitting_len`` frames every ``sitting_len // 2`` instead.
        """
        out = []
        for cid, s, L in zip(self.clip_ids, self.starts.tolist(), self.lengths.tolist()):
            if sitting_len > 0 and cid.startswith(SITTING_PREFIX):
                out += [(f, sitting_len) for f in range(s, s + L - sitting_len + 1, max(1, sitting_len // 2))]
                continue
            if L >= seq_len:
                firsts = list(range(s, s + L - seq_len + 1, max(1, stride)))
                if min_len > 0 and firsts[-1] != s + L - seq_len:
                    firsts.append(s + L - seq_len)
                out += [(f, seq_len) for f in firsts]
            elif min_len > 0 and L >= min_len:
                out.append((s, L))
        return torch.tensor(out, dtype=torch.long).reshape(-1, 2)

    def batch(self, win: torch.Tensor, seq_len: int | None = None) -> dict[str, torch.Tensor]:
        """Windows ``(B, 2)`` (first frame, length) -> tensors ``(B, T, ...)`` with ``T`` the longest
        window, and ``mask`` ``(B, T)`` (False on padding; padding repeats the window's last frame).
        ``seq_len`` is accepted for the common window-task signature and not needed."""
        T = int(win[:, 1].max())
        step = torch.arange(T)
        mask = step[None] < win[:, 1:2]
        idx = win[:, :1] + torch.minimum(step[None], win[:, 1:2] - 1)
        return {**{k: getattr(self, k)[idx] for k in TENSORS}, "mask": mask}

    def iter_batches(self, seq_len: int, stride: int, batch_size: int, generator: torch.Generator | None = None,
                     shuffle: bool = True, skip: int = 0, min_len: int = 0, sitting_len: int = 0
                     ) -> Iterator[dict[str, torch.Tensor]]:
        """Batches of :meth:`windows` (shuffled by ``generator``), skipping the first ``skip`` batches.

        With windows of several lengths (``min_len > 0`` or ``sitting_len > 0``) a shuffled batch
        would be padded to its longest window almost always; so the shuffled windows are sorted
        by length within groups of 32 batches, cut into batches, and the batches shuffled (same
        ``generator``): the padding stays small and the order is still random and reproducible.
        As without bucketing, the ``len(windows) % batch_size`` windows left over (here the
        longest of the last group) sit out the epoch.
        """
        w = self.windows(seq_len, stride, min_len, sitting_len)
        order = torch.randperm(len(w), generator=generator) if shuffle else torch.arange(len(w))
        n = num_batches(len(w), batch_size)
        if (min_len > 0 or sitting_len > 0) and shuffle:
            group = 32 * batch_size
            order = torch.cat([g[torch.argsort(w[g, 1], stable=True)] for g in order.split(group)]) if len(w) else order
            bo = torch.randperm(n, generator=generator)
            batches = [order[int(i) * batch_size:(int(i) + 1) * batch_size] for i in bo]
        else:
            batches = [order[i * batch_size:(i + 1) * batch_size] for i in range(n)]
        for sel in batches[skip:]:
            yield self.batch(w[sel])


def data_settings(cfg: PipConfig, body: Any) -> dict[str, Any]:
    """Everything that changes the simulated data (part of the fingerprint)."""
    return {"version": DATA_VERSION, "kit": cfg.kit, "rate": cfg.rate, "noise": cfg.train_noise, "seed": cfg.seed,
            "acc_scale": cfg.acc_scale, "vel_scale": cfg.vel_scale, "contact_speed": cfg.contact_speed,
            "contact_height": cfg.contact_height, "body_asset": body.asset_id, "orientation": "segment",
            "sites": kit_sites(cfg.kit, body)}


def build_split(split: str, cfg: PipConfig, body: Any, *, store: Any = None, limit: int | None = None,
                cache_root: str | Path | None = None, progress: Any = None) -> PipData:
    """Simulate (or load from the cache) one corpus split.

    Args:
        split: ``train`` / ``val`` / ``test``.
        cfg: data settings; body: the body model the sensors are simulated on.
        store: a :class:`~wearpose.motion.CorpusStore` (default: the prepared cache).
        limit: ``limit`` clips only, evenly spread over the sorted ids (the sorted order groups
            clips by source and motion type, so a prefix would be one kind of motion).
        cache_root: directory of the tensor cache (default ``<corpus cache>/estimators/pip``).
        progress: optional callable ``progress(done, total)``.

    On the train split, the config's training mix (:mod:`wearpose.estimators.trainmix`: wearers,
    site jitter, augmented copies, procedural clips) applies: the corpus clips on their wearers,
    then the added clips (cached apart, so the corpus cache is shared with runs that add other
    clips); with ``cfg.sitting_clips`` > 0, PIP's synthetic sitting clips (:func:`sitting_count`)
    follow.
    """
    # start-up: wearpose.motion adds ~60 ms to importing this module
    from wearpose.motion import CorpusStore

    store = store or CorpusStore()
    root = Path(cache_root) if cache_root is not None else Path(store.root) / "estimators" / "pip"
    corpus = _corpus_ids(split, store, limit)
    store, ids, mix = training_source(split, store, corpus, cfg, body, AUG_NAMESPACE)
    wearers = TrainingMix.from_config(cfg).corpus_settings() if split == "train" else {}
    data = _build_corpus_split(split, corpus, cfg, body, store, root, progress, wearers)
    if len(ids) > len(corpus):
        data = concat_data(data, _build_added(split, ids[len(corpus):], cfg, body, store, root, progress, mix))
    n_sit = sitting_count(cfg, split)
    if n_sit == 0:
        return data
    return concat_data(data, _build_sitting(split, n_sit, cfg, body, root))


def _build_added(split: str, ids: list[str], cfg: PipConfig, body: Any, store: Any, root: Path,
                 progress: Any, mix: dict[str, Any]) -> PipData:
    """The clips the training mix adds (augmented copies, procedural clips), simulated like
    corpus clips (own noise seeds); cached apart from the corpus clips."""
    settings = {**data_settings(cfg, body), **mix}
    fp = fingerprint(ids, {**settings, "split": split})
    return _simulate_cached(root / f"{split}-aug-{fp[:16]}.pt", ids, fp, settings,
                            lambda aid: simulate_clip(store.load(aid), cfg, clip_body(store, aid, body),
                                                      clip_seed(aid, cfg.seed, "pip")), progress)


def sitting_count(cfg: PipConfig, split: str) -> int:
    """Synthetic sitting clips added to ``split`` (``cfg.sitting_clips`` to train, a tenth, at
    least 4, to val, none to test)."""
    n = int(cfg.sitting_clips)
    if n <= 0 or split not in ("train", "val"):
        return 0
    return n if split == "train" else max(4, n // 10)


def concat_data(a: PipData, b: PipData) -> PipData:
    """Clips of ``a`` then ``b`` in one :class:`PipData` (fingerprint of both)."""
    return PipData(**{k: torch.cat([getattr(a, k), getattr(b, k)]) for k in TENSORS},
                   starts=torch.cat([a.starts, b.starts + a.num_frames]), lengths=torch.cat([a.lengths, b.lengths]),
                   clip_ids=[*a.clip_ids, *b.clip_ids], fingerprint=fingerprint([a.fingerprint, b.fingerprint], {}),
                   settings={**a.settings, **b.settings})


def _sitting_settings(cfg: PipConfig, body: Any) -> dict[str, Any]:
    """What the synthetic sitting clips' fingerprint (cache) depends on; a setting at its default
    is left out, so the clips of older configs keep their cache."""
    settings = {**data_settings(cfg, body), "sitting_version": 2}
    if tuple(cfg.sitting_stand_s) != STAND_HOLD_S:
        settings["sitting_stand_s"] = list(cfg.sitting_stand_s)
    if cfg.sitting_transitions != "slerp":
        settings["sitting_transitions"] = cfg.sitting_transitions
    if cfg.sitting_hanging_arms > 0.0:
        settings["sitting_hanging_arms"] = cfg.sitting_hanging_arms
    return settings


def _build_sitting(split: str, n: int, cfg: PipConfig, body: Any, root: Path) -> PipData:
    """``n`` synthetic sitting clips (:func:`~wearpose.estimators.pip.sitting.sitting_motion`),
    seeds in a per-split namespace, simulated like corpus clips; cached under ``root``."""
    ids = [sitting_clip_id(split, i) for i in range(n)]
    settings = _sitting_settings(cfg, body)
    fp = fingerprint(ids, {**settings, "split": split})

    def one(cid: str) -> dict[str, Any]:
        seed = clip_seed(cid, cfg.seed, "pip-sitting")
        return simulate_clip(sitting_motion(torch.Generator().manual_seed(seed), body, cfg.rate,
                                            stand_s=tuple(cfg.sitting_stand_s),
                                            transitions=cfg.sitting_transitions,
                                            hanging_arms=cfg.sitting_hanging_arms), cfg, body, seed)

    return _simulate_cached(root / f"{split}-sitting-{fp[:16]}.pt", ids, fp, settings, one)


def _corpus_ids(split: str, store: Any, limit: int | None) -> list[str]:
    """Sorted clip ids of ``split``; ``limit`` of them spread evenly over the list."""
    ids = store.clips(split=split)
    if limit and limit < len(ids):
        ids = [ids[int(i * len(ids) / limit)] for i in range(limit)]
    return ids


def _build_corpus_split(split: str, ids: list[str], cfg: PipConfig, body: Any, store: Any, root: Path,
                        progress: Any = None, wearers: dict[str, Any] | None = None) -> PipData:
    """The corpus clips ``ids``; ``wearers``: the training mix's
    :meth:`~wearpose.estimators.trainmix.TrainingMix.corpus_settings` (its wearers and site
    jitter change these clips too, so they join the cache key)."""
    settings = {**data_settings(cfg, body), **(wearers or {})}
    fp = fingerprint(ids, {**settings, "split": split})
    return _simulate_cached(root / f"{split}-{fp[:16]}.pt", ids, fp, settings,
                            lambda cid: simulate_clip(store.load(cid), cfg, clip_body(store, cid, body),
                                                      clip_seed(cid, cfg.seed, "pip")), progress)


def _simulate_cached(path: Path, ids: list[str], fp: str, settings: dict[str, Any], one: Any,
                     progress: Any = None) -> PipData:
    """Load ``path`` or simulate every clip id with ``one(cid)`` (:func:`simulate_clip`'s dict),
    concatenate and save it there."""
    d = cached_clips(path, ids, fp, lambda: concat_clips(ids, one, TENSORS, progress=progress))
    return PipData(**{k: d[k] for k in (*TENSORS, "starts", "lengths")}, clip_ids=d["clip_ids"], fingerprint=fp,
                   settings=settings)
