"""``wearpose estimate``: a recording (your sensors, or a simulated one) -> an estimated motion file.

Thin: :func:`wearpose.recording.load_recording` -> :func:`wearpose.estimators.run.open_model`
(the checkpoint read once) -> :func:`~wearpose.estimators.run.estimate_recording` (rate, T-pose
window, estimate, placed in the world) -> :meth:`PoseTrack.to_motion` ->
:func:`wearpose.export.export_motion`.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, List, Optional

import typer

from rich.markup import escape

from wearpose.cli.app import _emit, _kv_table, app, console, err_console
from wearpose.cli.models import check_pose_weights, parse_settings, recording_mismatch, with_settings
from wearpose.errors import InputFileError, ShapeError


@app.command()
def estimate(
    recording: Path = typer.Argument(..., help="A wearpose recording (.npz, docs/formats.md) with the sensors of the "
                                               "weights' kit at their trained rate."),
    model: str = typer.Option(..., help="Shipped weights (e.g. empose12_cpu, pip_cpu, birae6_cpu, miposer_cpu) or a "
                                        "checkpoint file."),
    out: Path = typer.Option(..., help="Output motion: .bvh (SMPL skeleton, cm), .npz (AMASS-style) or .glb."),
    resample: Optional[bool] = typer.Option(None, "--resample/--no-resample",
                                            help="Decimate the recording to the weights' trained rate by an integer "
                                                 "factor (e.g. 120 -> 30 Hz). Default: done when the rates differ by an "
                                                 "integer factor, with one warning line; --resample makes any other "
                                                 "ratio an error; --no-resample refuses another rate."),
    settings: Optional[List[str]] = typer.Option(None, "--set", help="KEY=VALUE: an inference setting of the "
                                                 "estimator (repeatable), as `wearpose evaluate --set`, e.g. "
                                                 "refine_steps=3 (EM-POSE: trust the sensors on unfamiliar motion) or "
                                                 "shape_fit_frames=30 (EM-POSE: fit the wearer's body)."),
    threads: int = typer.Option(1, min=1, help="torch CPU threads."),
    as_json: bool = typer.Option(False, "--json", help="Print the result as JSON."),
) -> None:
    """Estimate the full-body motion of a recording with shipped weights or a checkpoint, and
    write it as a motion file (`wearpose view OUT` plays a .bvh or .npz; Blender opens .bvh and .glb).

    The recording must hold the sensors of the weights' kit (names as in the card) at the rate
    they were trained at, or at an integer multiple of it (decimated, with a warning line;
    --no-resample refuses); a recording that does not fit is refused with the kit, the rate and
    a command that makes a fitting one. `--model segments` needs no weights: a dense kit's
    segments take their calibrated sensors' orientations (any sensors on known sites with a
    pelvis sensor, e.g. `wearpose recording import ximu3`). The motion is written upright with
    its feet on the floor (the result's `placement` and `floor` say how, and so does the file:
    GLB asset.extras, an npz key, a BVH's sidecar OUT.json; docs/formats.md).

    Example: wearpose estimate out/demo-em12/recording.npz --model empose12_cpu --out out/estimate.bvh

    Motion unlike the corpus's (another lab, floor work), EM-POSE (docs/empose.md): add
    --set refine_steps=3 --set refine_centre=recording --set refine_centre_frames=1
    --set refine_centre_every=1
    """
    import torch  # start-up: torch loads torch, +1.3 s to wearpose --help

    from wearpose.calibration import CalibrationError  # start-up: wearpose.calibration loads torch, +2.1 s to wearpose --help
    from wearpose.estimators.run import estimate_recording, open_model  # start-up: wearpose.estimators.run loads torch, +2.0 s to wearpose --help
    from wearpose.export import export_motion, sidecar_path  # start-up: wearpose.export loads torch, +1.6 s to wearpose --help
    from wearpose.recording import load_recording  # start-up: wearpose.recording loads torch, +1.7 s to wearpose --help

    if out.suffix not in (".bvh", ".npz", ".glb"):
        raise typer.BadParameter(f"{out}: expected a .bvh, .npz or .glb file name", param_hint="--out")
    torch.set_num_threads(threads)
    check_pose_weights(model)
    source = open_model(model)  # the checkpoint is read here, once
    chosen = parse_settings(settings)
    est = with_settings(source.make(), chosen, model)
    rec = load_recording(recording)
    try:
        # A spinner on stderr: an hour of IMU data through PIP's physics takes minutes.
        with err_console.status(f"estimating {rec.duration:.0f} s of {recording.name} with {model}"):
            run = estimate_recording(source, rec, recording, resample=resample, estimator=est)
    except ShapeError as exc:  # the estimator's check of the recording: missing sensors, another rate
        raise recording_mismatch(recording, source, exc) from None
    except CalibrationError as exc:  # IMU methods calibrate an uncalibrated recording from a T-pose
        raise InputFileError(recording, f"{model} could not calibrate it ({exc})",
                             "a recording that starts with about 1 s of T-pose (or marks its T-pose in "
                             "meta['calibration_window'], as `wearpose simulate --kit imu6` does), one calibrated with `wearpose "
                             "calibrate REC --method tpose --window START STOP`, or one whose meta says "
                             "orientation_frame='segment' (orientations already of the body segments)") from None
    if run.note:
        err_console.print(f"[yellow]warning:[/] {escape(run.note)}", soft_wrap=True)
    track = run.track  # upright, feet on the floor (as a user expects a file)
    motion = track.to_motion()
    motion.meta["estimator"] = {"model": model, "settings": chosen}  # the file says what made it
    path = export_motion(motion, out, run.body)
    valid = float(track.valid.float().mean()) * 100 if track.num_frames else 0.0
    res: dict[str, Any] = {"recording": str(recording), "model": model, "frames": track.num_frames,
                           "fps": track.fps, "valid_pct": round(valid, 2),
                           "frame": track.extras.get("frame", "world"),
                           "estimated_frame": run.estimated.extras.get("frame", "world"),
                           "translation": run.estimated.trans is not None,
                           "placement": track.extras.get("placement", "as estimated"),
                           "floor": track.extras.get("floor"), "settings": chosen, "written": str(path),
                           "metadata": str(sidecar_path(path) if path.suffix == ".bvh" else path)}
    if run.note:
        res["resampled"] = run.recording.meta.get("resampled")
    _emit(res, as_json, lambda r: console.print(_kv_table(f"estimate of {recording.name} by {model}", r)))
