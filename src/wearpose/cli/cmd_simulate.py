"""``wearpose simulate``: a simulated recording set from the prepared motion corpus.

Thin: parses options and calls :func:`wearpose.recording.dataset.simulate_corpus`.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Optional

import typer

from wearpose.cli.app import _emit, _kv_table, app, console, err_console


@app.command()
def simulate(
    out: Path = typer.Option(..., "--out", help="Output directory: one recording (.npz) per clip plus index.json."),
    kit: str = typer.Option("em12", help="Sensor kit: em12, em6, imu6, mimu6, miposer, miposer1."),
    split: str = typer.Option("train", help="Corpus split: train, val, test, or all."),
    seed: int = typer.Option(0, help="Base seed; each clip's seed is derived from it and the clip id."),
    noise: str = typer.Option("default", help="Sensor error models: default (documented noise, dropped EM frames), ximu3 (IMU terms fitted to a real x-IMU3 log) or none."),
    offsets: str = typer.Option("random", help="EM sensor-to-skin offsets: random (a synthetic subject per clip) or none."),
    limit: Optional[int] = typer.Option(None, min=1, help="Only the first N selected clips (sorted by id)."),
    workers: Optional[int] = typer.Option(None, min=1, help="Worker processes (default: the usable CPU cores for batches over 20 min of motion, else 1)."),
    rate: Optional[float] = typer.Option(None, help="Every sensor at this rate, Hz (default: the kit's rates, e.g. 120 for EM)."),
    source: Optional[list[str]] = typer.Option(None, "--source", help="Only clips of this corpus source (repeatable), e.g. cmu_daz."),
    licence: Optional[list[str]] = typer.Option(None, "--licence", help="Only clips under this licence (repeatable)."),
    include_nc: bool = typer.Option(True, "--include-nc/--exclude-nc",
                                    help="Include clips under NonCommercial licences (CC BY-NC); recorded in the index."),
    source_pose: bool = typer.Option(True, "--source-pose/--no-source-pose",
                                     help="Store the EM source's world pose in each recording (about a third of an em12 file)."),
    cache: Optional[Path] = typer.Option(None, help="Prepared corpus; default $WEARPOSE_CACHE or ~/.cache/wearpose."),
    body: Optional[str] = typer.Option(None, help="Body asset: default, smpl or a file path."),
    overwrite: bool = typer.Option(False, help="Replace a set in --out that was made with other settings."),
    executor: str = typer.Option("local", help="local (this machine's processes) or ray (a Ray cluster; "
                                               "pip install 'wearpose\\[ray]'; corpus and --out on a shared filesystem)."),
    ray_address: Optional[str] = typer.Option(None, help="Ray cluster address (default $RAY_ADDRESS, else a local Ray)."),
    tpose: Optional[float] = typer.Option(None, "--tpose", metavar="SECONDS",
                                          help="Hold a calibration T-pose this long before each clip (marked in the "
                                               "recording's meta; IMU estimators such as pip_cpu calibrate from it). "
                                               "Default: 1 for imu6, 0 (none) for the other kits."),
    shapes: str = typer.Option("none", help="Wearers' body shapes: none (the motion's own), random (one per clip "
                                            "from the body's adult shape space, for training sets) or heldout "
                                            "(a draw no training set uses, for test sets); the motion is re-fitted "
                                            "to each body."),
    as_json: bool = typer.Option(False, "--json", help="Print the result as JSON (progress goes to stderr)."),
) -> None:
    """Simulate a sensor kit on every clip of a corpus split: a recording set for training or tests.

    Writes OUT/<source>/<subject>/<clip>.npz (wearpose recordings with the clip as ground truth)
    and OUT/index.json (clip id, seed, kit, frames, licence, file). Re-runs skip clips that are
    already done with the same settings; a failing clip is reported and the others carry on
    (exit code 1 if any clip failed). Run `wearpose data prepare` first.

    Example: wearpose simulate --kit em12 --split train --out data/sim/em12-train --seed 0
    IMUs (each clip opens with 1 s of T-pose for the calibration): wearpose simulate --kit imu6 --split test --out sims/
    On a Ray cluster: wearpose simulate --kit imu6 --split all --out /shared/sim/imu6 --executor ray --ray-address auto
    Unseen wearers of every size: wearpose simulate --kit imu6 --split test --shapes heldout --out sims/imu6-bodies
    """
    from wearpose.recording.dataset import simulate_corpus  # start-up: wearpose.recording.dataset loads torch, +1.9 s to wearpose --help

    res = simulate_corpus(out, kit, None if split == "all" else split, cache_dir=cache, source=source or None,
                          licence=licence or None, include_nc=include_nc, seed=seed, noise=noise, offsets=offsets,
                          rate=rate, limit=limit, workers=workers, source_pose=source_pose, body=body,
                          overwrite=overwrite, progress=True, executor=executor, ray_address=ray_address,
                          tpose=tpose, shapes=shapes)

    def render(r: dict[str, Any]) -> None:
        keys = ("selected", "simulated", "skipped", "failed", "excluded_nc", "executor", "workers", "seconds", "clips_per_s",
                "sensor_frames", "sensor_frames_per_s")
        rows = {k: f"{r[k]:,}" if isinstance(r[k], int) else str(r[k]) for k in keys}
        rows.update(written=f"{r['bytes'] / 1e6:.1f} MB", index=r["index"])
        console.print(_kv_table(f"simulated {r['kit']} ({r['split'] or 'all splits'}) -> {r['out']}", rows))
        for cid, err in r["failures"].items():
            err_console.print(f"[red]failed[/] {cid}: {err}")

    _emit(res, as_json, render)
    if res["failed"]:
        raise typer.Exit(code=1)
