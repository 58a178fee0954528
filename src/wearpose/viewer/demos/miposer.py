"""``wearpose demo --kit miposer``: a held-out clip through MI-Poser among metal, MIM off and on.

The clip (after the 1 s calibration T-pose) is worn with the AR-glasses headset (simulated VIO)
and two wrist EM sensors whose poses come from the physical field simulation of
:mod:`wearpose.interference` in the "standard" condition (everyday metal objects the hands pass);
the shipped IK network estimates the upper body from the interfered EM with and without MIM.

Output folder: ``timeline.png`` (per wrist: the true EM position error, the frames MIM flags as
interfered and as "tracking degraded"; below: the upper-body error with and without MIM),
``viewer.html`` (:func:`wearpose.viewer.write_html`: estimate with MIM beside the estimate
without MIM and the ground truth), ``index.html`` (the timeline next to the viewer) and
``metrics.json``.
"""

from __future__ import annotations

import json
import math
import zlib
from pathlib import Path
from typing import Any

import numpy as np
import torch

from wearpose.calibration import calibrate
from wearpose.estimators.miposer.config import UPPER_BODY
from wearpose.estimators.miposer.evaluate import interference_recording, joint_errors
from wearpose.estimators.run import open_model
from wearpose.interference import simulate_condition
from wearpose.motion import load_motion, resample
from wearpose.recording.tpose import tpose_then
from wearpose.sensors import get_kit
from wearpose.viewer import write_html
from wearpose.viewer.figures import pyplot, save_figure
from wearpose.viewer.scene import ESTIMATE_COLOUR, SECOND_ESTIMATE_COLOUR, TRUTH_COLOUR, kit_sites


def _to_calibrated(body: Any, pose: torch.Tensor, trans: torch.Tensor, res: Any) -> tuple[torch.Tensor, torch.Tensor]:
    """A world-frame track in the calibrated world (rotation ``R^{WM}`` and shift of ``res``; SMPL
    rotates about the rest root joint ``J_0``)."""
    Rw = res.world_rotation[0].float()
    tw = res.world_translation[0].float()
    J0 = body.rest_joints(None)[0].float()
    out = pose.clone()
    out[:, 0] = Rw @ pose[:, 0]
    t = (Rw @ (J0 + trans).unsqueeze(-1)).squeeze(-1) * float(res.scale) + tw - J0
    return out, t


def _timeline_png(path: Path, t: np.ndarray, rows: list[dict[str, Any]], t60: np.ndarray, err_off: np.ndarray,
                  err_on: np.ndarray, title: str) -> Path:
    plt = pyplot()
    fig, axes = plt.subplots(len(rows) + 1, 1, figsize=(10, 2.0 * (len(rows) + 1)), sharex=True)
    for ax, r in zip(axes, rows):
        ax.plot(t, r["pos_error_cm"], color="k", lw=0.8, label="true EM position error (cm)")
        top = max(2.0, float(np.nanmax(r["pos_error_cm"])) * 1.1)
        ax.fill_between(t, 0, top, where=r["interfered"], color="tab:orange", alpha=0.35, step="mid", label="MIM: interfered")
        ax.fill_between(t, 0, top, where=r["degraded"], color="tab:red", alpha=0.35, step="mid", label="MIM: degraded")
        ax.set_ylim(0, top)
        ax.set_ylabel(r["name"], fontsize=8)
        ax.legend(loc="upper right", fontsize=7)
    ax = axes[-1]
    ax.plot(t60, err_off, color="tab:red", lw=0.9, label="upper-body MPJPE, MIM off (cm)")
    ax.plot(t60, err_on, color="tab:green", lw=0.9, label="upper-body MPJPE, MIM on (cm)")
    ax.set_xlabel("time (s)")
    ax.legend(loc="upper right", fontsize=7)
    axes[0].set_title(title, fontsize=9)
    return save_figure(fig, path, dpi=90)


def run_demo(clip: str, out: str | Path, weights: str = "miposer_cpu", condition: str = "standard",
             max_seconds: float = 10.0, seed: int = 0) -> dict[str, Any]:
    """Run the demo (module doc) on ``clip`` (clip id, corpus path or motion file) into ``out``.

    Returns:
        ``{"clip", "frames", "fps", "html", "viewer", "timeline", "title", "weights", "metrics"}``; metrics
        in report units: ``mpjpe_upper_mim_off_cm``, ``mpjpe_upper_mim_on_cm`` (clip frames),
        ``interfered_true_pct`` (120 Hz frames with a wrist's true EM error > 2 cm or 5 deg),
        ``flagged_pct`` (frames MIM flagged), ``max_em_error_cm``.
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    source = open_model(weights)  # shipped weights or a checkpoint file, read here once
    est = source.make()
    body = est.body
    seq = load_motion(clip, rest_joints=body.rest_joints())
    seq = resample(seq, est.fps) if abs(seq.fps - est.fps) > 1e-9 else seq
    seq = seq.slice(0, min(seq.num_frames, int(round(max_seconds * seq.fps))))
    mm, prefix = tpose_then(seq, est.config.tpose_s, est.config.blend_s)
    s = (zlib.crc32(f"demo:{clip}".encode()) + seed) % (2 ** 31 - 1)
    specs = get_kit(est.kit_name).of_kind("em6dof")
    sites, names = [sp.site for sp in specs], [sp.name for sp in specs]
    cs = simulate_condition(mm, condition, sensors=sites, seed=s, body=body)
    imu = {n: (cs[site].gyro, cs[site].acc) for n, site in zip(names, sites)}
    rec = interference_recording(mm, est, cs, "measured", s)
    hold = int(round(est.config.tpose_s * est.fps))
    res = calibrate(rec, "miposer-tpose", window=(0.1, (hold - 1) / est.fps), body=body)
    off = est.estimate(rec, calibration=res)
    est.mim = True
    on = est.estimate(rec, calibration=res, imu=imu)
    gt_pose, gt_trans = _to_calibrated(body, mm.pose.float(), mm.trans.float(), res)
    clip_f = torch.arange(prefix, mm.num_frames)
    e_off = joint_errors(body, off.local_rot[clip_f], gt_pose[clip_f])[:, list(UPPER_BODY)].mean(1).numpy() * 100
    e_on = joint_errors(body, on.local_rot[clip_f], gt_pose[clip_f])[:, list(UPPER_BODY)].mean(1).numpy() * 100
    info = on.extras["interference"]
    t120 = np.asarray(info[names[0]]["timestamps"])
    rows, bad = [], np.zeros(len(t120), bool)
    for n, site in zip(names, sites):
        c = cs[site]
        k = min(len(t120), c.num_frames)
        b = (c.pos_error[:k] > 0.02) | (c.rot_error[:k] > math.radians(5.0))
        bad[:k] |= b
        rows.append({"name": n, "pos_error_cm": c.pos_error[:k] * 100, "interfered": info[n]["interfered"][:k],
                     "degraded": info[n]["degraded"][:k]})
    t120 = t120[: min(len(r["pos_error_cm"]) for r in rows)]
    rows = [{k: (v[: len(t120)] if isinstance(v, np.ndarray) else v) for k, v in r.items()} for r in rows]
    flagged = np.zeros(len(t120), bool)
    for r in rows:
        flagged |= r["interfered"]
    t60 = clip_f.numpy() / est.fps
    metrics = {"mpjpe_upper_mim_off_cm": float(e_off.mean()), "mpjpe_upper_mim_on_cm": float(e_on.mean()),
               "interfered_true_pct": float(bad[: len(t120)].mean() * 100), "flagged_pct": float(flagged.mean() * 100),
               "max_em_error_cm": float(max(r["pos_error_cm"].max() for r in rows))}
    title = (f"{clip}: MI-Poser ({weights}) among metal ('{condition}'), {mm.num_frames} frames at {est.fps:g} fps "
             f"(first {prefix} = calibration T-pose)")
    png = _timeline_png(out / "timeline.png", t120, rows, t60, e_off, e_on, title)
    viewer = write_html(out / "viewer.html", body, on.local_rot, on.betas, on.trans, est.fps, title=title,
                        label="MI-Poser + MIM", compare=[("MI-Poser, MIM off", off.local_rot, off.betas, off.trans),
                                                         ("ground truth", gt_pose, mm.betas.float(), gt_trans)],
                        colours=[ESTIMATE_COLOUR, SECOND_ESTIMATE_COLOUR, TRUTH_COLOUR],
                        site_names=kit_sites(est.kit_name, body), sites_label=f"headset + {len(names)} wrist EM ({est.kit_name})",
                        info={"upper-body MPJPE MIM on (cm)": f"{metrics['mpjpe_upper_mim_on_cm']:.2f}",
                              "MIM off (cm)": f"{metrics['mpjpe_upper_mim_off_cm']:.2f}",
                              "interfered frames (%)": f"{metrics['interfered_true_pct']:.1f}"})
    index = out / "index.html"
    index.write_text(
        "<!DOCTYPE html><html><head><meta charset='utf-8'><title>MI-Poser demo</title><style>body{margin:0;"
        "font:13px sans-serif;background:#1d1f24;color:#ddd;display:flex;height:100vh}#l{width:42%;overflow:auto;"
        "padding:8px}#l img{width:100%;background:#fff}iframe{flex:1;border:0}</style></head><body><div id='l'>"
        f"<p>{title}</p><img src='timeline.png' alt='interference timeline'><pre>{json.dumps(metrics, indent=1)}</pre>"
        "</div><iframe src='viewer.html'></iframe></body></html>", encoding="utf-8")
    result = {"clip": clip, "frames": mm.num_frames, "fps": est.fps, "html": str(index), "viewer": str(viewer),
              "timeline": str(png), "title": title, "weights": weights,
              "weights_licence": source.card.get("licence", ""),
              "metrics": metrics,
              "mim_position_fallback": info.get("fallback")}
    (out / "metrics.json").write_text(json.dumps(result, indent=2))
    return result
