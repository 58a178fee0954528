"""``wearpose demo``: the main job on embedded defaults.

Today (foundation): a corpus clip played on the body and checked against itself after a file
round trip through both of our motion formats. Later estimator issues extend it to the full
sensors -> pose demo.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import torch

from wearpose.body import BodyModel
from wearpose.evaluate import compute_all
from wearpose.motion import MotionSequence, load_motion, read_amass, save_amass
from wearpose.viewer import write_html


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
                      info={"round-trip MPJPE (mm)": f"{metrics['amass_npz'].get('mpjpe_mm', float('nan')):.2g}"})
    result = {"clip": clip, "frames": seq.num_frames, "fps": seq.fps, "html": str(html),
              "files": [str(ours), str(amass)], "body": model.asset_id, "metrics": metrics}
    (out / "metrics.json").write_text(json.dumps(result, indent=2))
    return result
