"""``wearpose demo --kit mimu6``: BiRAE on one clip with simulated MIMUs and shipped weights.

The clip is resampled to 60 Hz and its six ``mimu6`` sensors synthesised twice
(:data:`wearpose.estimators.birae.data.SCENARIOS`): with real-sensor ``noise`` and with yaw drift +
strong ``magnetic`` disturbance (fixed demo seeds). The 6-param model (``birae6_cpu``) runs on the
noisy recording: MPJAE per joint group and the calibrated-sigma coverage against the ground truth,
a page with the estimate (root orientation from the root sensor, ground-truth translation)
beside the ground truth, and ``uncertainty.png``: left shoulder, left elbow and right knee exp-map
components with their +-1 sigma band (the paper's Figs. 7-10). Both the 6-param and the 3-param
(``birae3_cpu``) models then run on the disturbed recording, whose MPJAE shows the 3-param
model's robustness (Table 4).
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import torch

from wearpose.body import BodyModel, JOINT_INDEX, MAJOR_JOINTS
from wearpose.estimators.birae.data import SCENARIOS, make_recording, synthesize
from wearpose.estimators.birae.evaluate import group_errors
from wearpose.estimators.birae.representations import pose_to_target
from wearpose.estimators.birae.uncertainty import coverage
from wearpose.estimators.run import open_model
from wearpose.estimators.seeding import clip_seed
from wearpose.motion import load_motion
from wearpose.viewer import write_html
from wearpose.viewer.demos.birae_plots import uncertainty_bands
from wearpose.viewer.scene import ESTIMATE_COLOUR, TRUTH_COLOUR, kit_sites
from wearpose.weights import card

WEIGHTS = {"6param": "birae6_cpu", "3param": "birae3_cpu"}
BAND_JOINTS = (("left shoulder", "left_shoulder"), ("left elbow", "left_elbow"), ("right knee", "right_knee"))


def run_demo(clip: str, out: str | Path, max_seconds: float = 10.0, seed: int = 0) -> dict[str, Any]:
    """Run the demo (module doc); returns ``{"clip", "frames", "fps", "html", "title", "metrics", "plot", ...}``."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    body = BodyModel()
    seq = load_motion(clip, rest_joints=body.rest_joints())
    seq = seq.slice(0, min(seq.num_frames, int(round(max_seconds * seq.fps))))
    ests = {k: open_model(w).make() for k, w in WEIGHTS.items()}  # each checkpoint read once
    k = 180.0 / math.pi
    noisy = synthesize(seq, 60.0, SCENARIOS["noise"], clip_seed(clip, seed, "birae:demo-noise"), channels=True)
    rec = make_recording(noisy["R_world"], 60.0, noisy["sim"], motion=noisy["motion"], meta={"clip": clip})
    rec.save(out / "recording.npz")
    est = ests["6param"]
    track = est.estimate(rec)
    gt = noisy["pose"]
    errs = group_errors(track.local_rot, gt)

    resid = pose_to_target(gt) - track.extras["expmap"]
    metrics = {f"mpjae_{g}_deg": float(e.mean() * k) for g, e in errs.items()}
    metrics["within_1sigma_pct"] = 100 * coverage(resid, track.extras["sigma"])
    metrics["mean_sigma_deg"] = float(track.extras["sigma"].mean() * k)
    mag = synthesize(seq, 60.0, SCENARIOS["magnetic"], clip_seed(clip, seed, "birae:demo-magnetic"), channels=True)
    mrec = make_recording(mag["R_world"], 60.0, mag["sim"], meta={"clip": clip})
    for name, e in ests.items():
        metrics[f"magnetic_mpjae_{name}_deg"] = float(group_errors(e.estimate(mrec).local_rot, gt)["all"].mean() * k)
    metrics["noise_mpjae_3param_deg"] = float(group_errors(ests["3param"].estimate(rec).local_rot, gt)["all"].mean() * k)
    pos = {j: i for i, j in enumerate(MAJOR_JOINTS)}
    plot = uncertainty_bands(out / "uncertainty.png", 60.0, track.extras["expmap"], track.extras["sigma"],
                             pose_to_target(gt), [(lab, pos[JOINT_INDEX[j]]) for lab, j in BAND_JOINTS],
                             f"BiRAE 6-param on {clip} (simulated MIMU noise): estimate +-1 sigma vs ground truth")
    world = est.with_root(track, rec)
    m = noisy["motion"]
    kit, names = est.kit_name, est.sensor_names
    html = write_html(out / "demo.html", body, world.local_rot, m.betas, m.trans, 60.0,
                      title=f"wearpose demo: BiRAE ({kit}) on {clip}", label=f"estimate ({len(names)} MIMUs, 6-param)",
                      compare=[("ground truth", m.pose, m.betas, m.trans)], colours=[ESTIMATE_COLOUR, TRUTH_COLOUR],
                      site_names=kit_sites(kit, body, names), sites_label=f"{len(names)} MIMUs ({kit})",
                      info={"MPJAE (deg)": f"{metrics['mpjae_all_deg']:.1f}",
                            "inside 1 sigma (%)": f"{metrics['within_1sigma_pct']:.0f}"})
    result = {"clip": clip, "frames": int(gt.shape[0]), "fps": 60.0, "weights": dict(WEIGHTS),
              "title": f"{clip}: BiRAE ({WEIGHTS['6param']}) from 6 simulated MIMUs, {gt.shape[0]} frames at 60 fps",
              "weights_licence": card(WEIGHTS["6param"]).get("licence", ""), "html": str(html), "plot": str(plot),
              "metrics": metrics}
    (out / "metrics.json").write_text(json.dumps(result, indent=2))
    return result
