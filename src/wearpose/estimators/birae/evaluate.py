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

import json
import math
import shlex
from pathlib import Path
from typing import Any, Callable, Sequence

import torch

from wearpose.body.skeleton import MAJOR_JOINTS
from wearpose.estimators.birae.data import SCENARIOS, clip_seed, make_recording, synthesize
from wearpose.estimators.birae.representations import pose_to_target
from wearpose.estimators.birae.uncertainty import (
    GAUSS_1SIGMA, calibration_report, coverage, fit_sigma_scale, reliability_curve,
)
from wearpose.estimators.checkpoint import load_checkpoint
from wearpose.evaluate.metrics import joint_angle_errors, mpjae, mpjae_groups
from wearpose.geometry import rotation_y
from wearpose.motion import CorpusStore

GROUP_ORDER = ("distal", "tracking", "other", "all")


def scenario_recordings(split: str = "test", scenario: str = "clean", rate: float = 60.0, limit: int | None = None,
                        store: Any = None, seed: int = 0, heading_offset_deg: float = 0.0
                        ) -> list[tuple[str, Any, torch.Tensor]]:
    """``[(clip_id, recording, gt_pose (T, 24, 3, 3))]`` for the first ``limit`` clips of ``split``.

    Args:
        heading_offset_deg: if > 0, every sensor's world orientation is also turned about the
            vertical by its own constant angle ``U(-a, a)`` (seeded per clip): a diagnostic of
            how much a model reads heading at all (no other change to the scenario).
    """
    if scenario not in SCENARIOS:
        raise KeyError(f"unknown scenario {scenario!r}; expected one of {list(SCENARIOS)}")
    store = store or CorpusStore()
    out = []
    for cid in store.clips(split=split)[: limit or None]:
        s = synthesize(store.load(cid), rate, SCENARIOS[scenario], clip_seed(cid, seed, f"eval-{scenario}"), channels=True)
        R = s["R_world"]
        if heading_offset_deg > 0:
            g = torch.Generator().manual_seed(clip_seed(cid, seed, "eval-heading-offset"))
            u = (2 * torch.rand(R.shape[1], generator=g, dtype=torch.float64) - 1) * math.radians(heading_offset_deg)
            R = (rotation_y(u).to(R)[None] @ R).contiguous()
        out.append((cid, make_recording(R, rate, s["sim"], meta={"clip": cid, "scenario": scenario,
                                                                 "heading_offset_deg": heading_offset_deg}),
                    s["pose"]))
    return out


def group_errors(pred: torch.Tensor, gt: torch.Tensor) -> dict[str, torch.Tensor]:
    """Per-frame MPJAE (rad) per group and ``all`` for local rotations ``(T, 24, 3, 3)``."""
    g = mpjae_groups(pred, gt)
    g["all"] = mpjae(pred, gt, MAJOR_JOINTS)
    return g


def evaluate(est: Any, recs: Sequence[tuple[str, Any, torch.Tensor]], *, mode: str = "offline",
             window: tuple[int, int] | None = None, frame_stride: int = 1, mc_samples: int | None = None,
             keep_uncertainty: bool = False, progress: Callable[[int, int], None] | None = None) -> dict[str, Any]:
    """MPJAE per group (degrees, pooled over frames) of ``est`` on prepared recordings.

    Args:
        mode: ``"offline"`` (:meth:`BiraeEstimator.estimate`), ``"online"``
            (:meth:`BiraeEstimator.estimate_windowed` with ``window``) or ``"stream"``
            (:meth:`BiraeEstimator.estimate_streamed`: the incremental online mode, its future
            window from ``window`` or the estimator's, no MC samples); all count every
            ``frame_stride``-th frame only.
        mc_samples: MC-dropout passes (``0``: one deterministic pass, aleatoric sigma only).
        keep_uncertainty: also return pooled residuals and sigmas ``(N, 15, 3)`` (calibrated with
            the estimator's current ``sigma_scale``), per-joint geodesic errors ``(N, 15)`` and
            per-joint sigmas ``(N, 15)``.

    Returns:
        ``mpjae_<group>_deg`` pooled over frames, ``clips``, ``frames``, the settings, and
        ``per_clip``: ``[{"clip", "frames", "mpjae_<group>_deg"}]`` in order (the pooled arrays
        hold the clips' frames in the same order).
    """
    acc: dict[str, list[torch.Tensor]] = {g: [] for g in GROUP_ORDER}
    res_l, sig_l, je_l, js_l = [], [], [], []
    per_clip: list[dict[str, Any]] = []
    frames = 0
    for i, (cid, rec, gt) in enumerate(recs):
        T = gt.shape[0]
        if mode == "offline":
            track = est.estimate(rec, mc_samples=mc_samples)
            keep = track.valid.clone()
            if frame_stride > 1:
                keep[torch.arange(T) % frame_stride != 0] = False
        elif mode == "stream":
            idx = torch.arange(0, T, frame_stride)
            old_window = est.window
            est.set_window(*(window or est.window))
            try:
                track = est.estimate_streamed(rec, frames=idx)
            finally:
                est.set_window(*old_window)
            keep = track.valid
        else:
            idx = torch.arange(0, T, frame_stride)
            track = est.estimate_windowed(rec, window=window, mc_samples=mc_samples, frames=idx)
            keep = track.valid
        errs = group_errors(track.local_rot, gt)
        for g in GROUP_ORDER:
            acc[g].append(errs[g][keep])
        n = int(keep.sum())
        frames += n
        per_clip.append({"clip": cid, "frames": n, **{f"mpjae_{g}_deg": math.degrees(float(errs[g][keep].mean()))
                                                      for g in GROUP_ORDER if n}})
        if keep_uncertainty:
            res_l.append((pose_to_target(gt) - track.extras["expmap"])[keep])
            sig_l.append(track.extras["sigma"][keep])
            je_l.append(joint_angle_errors(track.local_rot, gt)[keep][:, list(MAJOR_JOINTS)])
            js_l.append(track.uncertainty[keep][:, list(MAJOR_JOINTS)])
        if progress is not None:
            progress(i + 1, len(recs))
    out: dict[str, Any] = {"clips": len(recs), "frames": frames, "mode": mode,
                           "window": list(window or est.window) if mode in ("online", "stream") else None,
                           "frame_stride": frame_stride,
                           "mc_samples": 0 if mode == "stream" else (est.mc_samples if mc_samples is None else mc_samples),
                           "per_clip": per_clip}
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


def motion_content(clip_id: str) -> str:
    """Motion content of a corpus clip id (folder + name without style and take number), e.g.
    ``bandai/bandai-C/dataset-2_run_normal_003`` -> ``bandai/bandai-C/dataset-2_run``."""
    head, _, name = clip_id.rpartition("/")
    parts = name.split("_")
    if len(parts) >= 3 and parts[-1].isdigit():
        parts = parts[:-2]
    elif len(parts) >= 2 and parts[-1].isdigit():
        parts = parts[:-1]
    return f"{head}/{'_'.join(parts)}" if head else "_".join(parts)


def content_folds(clip_ids: Sequence[str], k: int = 3) -> list[int]:
    """Fold index per clip: whole motion contents (:func:`motion_content`) dealt round-robin to
    ``k`` folds, largest first, so no content is in two folds."""
    groups: dict[str, list[int]] = {}
    for i, c in enumerate(clip_ids):
        groups.setdefault(motion_content(c), []).append(i)
    fold = [0] * len(clip_ids)
    for j, (_, idx) in enumerate(sorted(groups.items(), key=lambda kv: (-len(kv[1]), kv[0]))):
        for i in idx:
            fold[i] = j % k
    return fold


CAL_METHODS = ("quantile", "nll")


def calibrate(est: Any, val_recs: Sequence[tuple[str, Any, torch.Tensor]], method: str = "auto",
              mc_samples: int | None = None, folds: int = 3) -> dict[str, Any]:
    """Fit the post-hoc sigma scale on validation recordings and store it in ``est``.

    ``method``: ``"quantile"`` (68.27 % of the validation residuals inside +-1 sigma), ``"nll"``
    (Laves et al.) or ``"auto"``: choose between them on the validation data alone by
    cross-validation over motion contents (:func:`content_folds`: fit on the other folds,
    measure the +-1 sigma coverage on the held-out fold, whose motions the fit never saw, as on
    a test split) and keep the method whose held-out coverage is closest to 68.27 % on average;
    the chosen method is then fitted on all validation recordings.

    Returns ``{"method", "sigma_scale", "val_within_1sigma_before", "val_within_1sigma_after",
    "cv": {method: {"fold_coverage": [...], "mean_abs_dev": ...}} (auto), ...}``.
    """
    if method not in (*CAL_METHODS, "auto"):
        raise ValueError(f"calibrate: method must be one of {CAL_METHODS} or 'auto', got {method!r}")
    old = est.sigma_scale
    est.sigma_scale = 1.0
    fold = content_folds([c for c, _, _ in val_recs], folds) if method == "auto" else [0] * len(val_recs)
    parts = []  # per fold: (residual, sigma, frames)
    for f in sorted(set(fold)):
        r = evaluate(est, [x for x, k in zip(val_recs, fold) if k == f], mc_samples=mc_samples, keep_uncertainty=True)
        parts.append((r["_residual"], r["_sigma"], r["frames"], r["mc_samples"]))
    res, sig = torch.cat([p[0] for p in parts]), torch.cat([p[1] for p in parts])
    cv: dict[str, Any] = {}
    chosen = method
    if method == "auto":
        for m in CAL_METHODS:
            cov = []
            for f in range(len(parts)):
                rest = [p for j, p in enumerate(parts) if j != f]
                s_f = fit_sigma_scale(torch.cat([p[0] for p in rest]), torch.cat([p[1] for p in rest]), m)
                cov.append(coverage(parts[f][0], parts[f][1] * s_f))
            cv[m] = {"fold_coverage": cov, "mean_abs_dev": sum(abs(c - GAUSS_1SIGMA) for c in cov) / len(cov)}
        chosen = min(CAL_METHODS, key=lambda m: cv[m]["mean_abs_dev"])
    s = fit_sigma_scale(res, sig, chosen)
    before = calibration_report(res, sig)
    after = calibration_report(res, sig * s)
    est.sigma_scale = s
    est.calibration = {"method": chosen, "requested": method, "sigma_scale": s, "val_clips": len(val_recs),
                       "val_frames": sum(p[2] for p in parts), "mc_samples": parts[0][3] if parts else mc_samples,
                       "val_within_1sigma_before": before["within_1sigma"],
                       "val_within_1sigma_after": after["within_1sigma"], "previous_scale": old,
                       "scales": {m: fit_sigma_scale(res, sig, m) for m in CAL_METHODS}}
    if cv:
        est.calibration["cv"] = {"folds": len(parts), "by": "motion content", **cv}
    return dict(est.calibration)


def per_clip_uncertainty(res: dict[str, Any]) -> list[dict[str, float]]:
    """Per clip of an :func:`evaluate` result with ``keep_uncertainty`` (its ``per_clip`` order):
    ``within_1sigma_pct`` / ``within_2sigma_pct`` (coverage of the calibrated sigma, %) and
    ``mean_sigma_deg`` (the mean per-joint sigma of the 15 major joints, degrees)."""
    out, start = [], 0
    for c in res["per_clip"]:
        sl = slice(start, start + c["frames"])
        start += c["frames"]
        r, s = res["_residual"][sl], res["_sigma"][sl]
        out.append({} if not c["frames"] else {
            "within_1sigma_pct": 100 * coverage(r, s, 1.0), "within_2sigma_pct": 100 * coverage(r, s, 2.0),
            "mean_sigma_deg": math.degrees(float(res["_joint_sigma"][sl].mean()))})
    return out


def uncertainty_summary(res: dict[str, Any]) -> dict[str, Any]:
    """Calibration report + reliability curve of an :func:`evaluate` result with ``keep_uncertainty``."""
    rep = calibration_report(res["_residual"], res["_sigma"], joint_error=res["_joint_error"],
                             joint_sigma=res["_joint_sigma"])
    rep["reliability"] = reliability_curve(res["_residual"], res["_sigma"])
    return rep


def _epoch_rows(log: Path) -> dict[int, dict[str, Any]]:
    """Last ``"epoch"`` record per epoch of a training ``log.jsonl`` (a resumed epoch logs again)."""
    rows: dict[int, dict[str, Any]] = {}
    if log.is_file():
        for line in log.read_text().splitlines():
            try:
                r = json.loads(line)
            except ValueError:  # a line torn by a killed run
                continue
            if r.get("type") == "epoch":
                rows[int(r["epoch"])] = r
    return rows


def _run_dir(path: Path, ckpt: Any) -> Path | None:
    """The training run directory of a checkpoint: its own folder when it holds ``clean/`` or
    ``aug/`` (``<run>/best.pt``, ``<run>/calibrated.pt``), the phase's run when the checkpoint sits
    in ``<run>/<phase>/``, else the ``--out`` of its training command (shipped weights)."""
    for d in (path.parent, path.parent.parent):
        if (d / "clean").is_dir() or (d / "aug").is_dir():
            return d
    try:
        argv = shlex.split(ckpt.train_command or "")
    except ValueError:
        argv = []
    for i, a in enumerate(argv):
        out = argv[i + 1] if a == "--out" and i + 1 < len(argv) else a[6:] if a.startswith("--out=") else None
        if out and Path(out).is_dir():
            return Path(out)
    return None


def training_chain(path: str | Path, max_depth: int = 10) -> list[dict[str, Any]]:
    """The training runs behind a BiRAE checkpoint, oldest first, with the budget each contributed.

    Follows ``meta["init_from"]`` (``wearpose train birae --init-from``) back to the first run.
    For every run: its command, the phase the checkpoint came from, and per phase the epochs and
    optimiser steps up to the *kept* (best) epoch, which is what the next run started from, read
    from the phase's ``log.jsonl``; ``train_seconds`` is the wall-clock of those epochs (depends on
    the machine's load). A phase whose log is missing reports ``None`` figures.

    Returns ``[{"run", "checkpoint", "command", "init_from", "val_clips", "phases": {"clean"|"aug": {"epochs",
    "steps", "train_seconds", "val_mpjae_deg"}}, "steps"}]``; ``steps`` is ``None`` if unknown.
    """
    chain: list[dict[str, Any]] = []
    p: Path | None = Path(path)
    seen: set[str] = set()
    while p is not None and len(chain) < max_depth and str(p.resolve()) not in seen:
        seen.add(str(p.resolve()))
        ck = load_checkpoint(p)
        run = _run_dir(p, ck)
        phase = ck.meta.get("phase", "aug")
        phases: dict[str, Any] = {}
        # an augmented-phase model started from the same run's best clean checkpoint
        for ph in (("clean", "aug") if phase == "aug" else ("clean",)):
            kept = ck.meta.get("epoch") if ph == phase else None
            if kept is None and run is not None and (run / ph / "best.pt").is_file():
                kept = load_checkpoint(run / ph / "best.pt").meta.get("epoch")
            rows = _epoch_rows(run / ph / "log.jsonl") if run is not None else {}
            if kept is None:
                if ph != phase and run is not None and (run / ph).is_dir() and not rows:
                    phases[ph] = {"epochs": 0, "steps": 0, "train_seconds": 0.0, "val_mpjae_deg": None}
                continue
            kept = int(kept)
            ok = kept in rows
            phases[ph] = {"epochs": kept, "steps": int(rows[kept]["steps"]) if ok else None,
                          "train_seconds": sum(float(r.get("train_seconds", 0.0)) for e, r in rows.items() if e <= kept) if ok else None,
                          "val_mpjae_deg": rows[kept].get("val_mpjae_deg") if ok else None}
        steps = [v["steps"] for v in phases.values()]
        init = ck.meta.get("init_from")
        chain.append({"run": str(run) if run is not None else None, "checkpoint": str(p), "command": ck.train_command,
                      "init_from": init, "val_clips": ck.meta.get("val_clips"), "phases": phases,
                      "steps": sum(steps) if steps and None not in steps else None})
        p = Path(init) if init and Path(init).is_file() else None
    return chain[::-1]


def budget_summary(chain: list[dict[str, Any]]) -> dict[str, Any]:
    """Totals of a :func:`training_chain`: ``{"epochs_clean", "epochs_aug", "steps", "train_seconds",
    "runs", "text"}`` (``text``: one line, e.g. ``"birae6_cpu (clean 1 + aug 3 ep, 452 steps) ->
    birae6_v2 (aug 13 ep, 1469 steps)"``); unknown parts make the totals ``None``."""
    def total(key: str, ph: str | None = None) -> Any:
        if any(not c["phases"] for c in chain):  # a run without logs: its budget is unknown
            return None
        vals = [v[key] for c in chain for k, v in c["phases"].items() if ph is None or k == ph]
        return None if None in vals else (sum(vals) if vals else 0)

    parts = []
    for c in chain:
        name = Path(c["run"]).name if c["run"] else Path(c["checkpoint"]).stem
        eps = " + ".join(f"{k} {v['epochs']}" for k, v in c["phases"].items() if v["epochs"])
        parts.append(f"{name} ({eps or 'no'} ep, {c['steps'] if c['steps'] is not None else '?'} steps)")
    return {"epochs_clean": total("epochs", "clean"), "epochs_aug": total("epochs", "aug"), "steps": total("steps"),
            "train_seconds": total("train_seconds"), "runs": len(chain), "text": " -> ".join(parts)}
