#!/usr/bin/env python
"""Render a motion file (BVH / npz) at a few instants to a PNG, front and side, for a visual
check of an estimate (matplotlib; tools only). The floor (y = 0) is the black line.

    python tools/render_motion.py legs.bvh docs/img/ximu3_segments.png --frames 8 --dpi 55
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "src"))
from render_body import _draw_mesh  # noqa: E402
from wearpose.body import BodyModel  # noqa: E402
from wearpose.motion import load_motion  # noqa: E402


def main() -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("motion")
    ap.add_argument("out")
    ap.add_argument("--frames", type=int, default=8, help="instants, evenly spread over the motion")
    ap.add_argument("--dpi", type=int, default=70)
    a = ap.parse_args()
    seq, body = load_motion(a.motion), BodyModel()
    frames = np.linspace(0, seq.num_frames - 1, a.frames).astype(int)
    with torch.no_grad():
        out = body(seq.pose[frames], seq.betas, seq.trans[frames], return_normals=False)
    fig, axes = plt.subplots(2, len(frames), figsize=(2.2 * len(frames), 7), squeeze=False)
    for k, f in enumerate(frames):
        v = out.vertices[k].numpy()
        for row, view in enumerate(("front", "side")):
            ax = axes[row, k]
            _draw_mesh(ax, v, body.faces.numpy(), view, (0.6, 0.7, 0.9))
            ax.axhline(0, color="k", lw=0.8)
            ax.set_aspect("equal")
            c = v[:, 0 if view == "front" else 2].mean()
            ax.set_xlim(c - 0.8, c + 0.8)
            ax.set_ylim(-0.1, 2.0)
            ax.set_title(f"t={f / seq.fps:.1f}s {view}", fontsize=8)
            ax.tick_params(labelsize=6)
    plt.tight_layout()
    plt.savefig(a.out, dpi=a.dpi)
    print(f"wrote {a.out}")


if __name__ == "__main__":
    main()
