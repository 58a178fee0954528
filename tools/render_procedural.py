#!/usr/bin/env python
"""Render a procedural motion clip (``wearpose motion procedural``) at the middle of its phases,
front and side, turned back to zero heading so "front" faces the body; the floor (y = 0) is the
black line, and the lowest vertex height of each frame is printed in its title (matplotlib; tools
only).

    python tools/render_procedural.py squat.npz docs/img/procedural_squat.png --phases 6 --dpi 45
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "src"))
from render_body import _draw_mesh  # noqa: E402
from wearpose.body import BodyModel  # noqa: E402
from wearpose.motion import MotionSequence  # noqa: E402


def main() -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("motion")
    ap.add_argument("out")
    ap.add_argument("--phases", type=int, default=6, help="phases shown (the longest distinct ones, in time order)")
    ap.add_argument("--dpi", type=int, default=50)
    a = ap.parse_args()
    seq, body = MotionSequence.load(a.motion), BodyModel()
    segs = seq.meta["segments"]
    seen, picks = set(), []
    for name, first, n, _ in segs:  # first occurrence of each phase name
        if name not in seen:
            seen.add(name)
            picks.append((first + n // 2, name))
    picks = picks[: a.phases]
    frames = [f for f, _ in picks]
    with torch.no_grad():
        v = body(seq.pose[frames], seq.betas, seq.trans[frames], return_normals=False).vertices.double().numpy()
    h = math.radians(seq.meta.get("heading_deg", 0.0))
    c, s = math.cos(-h), math.sin(-h)
    R = np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])
    fig, axes = plt.subplots(2, len(frames), figsize=(2.0 * len(frames), 5.6), squeeze=False)
    for k, (f, name) in enumerate(picks):
        vk = v[k] @ R.T
        for row, view in enumerate(("front", "side")):
            ax = axes[row, k]
            _draw_mesh(ax, vk, body.faces.numpy(), view, (0.6, 0.7, 0.9))
            ax.axhline(0, color="k", lw=0.8)
            ax.set_aspect("equal")
            cx = vk[:, 0 if view == "front" else 2].mean()
            ax.set_xlim(cx - 0.9, cx + 0.9)
            ax.set_ylim(-0.1, 1.9)
            ax.set_title(f"{name} {view}\nlowest {100 * vk[:, 1].min():+.1f} cm", fontsize=7)
            ax.tick_params(labelsize=5)
    fig.suptitle(f"{seq.meta.get('clip', '')}", fontsize=8)
    plt.tight_layout()
    plt.savefig(a.out, dpi=a.dpi)
    print(f"wrote {a.out}")


if __name__ == "__main__":
    main()
