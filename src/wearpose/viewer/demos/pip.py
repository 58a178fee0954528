"""``wearpose demo --kit imu6``: a clip -> 6 simulated IMUs -> PIP (kinematics + physics) ->
metrics, physical properties and a page with the estimate beside the ground truth.

The simulated recording is what ``wearpose simulate --kit imu6`` writes: a 1 s calibration
T-pose before the clip (marked in ``meta["calibration_window"]``, :mod:`wearpose.recording.tpose`),
IMUs on the skin; the estimator calibrates on that window and runs on the recording, as
``wearpose estimate`` does. Metrics cover the clip (not the T-pose), in the calibrated world.

Also :func:`physical_plots`: ground reaction forces of both feet (with body weight) and arm
joint torques over time, as PNG figures a person can look at (matplotlib, if installed).
"""

from __future__ import annotations

import json
import math
import warnings
from pathlib import Path
from typing import Any

import torch

from wearpose.estimators.pip.data import EDGE_FRAMES
from wearpose.estimators.run import estimate_recording, open_model
from wearpose.estimators.seeding import clip_seed
from wearpose.evaluate import compute_all
from wearpose.geometry import heading, rotation_y
from wearpose.motion import load_motion, resample
from wearpose.recording import CALIBRATION_WINDOW_KEY, Recording, prepend_tpose
from wearpose.sensors import simulate
from wearpose.viewer import write_html
from wearpose.viewer.figures import pyplot, save_figure
from wearpose.viewer.scene import ESTIMATE_COLOUR, TRUTH_COLOUR, kit_sites

#: Gravity magnitude used for "body weight", m/s^2.
G = 9.81
#: Seconds of calibration T-pose before the clip (PIP calibrates sensor-to-bone from 1 s, Sec. 3.1).
TPOSE_S = 1.0


def physical_summary(track: Any, mass_kg: float) -> dict[str, float]:
    """GRF and contact figures of a physics :class:`~wearpose.estimators.PoseTrack`: mean summed
    vertical GRF over body weight (%), share of frames with both / one / no foot in contact (%),
    alternation (frames where the left foot carries more than the right, %), max penetration (cm),
    mean absolute shoulder/elbow torque (N m)."""
    ex = track.extras
    grf_y = ex["grf"][..., 1]
    flags = ex["contact_flags"].float()
    tau = ex["torques"]
    arm = tau[:, [16, 17, 18, 19]].norm(dim=-1)
    return {"grf_over_weight_pct": float(grf_y.sum(-1).mean() / (mass_kg * G) * 100),
            "both_feet_contact_pct": float((flags.sum(-1) == 2).float().mean() * 100),
            "no_contact_pct": float((flags.sum(-1) == 0).float().mean() * 100),
            "left_carries_more_pct": float((grf_y[:, 0] > grf_y[:, 1]).float().mean() * 100),
            "max_penetration_cm": float(ex["penetration_m"].max() * 100),
            "arm_torque_mean_nm": float(arm.mean()), "mass_kg": float(mass_kg)}


def physical_plots(track: Any, mass_kg: float, out_png: str | Path, title: str) -> Path | None:
    """Two stacked plots: vertical GRF of the left/right foot and their sum against body weight;
    torque magnitude at the shoulders and elbows. Returns the PNG path, or None without matplotlib."""
    try:
        plt = pyplot()
    except ImportError:
        return None
    ex = track.extras
    t = torch.arange(track.num_frames) / track.fps
    grf = ex["grf"][..., 1]
    tau = ex["torques"].norm(dim=-1)
    fig, ax = plt.subplots(2, 1, figsize=(9, 6), sharex=True)
    ax[0].plot(t, grf[:, 0], label="left foot")
    ax[0].plot(t, grf[:, 1], label="right foot")
    ax[0].plot(t, grf.sum(-1), "k", lw=0.8, label="sum")
    ax[0].axhline(mass_kg * G, color="r", ls="--", lw=0.8, label=f"body weight ({mass_kg:.0f} kg)")
    ax[0].set_ylabel("vertical GRF [N]")
    ax[0].legend(loc="upper right", fontsize=8)
    for j, name in ((16, "left shoulder"), (17, "right shoulder"), (18, "left elbow"), (19, "right elbow")):
        ax[1].plot(t, tau[:, j], label=name)
    ax[1].set_ylabel("|joint torque| [N m]")
    ax[1].set_xlabel("time [s]")
    ax[1].legend(loc="upper right", fontsize=8)
    fig.suptitle(title, fontsize=10)
    return save_figure(fig, out_png, dpi=90)


def run_demo(clip: str, out: str | Path, weights: str = "pip_cpu", max_seconds: float = 10.0, seed: int = 0,
             physics: bool = True) -> dict[str, Any]:
    """Simulate 6 IMUs on ``clip``, run shipped PIP weights with physics, evaluate.

    Args:
        clip: clip id, corpus path or motion file.
        out: output folder (``demo.html``, ``metrics.json``, ``physics.png``, ``recording.npz``).
        weights: shipped weights name or a checkpoint path.
        max_seconds: clip length used.
        seed: simulation seed (IMU noise).
        physics: run the physics optimizer.

    Returns:
        ``{"clip", "frames", "fps", "weights", "html", "title", "metrics": {...}}``.
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    source = open_model(weights)  # shipped weights or a checkpoint file, read here once
    path, licence = Path(source.path or weights), source.card.get("licence", "")
    est = source.make()
    est.physics = bool(physics)
    body = est.body
    seq = load_motion(clip, rest_joints=body.rest_joints())
    if abs(seq.fps - est.fps) > 1e-9:
        seq = resample(seq, est.fps)
    seq = seq.slice(0, min(seq.num_frames, int(round(max_seconds * seq.fps))))
    # What `wearpose simulate --kit imu6` writes and a wearer does: a calibration T-pose first,
    # IMUs on the skin (sensor-to-bone offsets unknown to PIP), the hold marked in the meta.
    full, window = prepend_tpose(seq, TPOSE_S)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the kit's documented site substitutions warn per call
        sim = simulate(full, est.config.kit, body, seed=clip_seed(clip, seed, "demo"), noise="default", rate=est.fps)
    rec = Recording.from_simulation(sim, full, meta={CALIBRATION_WINDOW_KEY: window, "clip": clip})
    rec.save(out / "recording.npz")
    # PIP's known initial state (Sec. 3.1.2) is the calibration pose: a T-pose at rest at the
    # origin, facing +Z; the subject's shape is known, as in PIP.
    est.set_initial_state(betas=seq.betas)
    run = estimate_recording(source, rec, out / "recording.npz", estimator=est)  # calibrates on the marked T-pose
    track = run.estimated  # metrics in the calibrated world; the page shows run.track (feet on the floor)
    # Ground truth in the calibrated world: the T-pose faced the clip's first heading and the
    # estimate starts at the origin, so rotate by minus that heading about +Y around the start.
    R = rotation_y(-heading(full.pose[0, 0].double())).float()
    gt_pose = full.pose.float().clone()
    gt_pose[:, 0] = R @ gt_pose[:, 0]
    gt_trans = (full.trans.float() - full.trans[0].float()) @ R.T
    gt_betas = full.betas.float()
    # Metrics on the clip only (not the T-pose prefix), without its first/last EDGE_FRAMES
    # (many clips start or end with a jump; PIP's evaluation trims the same frames).
    prefix = int(round(window["prefix_s"] * est.fps))
    n = min(track.num_frames, full.num_frames)
    ev = slice(min(prefix + EDGE_FRAMES, n - 1), max(n - EDGE_FRAMES, min(prefix + EDGE_FRAMES, n - 1) + 1))
    with torch.no_grad():
        p = body(track.local_rot[ev], track.betas, track.trans[ev])
        g = body(gt_pose[ev], gt_betas, gt_trans[ev])
    m = compute_all({"local_rot": track.local_rot[ev], "joints": p.joints, "vertices": p.vertices,
                     "trans": track.trans[ev]},
                    {"local_rot": gt_pose[ev], "joints": g.joints, "vertices": g.vertices, "trans": gt_trans[ev]},
                    fps=est.fps, mask_ignored=True)
    frames = len(range(*ev.indices(n)))
    keep = ("sip_error_deg", "angular_error_deg", "positional_error_cm", "mesh_error_cm", "jitter_abs_km_s3",
            "translation_error_cm")
    metrics = {k: float(m[k]) for k in keep if k in m and math.isfinite(m[k])}
    png = None
    if track.extras.get("physics"):
        mass = est._char[1].mass_kg
        metrics.update({f"physics_{k}": v for k, v in physical_summary(track, mass).items()})
        png = physical_plots(track, mass, out / "physics.png", f"PIP on {clip}: ground reaction forces and arm torques")
    title = (f"{clip}: PIP ({path.stem}) from 6 simulated IMUs after a {TPOSE_S:g} s calibration T-pose, "
             f"{frames} clip frames evaluated at {est.fps:g} fps"
             f"{', physics (dual PD)' if track.extras.get('physics') else ', no physics'}")
    lift = run.track.trans[:1] - track.trans[:1]  # place_in_world's vertical shift, given to the truth too
    html = write_html(out / "demo.html", body, run.track.local_rot, run.track.betas, run.track.trans, est.fps, title=title,
                      label=f"estimate ({len(est.sensor_names)} IMUs, PIP)",
                      compare=[("ground truth", gt_pose[:n], gt_betas, gt_trans[:n] + lift)],
                      colours=[ESTIMATE_COLOUR, TRUTH_COLOUR], site_names=kit_sites(est.kit_name, body, est.sensor_names),
                      sites_label=f"{len(est.sensor_names)} IMUs ({est.kit_name})",
                      info={"SIP err (deg)": f"{metrics.get('sip_error_deg', float('nan')):.1f}",
                            "mesh err (cm)": f"{metrics.get('mesh_error_cm', float('nan')):.1f}"})
    result = {"clip": clip, "frames": frames, "fps": est.fps, "tpose_s": TPOSE_S, "weights": str(path), "weights_licence": licence,
              "title": title, "html": str(html), "physics_png": str(png) if png else None, "metrics": metrics}
    (out / "metrics.json").write_text(json.dumps(result, indent=2))
    return result
