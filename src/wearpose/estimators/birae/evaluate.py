"""BiRAE evaluation on a corpus split in the paper's metric: MPJAE (degrees) per joint group.

Groups (Tables 1-4, :data:`wearpose.evaluate.BIRAE_JOINT_GROUPS`): distal (hips, shoulders),
tracking (knees, elbows, head), other (spine, neck, collars); ``all`` = the 15 major joints.
MPJAE compares root-relative global rotations (:func:`wearpose.evaluate.mpjae_groups`), averaged
over every frame of every clip (frames pooled).

Recordings: each clip is resampled to the evaluation rate and its ideal ``mimu6`` orientations
disturbed by a scenario of :data:`wearpose.estimators.birae.data.SCENARIOS` with a per-clip seed
in an evaluation namespace (never a training draw); :func:`~wearpose.estimators.birae.data.make_recording`
turns them into a :class:`~wearpose.recording.Recording` and the estimator runs on that.
"""

from __future__ import annotations

import math
from typing import Any, Callable, Sequence

import torch

from wearpose.estimators.birae.data import SCENARIOS, clip_seed, make_recording, synthesize
from wearpose.estimators.birae.uncertainty import calibration_report, fit_sigma_scale, reliability_curve

GROUP_ORDER = ("distal", "tracking", "other", "all")


def scenario_recordings(split: str = "test", scenario: str = "clean", rate: float = 60.0, limit: int | None = None,
                        store: Any = None, seed: int = 0) -> list[tuple[str, Any, torch.Tensor]]:
    """``[(clip_id, recording, gt_pose (T, 24, 3, 3))]`` for the first ``limit`` clips of ``split``."""
    from wearpose.motion import CorpusStore

    if scenario not in SCENARIOS:
        raise KeyError(f"unknown scenario {scenario!r}; expected one of {list(SCENARIOS)}")
    store = store or CorpusStore()
    out = []
    for cid in store.clips(split=split)[: limit or None]:
        s = synthesize(store.load(cid), rate, SCENARIOS[scenario], clip_seed(cid, seed, f"eval-{scenario}"), channels=True)
        out.append((cid, make_recording(s["R_world"], rate, s["sim"], meta={"clip": cid, "scenario": scenario}),
                    s["pose"]))
    return out


def group_errors(pred: torch.Tensor, gt: torch.Tensor) -> dict[str, torch.Tensor]:
    """Per-frame MPJAE (rad) per group and ``all`` for local rotations ``(T, 24, 3, 3)``."""
    from wearpose.body.skeleton import MAJOR_JOINTS
    from wearpose.evaluate import mpjae, mpjae_groups

    g = mpjae_groups(pred, gt)
    g["all"] = mpjae(pred, gt, MAJOR_JOINTS)
    return g


def evaluate(est: Any, recs: Sequence[tuple[str, Any, torch.Tensor]], *, mode: str = "offline",
             window: tuple[int, int] | None = None, frame_stride: int = 1, mc_samples: int | None = None,
             keep_uncertainty: bool = False, progress: Callable[[int, int], None] | None = None) -> dict[str, Any]:
    """MPJAE per group (degrees, pooled over frames) of ``est`` on prepared recordings.

    Args:
        mode: ``"offline"`` (:meth:`BiraeEstimator.estimate`) or ``"online"``
            (:meth:`BiraeEstimator.estimate_windowed` with ``window``); both count every
            ``frame_stride``-th frame only.
        mc_samples: MC-dropout passes (``0``: one deterministic pass, aleatoric sigma only).
        keep_uncertainty: also return pooled residuals and sigmas ``(N, 15, 3)`` (calibrated with
            the estimator's current ``sigma_scale``), per-joint geodesic errors ``(N, 15)`` and
            per-joint sigmas ``(N, 15)``.
    """
    from wearpose.body.skeleton import MAJOR_JOINTS
    from wearpose.estimators.birae.representations import pose_to_target
    from wearpose.evaluate import joint_angle_errors

    acc: dict[str, list[torch.Tensor]] = {g: [] for g in GROUP_ORDER}
    res_l, sig_l, je_l, js_l = [], [], [], []
    frames = 0
    for i, (cid, rec, gt) in enumerate(recs):
        T = gt.shape[0]
        if mode == "offline":
            track = est.estimate(rec, mc_samples=mc_samples)
            keep = track.valid.clone()
            if frame_stride > 1:
                keep[torch.arange(T) % frame_stride != 0] = False
        else:
            idx = torch.arange(0, T, frame_stride)
            track = est.estimate_windowed(rec, window=window, mc_samples=mc_samples, frames=idx)
            keep = track.valid
        errs = group_errors(track.local_rot, gt)
        for g in GROUP_ORDER:
            acc[g].append(errs[g][keep])
        frames += int(keep.sum())
        if keep_uncertainty:
            res_l.append((pose_to_target(gt) - track.extras["expmap"])[keep])
            sig_l.append(track.extras["sigma"][keep])
            je_l.append(joint_angle_errors(track.local_rot, gt)[keep][:, list(MAJOR_JOINTS)])
            js_l.append(track.uncertainty[keep][:, list(MAJOR_JOINTS)])
        if progress is not None:
            progress(i + 1, len(recs))
    out: dict[str, Any] = {"clips": len(recs), "frames": frames, "mode": mode,
                           "window": list(window or est.window) if mode == "online" else None,
                           "frame_stride": frame_stride,
                           "mc_samples": est.mc_samples if mc_samples is None else mc_samples}
    for g in GROUP_ORDER:
        e = torch.cat(acc[g]) if acc[g] else torch.zeros(0)
        out[f"mpjae_{g}_deg"] = math.degrees(float(e.mean())) if e.numel() else math.nan
    if keep_uncertainty:
        out["_residual"], out["_sigma"] = torch.cat(res_l), torch.cat(sig_l)
        out["_joint_error"], out["_joint_sigma"] = torch.cat(je_l), torch.cat(js_l)
    return out


def public(res: dict[str, Any]) -> dict[str, Any]:
    """``res`` without the private tensors (JSON-able)."""
    return {k: v for k, v in res.items() if not k.startswith("_")}


def calibrate(est: Any, val_recs: Sequence[tuple[str, Any, torch.Tensor]], method: str = "quantile",
              mc_samples: int | None = None) -> dict[str, Any]:
    """Fit the post-hoc sigma scale on validation recordings and store it in ``est``.

    Returns ``{"method", "sigma_scale", "val_within_1sigma_before", "val_within_1sigma_after", ...}``.
    """
    old = est.sigma_scale
    est.sigma_scale = 1.0
    r = evaluate(est, val_recs, mc_samples=mc_samples, keep_uncertainty=True)
    s = fit_sigma_scale(r["_residual"], r["_sigma"], method)
    before = calibration_report(r["_residual"], r["_sigma"])
    after = calibration_report(r["_residual"], r["_sigma"] * s)
    est.sigma_scale = s
    est.calibration = {"method": method, "sigma_scale": s, "val_clips": len(val_recs), "val_frames": r["frames"],
                       "mc_samples": r["mc_samples"], "val_within_1sigma_before": before["within_1sigma"],
                       "val_within_1sigma_after": after["within_1sigma"], "previous_scale": old}
    return dict(est.calibration)


def uncertainty_summary(res: dict[str, Any]) -> dict[str, Any]:
    """Calibration report + reliability curve of an :func:`evaluate` result with ``keep_uncertainty``."""
    rep = calibration_report(res["_residual"], res["_sigma"], joint_error=res["_joint_error"],
                             joint_sigma=res["_joint_sigma"])
    rep["reliability"] = reliability_curve(res["_residual"], res["_sigma"])
    return rep
