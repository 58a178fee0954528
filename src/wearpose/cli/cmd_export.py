"""``wearpose export``: write a motion as BVH (SMPL skeleton) or AMASS-style npz."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer

from wearpose.cli.app import app, console


@app.command()
def export(
    motion: str = typer.Argument(..., help="Clip id, corpus path or motion file (.bvh/.bvh.gz/.npz)."),
    out: Path = typer.Argument(..., help="Output file: .bvh (SMPL skeleton, cm), .npz (AMASS-style, Z up) or .glb (skinned mesh animation)."),
    body: Optional[str] = typer.Option(None, help="Body asset whose rest skeleton the motion uses: default, smpl or a path."),
) -> None:
    """Export a motion to BVH on the SMPL skeleton, AMASS-style npz or an animated GLB.

    Example: wearpose export cmu_daz/05/05_01 out/walk.bvh
    """
    from wearpose.body import BodyModel  # start-up: wearpose.body loads torch, +1.6 s to wearpose --help
    from wearpose.export import export_motion  # start-up: wearpose.export loads torch, +1.6 s to wearpose --help
    from wearpose.motion import load_motion  # start-up: wearpose.motion loads torch, +1.7 s to wearpose --help

    model = BodyModel(body)
    rest = model.rest_joints()
    seq = load_motion(motion, rest_joints=rest)
    path = export_motion(seq, out, model)
    console.print(f"wrote {path} ({seq.num_frames} frames at {seq.fps:g} fps)")
