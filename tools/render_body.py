#!/usr/bin/env python
"""Render a body asset to a PNG for a visual check (matplotlib, tools only; not a runtime dependency).

Panels: the rest pose (beta = 0) from the front (+Z towards the viewer) and from the left side
with joints and sensor sites, then beta[0] = -2, 0, +2 and beta[1] = -2, +2 from the front.
Orthographic projection, flat shading by the face normal; metres on the axes.

    python tools/render_body.py --out docs/img/body_rest.png
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "src"))
from wearpose.body.asset import BodyAsset, load_asset_npz, load_default_asset  # noqa: E402
from wearpose.body.skeleton import PARENTS  # noqa: E402


def _draw_mesh(ax, v: np.ndarray, faces: np.ndarray, view: str, colour: tuple[float, float, float]) -> None:
    """Draw mesh v (V, 3) (wearpose frame, m) orthographically.

    view: "front" looks along -Z (the body faces the viewer, its left on the image right);
    "side" looks along -X from the subject's left (front of the body on the image right).
    """
    from matplotlib.collections import PolyCollection

    if view == "front":
        xy, depth, eye = v[:, [0, 1]], v[:, 2], np.array([0.0, 0.0, 1.0])
    else:
        xy, depth, eye = v[:, [2, 1]], v[:, 0], np.array([1.0, 0.0, 0.0])
    tri = v[faces]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n /= np.linalg.norm(n, axis=1, keepdims=True) + 1e-12
    facing = n @ eye
    keep = facing > 0  # back-face culling (faces wind counter-clockwise seen from outside)
    order = np.argsort(depth[faces].mean(1)[keep])  # painter's algorithm: far faces first
    f = faces[keep][order]
    light = np.clip(0.25 + 0.75 * (n[keep][order] @ (eye + np.array([0.3, 0.5, 0.0])) / np.linalg.norm(eye + [0.3, 0.5, 0])), 0, 1)
    cols = np.clip(np.array(colour)[None] * light[:, None], 0, 1)
    ax.add_collection(PolyCollection(xy[f], facecolors=cols, edgecolors="none", antialiased=False))


def render(asset: BodyAsset, out: Path, dpi: int = 70) -> None:
    """Write the PNG of ``asset`` to ``out``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    v0, f, sd = asset.v_template.astype(np.float64), asset.faces, asset.shapedirs.astype(np.float64)
    J = asset.J_regressor.astype(np.float64) @ v0
    sites = asset.v_template[asset.site_vertices]
    panels = [("rest, front", v0, "front", True), ("rest, left side", v0, "side", True)]
    for k, b in ((0, -2.0), (0, 2.0), (1, -2.0), (1, 2.0)):
        panels.append((f"beta[{k}] = {b:+.0f}", v0 + b * sd[:, :, k], "front", False))
    fig, axes = plt.subplots(1, len(panels), figsize=(3.0 * len(panels), 4.6))
    for ax, (title, v, view, marks) in zip(axes, panels):
        _draw_mesh(ax, v, f, view, (0.75, 0.72, 0.68))
        h = v[:, 1].max() - v[:, 1].min()
        if marks:
            c = [0, 1] if view == "front" else [2, 1]
            for j, p in enumerate(PARENTS):
                if p >= 0:
                    ax.plot(J[[p, j], c[0]], J[[p, j], c[1]], "-", color="tab:blue", lw=1.0)
            ax.plot(J[:, c[0]], J[:, c[1]], "o", color="tab:blue", ms=2.5)
            ax.plot(sites[:, c[0]], sites[:, c[1]], "s", color="tab:red", ms=3.0)
        ax.set_title(f"{title}\nheight {h:.2f} m", fontsize=9)
        ax.set_aspect("equal")
        ax.set_xlim(-0.95, 0.95) if view == "front" else ax.set_xlim(-0.5, 0.5)
        ax.set_ylim(-1.35, 0.75)
        ax.tick_params(labelsize=6)
    fig.suptitle(f"{asset.asset_id}: Y up, facing +Z (front view: subject's left on the right); "
                 "blue = joints (J_regressor), red = sensor sites", fontsize=9)
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=dpi)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description="Render a wearpose body asset to PNG.")
    ap.add_argument("--asset", type=Path, default=None, help="asset .npz (default: the embedded asset)")
    ap.add_argument("--out", type=Path, default=Path("docs/img/body_rest.png"), help="output PNG")
    ap.add_argument("--dpi", type=int, default=70, help="resolution (default 70)")
    args = ap.parse_args(argv)
    asset = load_asset_npz(args.asset) if args.asset else load_default_asset()
    render(asset, args.out, args.dpi)
    print(f"wrote {args.out} ({args.out.stat().st_size / 1024:.0f} KB)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
