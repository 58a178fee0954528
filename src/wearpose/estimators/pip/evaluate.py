"""PIP evaluation: Table 2/3-style metrics on simulated held-out recordings, the translation
error vs travelled distance curve (Fig. 3) and the long-sitting drift test (Fig. 9).

Protocol (:func:`evaluate_variants`): every clip of the split (or ``limit`` clips spread over
it) is resampled to 60 Hz, simulated with kit ``imu6`` (bone orientations as after a T-pose
calibration, free accelerations, the default IMU error model, seeds in an evaluation namespace
never used for training), trimmed by :data:`~wearpose.estimators.pip.data.EDGE_FRAMES` at both
ends, and given to each variant from the ground-truth first frame (pose, joint velocities,
translation, shape: PIP assumes the initial state known, Sec. 3.1.2). Metrics are
:func:`wearpose.evaluate.compute_all` per clip (rotation metrics with PIP's protocol of masking
the ignored joints, ``mask_ignored=True``), averaged over frames of all clips. Added per variant: PIP's ZMP
distance (:func:`wearpose.physics.zmp_distance` on the output motion, finite differences over
+-:data:`ZMP_STRIDE` frames; averaged over the frames with a supporting foot) and the same for
the ground truth (``result["ground_truth"]``: validates the metric, real motion should be near
0), and per-clip rows (the clip's :func:`compute_all` figures, translation error, final drift,
deepest penetration with its frame and joint) in ``rows[name]["per_clip"]``.
"""

from __future__ import annotations

import math
import time
from typing import Any, Callable

import numpy as np
import torch

from wearpose.errors import ConfigError
from wearpose.estimators.bodies import wearer_store
from wearpose.estimators.pip.data import EDGE_FRAMES, edge_cut, imu_features, simulate_clip
from wearpose.estimators.pip.sitting import sitting_pose, sitting_sequence
from wearpose.estimators.seeding import clip_seed
from wearpose.evaluate.metrics import compute_all, cumulative_translation_error, joint_angle_errors

#: Travelled-distance thresholds of the translation error curve, m.
DISTANCES = tuple(float(d) for d in range(0, 21, 2))
#: Metrics averaged over frames (keys of :func:`wearpose.evaluate.compute_all`).
FRAME_METRICS = ("sip_error_deg", "angular_error_deg", "positional_error_cm", "mesh_error_cm", "jitter_abs_km_s3",
                 "jitter_rel_km_s3", "mpjpe_major_mm", "translation_error_cm")


def horizontal_path_m(trans: torch.Tensor) -> float:
    """Ground-plane path length of a root trajectory ``trans`` ``(T, 3)`` (y up), m: the
    travelled distance by which clips are selected ("clips that travel > 1 m")."""
    return float((trans[1:, [0, 2]] - trans[:-1, [0, 2]]).norm(dim=-1).sum())


def clip_travel_m(motion: Any, rate: float, trim: int = EDGE_FRAMES) -> float:
    """:func:`horizontal_path_m` of a corpus clip as the evaluation sees it: resampled to
    ``rate`` Hz and cut by ``trim`` frames at both ends (as :func:`simulate_clip`), without
    simulating sensors."""
    # start-up: wearpose.motion adds ~60 ms to importing this module
    from wearpose.motion import resample

    m = motion if abs(motion.fps - rate) < 1e-9 else resample(motion, rate)
    trans = m.trans.float()
    cut = edge_cut(trans.shape[0], trim)
    return horizontal_path_m(trans if cut is None else trans[cut])


#: finite-difference stride of the ZMP metric, frames at 60 fps (see :func:`zmp_of`)
ZMP_STRIDE = 2
_CHARACTERS: dict[tuple[int, tuple[float, ...]], Any] = {}


def zmp_of(body: Any, betas: torch.Tensor, pose: torch.Tensor, trans: torch.Tensor, fps: float) -> Any:
    """:func:`wearpose.physics.zmp_distance` of a motion (``(T, 24, 3, 3)`` local rotations,
    ``(T, 3)`` m) on the character of ``betas`` (kept between calls: building one costs ~0.1 s)."""
    # start-up: wearpose.physics adds ~240 ms to importing this module
    from wearpose.physics import PhysicsCharacter, zmp_distance

    key = (id(body), tuple(float(b) for b in torch.as_tensor(betas).reshape(-1)))
    if key not in _CHARACTERS:
        if len(_CHARACTERS) > 8:
            _CHARACTERS.clear()
        _CHARACTERS[key] = PhysicsCharacter.from_body(body, torch.as_tensor(betas).reshape(-1))
    # +-2 frames: the Bandai clips are 30 fps mocap upsampled to 60; 1-frame differences of the
    # interpolated ground truth put its mean ZMP distance at 0.20 m on a val walk, 0.06 m natively
    return zmp_distance(_CHARACTERS[key], pose, trans, fps, stride=ZMP_STRIDE)


def _init(est: Any, r: dict[str, Any]) -> None:
    est.set_initial_state(r["pose"][0], r["vel"][0].view(24, 3) * est.config.vel_scale, r["trans"][0], r["betas"])


@torch.no_grad()
def clip_metrics(est: Any, r: dict[str, Any], body: Any, gt: Any = None) -> tuple[dict[str, float], dict[str, Any]]:
    """Run ``est`` on one simulated clip ``r`` (:func:`simulate_clip`) and score it; ``gt`` the
    ground truth's body output (computed here when None; pass it to share it between variants).

    Returns ``(metrics, info)``: :func:`compute_all` figures, and the translation curve / physics
    diagnostics of the clip.
    """
    _init(est, r)
    t0 = time.perf_counter()
    track = est.estimate_tensors(r["acc"], r["ori"])
    sec = time.perf_counter() - t0
    betas = r["betas"]
    # vertex normals are not scored; skipping them halves the cost of the evaluation
    pred = body(track.local_rot, betas, track.trans, return_normals=False)
    if gt is None:
        gt = body(r["pose"], betas, r["trans"], return_normals=False)
    m = compute_all({"local_rot": track.local_rot, "joints": pred.joints, "vertices": pred.vertices, "trans": track.trans},
                    {"local_rot": r["pose"], "joints": gt.joints, "vertices": gt.vertices, "trans": r["trans"]},
                    fps=est.fps, mask_ignored=True)
    curve = cumulative_translation_error(track.trans, r["trans"], DISTANCES)
    info: dict[str, Any] = {"frames": track.num_frames, "seconds": sec, "error_at": curve.error_at.tolist(),
                            "travelled_m": float(curve.travelled[-1]), "final_error_m": float(curve.final_error)}
    info["translation_error_cm"] = float((track.trans - r["trans"]).norm(dim=-1).mean()) * 100
    z = zmp_of(body, betas, track.local_rot, track.trans, est.fps)
    info.update(zmp_sum_m=float(z.distance[np.isfinite(z.distance)].sum()), zmp_frames=z.frames_defined)
    ex = track.extras
    if ex.get("physics"):
        info.update(qp_ms=ex["qp_ms"].tolist(), max_penetration_m=float(ex["penetration_m"].max()))
        opt = getattr(est, "_optimizer", None)
        if opt is not None:  # where the deepest penetration is: frame and joint (SMPL index)
            cand = list(opt.config.contact_candidates)
            depth = opt.ground_y - pred.joints[:, cand, 1]
            k = int(depth.argmax())
            info["penetration_at"] = {"frame": k // len(cand), "joint": cand[k % len(cand)],
                                      "depth_cm": float(depth.max()) * 100}
    return m, info


def evaluate_variants(variants: dict[str, Any], split: str = "test", limit: int | None = None, *, noise: str = "default",
                      seed: int = 0, store: Any = None, progress: Callable[[int, int], None] | None = None,
                      min_travel: float = 0.0, bodies: str = "corpus") -> dict[str, Any]:
    """Evaluate several estimators (name -> :class:`PipEstimator`, all with one body) on the same
    simulated clips (module doc); ``min_travel`` > 0 keeps only the clips whose
    :func:`clip_travel_m` reaches it (m; applied before ``limit``). ``bodies``: ``"corpus"``
    (default) the clips' own body (beta = 0); ``"heldout"`` each clip's held-out wearer
    (:mod:`wearpose.estimators.bodies`: the same body for every method; never a training draw),
    the clip re-fitted to it (its shape is part of the known initial state). Returns
    ``{"rows": {name: {...}}, "clips", "frames", ...}``."""
    # start-up: wearpose.motion adds ~60 ms to importing this module
    from wearpose.motion import CorpusStore

    first = next(iter(variants.values()))
    body, cfg = first.body, first.config
    store = wearer_store(store or CorpusStore(), bodies, body, seed)
    ids = store.clips(split=split)
    if min_travel > 0:
        ids = [cid for cid in ids if clip_travel_m(store.load(cid), cfg.rate) >= min_travel]
    if limit and limit < len(ids):
        ids = [ids[int(i * len(ids) / limit)] for i in range(limit)]
    acc: dict[str, dict[str, Any]] = {n: {"sums": {}, "frames": 0, "curves": [], "drift": [], "qp_ms": [], "pen": [],
                                          "seconds": 0.0, "per_clip": [], "zmp": [0.0, 0]} for n in variants}
    frames = 0
    gt_zmp = [0.0, 0]
    for c, cid in enumerate(ids):
        r = simulate_clip(store.load(cid), cfg, body, clip_seed(cid, seed, "pip-eval"), noise=noise)
        T = int(r["x"].shape[0])
        frames += T
        gt = body(r["pose"], r["betas"], r["trans"], return_normals=False)
        z = zmp_of(body, r["betas"], r["pose"], r["trans"], cfg.rate)
        gt_zmp[0] += float(z.distance[np.isfinite(z.distance)].sum())
        gt_zmp[1] += z.frames_defined
        for name, est in variants.items():
            m, info = clip_metrics(est, r, body, gt)
            a = acc[name]
            for k, v in m.items():
                if isinstance(v, float) and math.isfinite(v):
                    s = a["sums"].setdefault(k, [0.0, 0])
                    s[0] += v * T
                    s[1] += T
            a["frames"] += T
            a["zmp"][0] += info["zmp_sum_m"]
            a["zmp"][1] += info["zmp_frames"]
            a["seconds"] += info["seconds"]
            a["curves"].append(info["error_at"])
            if info["travelled_m"] > 1.0:
                a["drift"].append(info["final_error_m"] / info["travelled_m"])
            a["qp_ms"].extend(info.get("qp_ms", []))
            if "max_penetration_m" in info:
                a["pen"].append(info["max_penetration_m"])
            a["per_clip"].append({"clip": cid, "frames": T, **{k: v for k, v in m.items() if isinstance(v, float)
                                                                 and math.isfinite(v)},
                                  "translation_error_cm": info["translation_error_cm"],
                                  "final_error_m": info["final_error_m"], "travelled_m": info["travelled_m"],
                                  **({"betas": [round(float(x), 4) for x in r["betas"]]} if bodies != "corpus" else {}),
                                  "zmp_distance_m": info["zmp_sum_m"] / max(info["zmp_frames"], 1),
                                  **{k: info[k] for k in ("max_penetration_m", "penetration_at") if k in info}})
        if progress is not None:
            progress(c + 1, len(ids))
    rows: dict[str, Any] = {}
    for name, a in acc.items():
        est = variants[name]
        row: dict[str, Any] = {k: s[0] / s[1] for k, s in a["sums"].items() if s[1]}
        cur = torch.tensor(a["curves"], dtype=torch.float64)
        row["translation_error_vs_distance_cm"] = {f"{d:g}m": (float(torch.nanmean(cur[:, i])) * 100 if
                                                               bool((~cur[:, i].isnan()).any()) else None)
                                                   for i, d in enumerate(DISTANCES)}
        row["clips_reaching_m"] = {f"{d:g}m": int((~cur[:, i].isnan()).sum()) for i, d in enumerate(DISTANCES)}
        row["final_drift_pct"] = float(torch.tensor(a["drift"]).mean() * 100) if a["drift"] else None
        row["options"] = {"physics": est.physics, "dual_pd": est.dual_pd, "learned_init": est.learned_init and
                          est.config.learned_init}
        row["ms_per_frame"] = a["seconds"] / max(a["frames"], 1) * 1000
        if a["qp_ms"]:
            q = torch.tensor(a["qp_ms"])
            row["qp_ms"] = {"median": float(q.median()), "p99": float(torch.quantile(q, 0.99)), "max": float(q.max())}
        if a["pen"]:
            row["max_penetration_cm"] = max(a["pen"]) * 100
        row["zmp_distance_m"] = a["zmp"][0] / a["zmp"][1] if a["zmp"][1] else None
        row["zmp_frames_pct"] = a["zmp"][1] / max(a["frames"], 1) * 100
        row["per_clip"] = a["per_clip"]
        row["checkpoint"] = getattr(est, "source", "")
        row["data_fingerprint"] = est.data_fingerprint
        rows[name] = row
    ground_truth = {"zmp_distance_m": gt_zmp[0] / gt_zmp[1] if gt_zmp[1] else None,
                    "zmp_frames_pct": gt_zmp[1] / max(frames, 1) * 100}
    return {"split": split, "clips": len(ids), "frames": frames, "noise": noise, "seed": seed, "rows": rows,
            **({"bodies": bodies} if bodies != "corpus" else {}),
            "ground_truth": ground_truth,
            "protocol": "simulated imu6 (bone orientations, free acc, default IMU noise), known initial state, "
                        "rotation metrics with ignored joints masked (PIP protocol)"}


@torch.no_grad()
def sitting_drift(est: Any, hours: float = 1.0, start: str = "standing", chunk: int = 3600, seed: int = 0,
                  noise: str = "none", every_s: float = 600.0, seq: Any = None) -> dict[str, Any]:
    """PIP Fig. 6 / Fig. 9: a sit-down (:func:`~wearpose.estimators.pip.sitting.sitting_sequence`;
    or already seated, ``start="seated"``: only its last, seated second) followed by ``hours`` of
    perfectly still input (zero accelerations, the seated orientations), kinematics only.
    ``seq``: another clip to play instead of the sit-down (a :class:`~wearpose.motion.MotionSequence`
    whose last second is seated, e.g. :func:`~wearpose.estimators.pip.sitting.heldout_sitting_clip`);
    its last frame is then the seated pose errors are measured against.

    Returns the root-relative angular error against the seated pose (all joints, and the upper
    legs alone, the quantity of PIP's Fig. 6) at the start of the still period, after 1 min and
    at the end, a series every ``every_s`` seconds, and the drift: the mean joint angle between
    the estimates at the start and at the end of the still period (Fig. 9's "total drift").
    """
    body, cfg = est.body, est.config
    target = sitting_pose() if seq is None else seq.pose[-1].float()
    seq = sitting_sequence(body) if seq is None else seq
    r = simulate_clip(seq, cfg, body, seed, noise=noise, trim=0)
    if start == "seated":
        n = int(r["x"].shape[0])
        keep = slice(n - int(cfg.rate), n)
        r = {k: (v[keep] if isinstance(v, torch.Tensor) and v.dim() > 0 and v.shape[0] == n else v) for k, v in r.items()}
    _init(est, r)
    est.model.eval()
    x = imu_features(r["acc"], r["ori"], cfg.acc_scale)
    x_still = imu_features(torch.zeros_like(r["acc"][-1]), r["ori"][-1], cfg.acc_scale)
    states = est._start_states()
    out, states = est.model(x[None], states)
    root = r["ori"][-1, 5]
    legs = [1, 2]  # SMPL left/right hip joints: the upper-leg orientations

    def err(rot6: torch.Tensor) -> tuple[float, float, torch.Tensor]:
        pose = est._decode({"rot6": rot6, "vel": torch.zeros(1, 72), "contact_logit": torch.zeros(1, 2)},
                           root[None])["pose"][0]
        e = joint_angle_errors(pose, target, "root_relative")
        return math.degrees(float(e.mean())), math.degrees(float(e[legs].mean())), pose

    e0, l0, p0 = err(out["rot6"][0, -1:])
    total = int(hours * 3600 * cfg.rate)
    every = max(1, int(every_s * cfg.rate))
    series = [{"minutes": 0.0, "error_deg": e0, "upper_leg_error_deg": l0}]
    done, e1min = 0, None
    t0 = time.perf_counter()
    last = out["rot6"][0, -1:]
    while done < total:
        n = min(chunk, total - done, every - done % every)
        o, states = est.model(x_still.expand(1, n, -1), states)
        if e1min is None and done + n >= int(60 * cfg.rate):
            e1min = err(o["rot6"][0, int(60 * cfg.rate) - done - 1:int(60 * cfg.rate) - done])[0]
        last = o["rot6"][0, -1:]
        done += n
        if done % every == 0 or done == total:
            e, le, _ = err(last)
            series.append({"minutes": done / cfg.rate / 60, "error_deg": e, "upper_leg_error_deg": le})
    e_end, l_end, p_end = err(last)
    drift = math.degrees(float(joint_angle_errors(p_end, p0, "root_relative").mean()))
    return {"start": start, "hours": hours, "frames": total, "error_at_start_deg": e0, "error_after_1min_deg": e1min,
            "error_at_end_deg": e_end, "upper_leg_error_at_start_deg": l0, "upper_leg_error_at_end_deg": l_end,
            "upper_leg_error_max_deg": max(s["upper_leg_error_deg"] for s in series),
            "drift_total_deg": drift, "drift_per_hour_deg": drift / hours if hours else None, "series": series,
            "learned_init": bool(est.learned_init and est.config.learned_init), "seconds": time.perf_counter() - t0}
