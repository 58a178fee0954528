"""``wearpose calibrate``: run a calibration on a recording and store the result with it.

Thin: :func:`wearpose.recording.load_recording` -> :func:`wearpose.calibration.calibrate` ->
:func:`wearpose.calibration.store_calibration` -> :func:`wearpose.recording.save_recording`.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any, Optional

import typer

from wearpose.cli.app import _emit, _kv_table, app, console


def _short(v: Any) -> str:
    """One table cell: numbers rounded, long lists abbreviated."""
    if isinstance(v, float):
        return f"{v:.4g}"
    if isinstance(v, list):
        flat = [f"{x:.3g}" if isinstance(x, float) else str(x) for x in v[:6]]
        return "[" + ", ".join(flat) + (", ..." if len(v) > 6 else "") + "]"
    return str(v)


@app.command()
def calibrate(
    recording: Path = typer.Argument(..., help="A wearpose recording (.npz)."),
    method: str = typer.Option(..., help="empose-offsets, tpose, ipose, miposer-tpose or hand-eye."),
    out: Optional[Path] = typer.Option(None, help="Where to write: a .npz gets the recording with the calibration stored "
                                                  "in it, a .json only the result. Default: update RECORDING in place."),
    window: Optional[tuple[float, float]] = typer.Option(None, help="START STOP seconds of the calibration pose "
                                                                     "(default 0 1; empose-offsets: the whole sequence)."),
    sensor: Optional[list[str]] = typer.Option(None, "--sensor", help="Sensor to use (repeatable; default: every sensor "
                                                                      "of the kinds the method needs; hand-eye: A then B)."),
    body: Optional[str] = typer.Option(None, help="Body asset: default, smpl or a file path."),
    as_json: bool = typer.Option(False, "--json", help="Print the calibration result as JSON."),
) -> None:
    """Calibrate a recording (EM-POSE subject offsets, T-/I-pose alignment, MI-Poser T-pose, AX=YB).

    The result goes into the recording's meta["calibration"] (empose-offsets also into
    subject["offsets"]), written atomically back to RECORDING or to --out. See docs/calibration.md
    for what each method needs in the recording.

    Example: wearpose calibrate walk.npz --method tpose --window 0.5 2.0 --out walk_calibrated.npz
    """
    from wearpose.calibration import METHODS, CalibrationError, store_calibration  # start-up: wearpose.calibration loads torch, +2.1 s to wearpose --help
    from wearpose.calibration import calibrate as run_calibration  # start-up: wearpose.calibration loads torch, +2.1 s to wearpose --help
    from wearpose.fileio import atomic_write_text  # start-up: wearpose.fileio adds ~125 ms to wearpose --help
    from wearpose.recording import load_recording, save_recording  # start-up: wearpose.recording loads torch, +1.7 s to wearpose --help

    if method not in METHODS:
        raise CalibrationError(f"--method {method!r} is not a calibration method; expected one of {list(METHODS)}")
    if window is not None and not 0 <= window[0] < window[1]:
        raise typer.BadParameter(f"{window[0]:g} {window[1]:g}: expected START STOP in seconds with "
                                 f"0 <= START < STOP", param_hint="--window")
    rec = load_recording(recording)
    unknown = [n for n in sensor or [] if n not in rec.names]
    if unknown:
        raise typer.BadParameter(f"{recording} has no sensor {', '.join(map(repr, unknown))}; its sensors: "
                                 f"{', '.join(rec.names)}", param_hint="--sensor")
    kw: dict[str, Any] = {}
    if window is not None:
        kw["window"] = window
        if method == "empose-offsets":
            kw["use_window"] = True  # the library uses the whole sequence unless told otherwise
    bm = None
    if body is not None:
        import torch  # start-up: torch loads torch, +1.3 s to wearpose --help

        from wearpose.body import BodyModel  # start-up: wearpose.body loads torch, +1.6 s to wearpose --help

        bm = BodyModel(body, dtype=torch.float64)
    result = run_calibration(rec, method, body=bm, sensors=sensor or None, **kw)
    dest = out if out is not None else recording
    if dest.suffix.lower() == ".json":
        atomic_write_text(dest, json.dumps(result.to_dict(), indent=1))
    else:
        save_recording(store_calibration(rec, result), dest)
    payload = {"recording": str(recording), "written": str(dest), "calibration": result.to_dict()}

    def render(r: dict[str, Any]) -> None:
        c = r["calibration"]
        rows = {"sensors": ", ".join(c["sensors"]), **{k: _short(v) for k, v in (c.get("quality") or {}).items()}}
        if c.get("scale") is not None:
            rows["scale"] = _short(c["scale"])
        console.print(_kv_table(f"calibration {c['method']} of {r['recording']}", {**rows, "written": r["written"]}))

    _emit(payload, as_json, render)
