"""``wearpose demo``: the main job on embedded defaults.

- ``sensors`` (default when shipped EM-POSE weights exist): a held-out test clip -> simulated EM
  sensors (12-sensor kit, default noise, an unseen random subject) -> LGD-RNN estimate ->
  metrics against the ground truth and a page with the estimate beside the ground truth.
- ``roundtrip``: a clip played on the body and checked against itself after a file round trip
  through our MotionSequence npz and AMASS npz.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import math

import torch

from wearpose.body import BodyModel
from wearpose.evaluate import compute_all
from wearpose.motion import MotionSequence, load_motion, read_amass, save_amass
from wearpose.viewer import write_html
from wearpose.viewer.scene import ESTIMATE_COLOUR, TRUTH_COLOUR, kit_sites
from wearpose.errors import ConfigError
from wearpose.estimators.method import resolve, target_available
from wearpose.estimators.seeding import clip_seed
from wearpose import weights as shipped  # the module, not its names: a test may replace them


def kit_demos() -> dict[str, str]:
    """``wearpose demo --kit K`` -> ``"module:function"``, from every method's declaration
    (:attr:`wearpose.estimators.method.MethodSpec.demos`). Each function has the signature
    ``fn(clip: str, out: Path, max_seconds: float) -> dict`` and returns at least ``{"clip", "frames", "fps", "html",
    "title", "metrics": {name: float}}`` (metrics in report units, names ending in the unit, e.g.
    ``mpjpe_mm``)."""
    from wearpose.estimators.registry import get_method, list_methods  # start-up: wearpose.estimators.registry adds ~25 ms to wearpose --help

    return {kit: target for m in list_methods() for kit, target in get_method(m).demos.items()}


def kit_demo(kit: str) -> Any:
    """The demo function for ``kit`` (ConfigError naming the kits with a demo when absent, or
    saying that the module its method declares is not part of this build)."""

    demos = kit_demos()
    if kit not in demos:
        raise ConfigError(f"--kit {kit!r}: no demo for this kit; expected one of {', '.join(demos)}")
    if not target_available(demos[kit]):
        raise ConfigError(f"--kit {kit!r}: the demo of this kit ({demos[kit]}) is not part of this build")
    return resolve(demos[kit])


def _evaluate(body: BodyModel, ref: MotionSequence, other: MotionSequence) -> dict[str, float]:
    with torch.no_grad():
        def side(seq: MotionSequence) -> dict[str, torch.Tensor]:
            out = body(seq.pose, seq.betas, seq.trans)
            return {"local_rot": seq.pose, "joints": out.joints, "vertices": out.vertices, "trans": seq.trans}

        return compute_all(side(other), side(ref), fps=ref.fps)


def run_roundtrip_demo(clip: str, out: str | Path, body: str | None = None, max_seconds: float = 10.0) -> dict[str, Any]:
    """Load ``clip``, round-trip it through our npz and AMASS npz, evaluate, write an HTML page.

    Args:
        clip: clip id, corpus path or motion file (see :func:`wearpose.motion.load_motion`).
        out: output folder.
        body: body asset (``None`` = embedded default).
        max_seconds: clip length used (the start of the clip).

    Returns:
        ``{"clip", "frames", "fps", "html", "files", "metrics": {"wearpose_npz": {...}, "amass_npz": {...}}}``
        with metrics in report units (mm, deg, cm, km/s^3).
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    model = BodyModel(body)
    rest = model.rest_joints()
    seq = load_motion(clip, rest_joints=rest)
    seq = seq.slice(0, min(seq.num_frames, int(round(max_seconds * seq.fps))))
    ours = seq.save(out / "motion.npz")
    amass = out / "motion_amass.npz"
    save_amass(seq, amass, rest_joints=rest)
    back_ours = MotionSequence.load(ours)
    back_amass = read_amass(amass, rest_joints=rest)
    metrics = {"wearpose_npz": _evaluate(model, seq, back_ours), "amass_npz": _evaluate(model, seq, back_amass)}
    html = write_html(out / "demo.html", model, seq.pose, seq.betas, seq.trans, seq.fps, title=f"wearpose demo: {clip}",
                      site_names=(), label="original clip",
                      info={"round-trip MPJPE (mm)": f"{metrics['amass_npz'].get('mpjpe_mm', float('nan')):.2g}"})
    result = {"clip": clip, "frames": seq.num_frames, "fps": seq.fps, "html": str(html),
              "files": [str(ours), str(amass)], "body": model.asset_id, "metrics": metrics}
    (out / "metrics.json").write_text(json.dumps(result, indent=2))
    return result


def run_sensor_demo(clip: str, out: str | Path, weights: str = "empose12_cpu", max_seconds: float = 10.0,
                    seed: int = 0) -> dict[str, Any]:
    """Simulate EM sensors on ``clip``, estimate the pose with shipped LGD-RNN weights, evaluate.

    Args:
        clip: clip id, corpus path or motion file.
        out: output folder (``demo.html``, ``metrics.json``, the simulated ``recording.npz``).
        weights: shipped weights name (see :mod:`wearpose.weights`).
        max_seconds: clip length used.
        seed: simulation seed (noise, dropped frames, subject offsets).

    Returns:
        ``{"clip", "frames", "fps", "weights", "html", "metrics": {...}}``; metrics in mm / deg over
        the 15 major joints on frames where every sensor is valid (EM-POSE Sec. 6.2).
    """
    from wearpose.body.skeleton import MAJOR_JOINTS  # start-up: wearpose.body.skeleton loads torch, +1.5 s to wearpose --help
    from wearpose.estimators.empose.data import recording_from_clip, simulate_clip  # start-up: wearpose.estimators.empose.data loads torch, +2.1 s to wearpose --help
    from wearpose.estimators.run import estimate_recording, open_model  # start-up: wearpose.estimators.run loads torch, +2.0 s to wearpose --help
    from wearpose.evaluate import mpjae, mpjpe, pa_mpjpe  # start-up: wearpose.evaluate loads torch, +1.7 s to wearpose --help

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    source = open_model(weights)  # the checkpoint is read here, once
    est = source.make()
    body = est.body
    seq = load_motion(clip, rest_joints=body.rest_joints())
    seq = seq.slice(0, min(seq.num_frames, int(round(max_seconds * seq.fps))))
    r = simulate_clip(seq, est.config, body, clip_seed(clip, seed, "demo"), noise="default", offsets="random")
    rec = recording_from_clip(r, est.config)
    rec.save(out / "recording.npz")
    run = estimate_recording(source, rec, out / "recording.npz", estimator=est)
    track, world = run.estimated, run.track  # world: through the recorded EM source pose, on the floor
    with torch.no_grad():
        pj = body(track.local_rot, track.betas, None, return_vertices=False).joints
    ok = track.valid
    k = 180.0 / math.pi
    metrics = {
        "mpjpe_mm": float(mpjpe(pj, r["joints"], MAJOR_JOINTS)[ok].mean() * 1000),
        "pa_mpjpe_mm": float(pa_mpjpe(pj, r["joints"], MAJOR_JOINTS)[ok].mean() * 1000),
        "mpjae_deg": float(mpjae(track.local_rot, r["pose"])[ok].mean() * k),
        "valid_frames_pct": float(ok.float().mean() * 100),
    }
    gt = r["motion"]
    n_em = len(est.sensor_names)
    html = write_html(out / "demo.html", body, world.local_rot, world.betas, world.trans, gt.fps,
                      title=f"wearpose demo: EM-POSE ({est.kit_name}) on {clip}",
                      label=f"estimate ({n_em} EM sensors, {est.kit_name})",
                      compare=[("ground truth", gt.pose, gt.betas, gt.trans)], colours=[ESTIMATE_COLOUR, TRUTH_COLOUR],
                      site_names=kit_sites(est.kit_name, body, est.sensor_names),
                      sites_label=f"{n_em} EM sensors ({est.kit_name})",
                      info={"MPJPE (mm)": f"{metrics['mpjpe_mm']:.1f}", "MPJAE (deg)": f"{metrics['mpjae_deg']:.1f}"})
    result = {"clip": clip, "frames": gt.num_frames, "fps": gt.fps, "weights": weights,
              "title": f"{clip}: EM-POSE ({weights}) from {len(est.sensor_names)} simulated EM sensors, "
                       f"{gt.num_frames} frames at {gt.fps:g} fps",
              "weights_licence": shipped.card(weights).get("licence", ""), "html": str(html), "metrics": metrics}
    (out / "metrics.json").write_text(json.dumps(result, indent=2))
    return result


def run_sensor_demo_em6(clip: str, out: str | Path, max_seconds: float = 10.0) -> dict[str, Any]:
    """:func:`run_sensor_demo` with the shipped 6-sensor weights."""
    return run_sensor_demo(clip, out, weights="empose6_cpu", max_seconds=max_seconds)
