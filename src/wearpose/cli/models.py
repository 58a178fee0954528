"""Model arguments shared by the commands that run an estimator (``serve``, ``view-recording``,
``evaluate``): clear errors for names that are not pose-estimator weights, and for recordings
that do not fit the weights (kit, rate)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import typer


def pose_weights() -> list[str]:
    """Shipped weights whose card names a registered pose estimator (the others, e.g. the N-BEATS
    forecaster of MI-Poser's interference correction, are parts of a method, not estimators)."""
    from wearpose.estimators.registry import list_estimators
    from wearpose.weights import card, list_weights

    known = set(list_estimators())
    return [n for n in list_weights() if card(n).get("method") in known]


def check_pose_weights(model: str, param_hint: str = "--model") -> None:
    """Refuse shipped weights ``model`` that are not a pose estimator, naming what they are and
    which shipped weights are estimators. Anything else (a checkpoint file, an unknown name) is
    left to the loader, whose errors already say what is wrong."""
    from wearpose.weights import card, list_weights

    if model not in list_weights() or model in pose_weights():
        return
    what = card(model).get("method", "?")
    raise typer.BadParameter(f"{model!r} is not a pose estimator (its card says: {what}); pose-estimator weights: "
                             f"{', '.join(pose_weights())}", param_hint=param_hint)


def weights_setting(model: str) -> dict[str, Any]:
    """Kit, sensors, method and trained rate (``fps``) of shipped weights (read from their card) or
    of a checkpoint file, or ``{}`` when neither says (rate fitting and error messages)."""
    from wearpose.estimators.checkpoint import load_checkpoint
    from wearpose.weights import card, list_weights, weight_path

    if model in list_weights():  # the card says the same as the checkpoint without loading its weights
        c = card(model)
        if all(k in c for k in ("kit", "sensors", "method")):
            rate = c.get("config", {}).get("rate") if isinstance(c.get("config"), dict) else None
            return {"kit": c["kit"], "sensors": list(c["sensors"]), "fps": rate, "method": c["method"]}
    try:
        ck = load_checkpoint(weight_path(model) if model in list_weights() else Path(model))
    except Exception:  # noqa: BLE001 - only used to word an error; the loader reports its own problems
        return {}
    fps = ck.config.get("rate") if isinstance(ck.config, dict) else None  # Hz the network was trained at
    return {"kit": ck.kit, "sensors": list(ck.sensors), "fps": fps, "method": ck.method}


def recording_mismatch(recording: Path, model: str, problem: str) -> Exception:
    """An :class:`~wearpose.errors.InputFileError` for a recording the weights cannot read: the
    file, the estimator's complaint, and what a fitting recording looks like."""
    from wearpose.errors import InputFileError

    s = weights_setting(model)
    if not s:
        return InputFileError(recording, problem, f"a recording made for {model}")
    rate = f" at {s['fps']:g} Hz" if s.get("fps") else ""
    sim = f"`wearpose simulate --kit {s['kit']}" + (f" --rate {s['fps']:g}`" if s.get("fps") else "`")
    return InputFileError(recording, f"does not fit {model} ({problem})",
                          f"a recording of kit {s['kit']}{rate} with sensors {', '.join(s['sensors'])} "
                          f"(e.g. {sim}), or weights for this recording's sensors")


def fit_rate(path: Path, rec: Any, model: str, resample: bool | None) -> tuple[Any, str | None]:
    """Bring ``rec`` to the rate ``model`` was trained at by integer-factor decimation
    (:func:`wearpose.recording.decimate`).

    ``resample``: ``None`` (auto) decimates when the weights' sensors in the recording share one
    rate that is an integer multiple of the trained rate, and returns a one-line note saying so;
    a ratio that does not decimate is left to the estimator, which refuses it with the fitting
    kit and rate. ``True`` does the same but makes a non-integer ratio an error naming both
    rates. ``False`` never changes the recording. Kits whose sensors run at different rates by
    design (MI-Poser: 60 Hz headset, 120 Hz EM) are left alone in auto mode.

    Returns:
        ``(recording, note)``; ``note`` is None when nothing changed.
    """
    from wearpose.errors import InputFileError
    from wearpose.recording import RecordingError, decimate

    s = weights_setting(model)
    target = s.get("fps")
    if resample is False or not target:
        return rec, None
    names = [n for n in s.get("sensors", []) if n in rec.names] or list(rec.names)
    rates = sorted({float(rec.sensor(n).info.rate) for n in names})
    if all(abs(r - target) <= 1e-3 * target for r in rates):
        return rec, None
    if len(rates) > 1 and resample is None:
        return rec, None
    try:
        out = decimate(rec.select(names), float(target))
    except RecordingError as exc:
        if resample:
            raise InputFileError(path, f"--resample: {exc}", f"sensors at an integer multiple of {target:g} Hz") from None
        return rec, None
    k = {d["factor"] for d in out.meta.get("resampled", {}).values()}
    note = (f"{path.name}: {', '.join(f'{r:g}' for r in rates)} Hz decimated by {'/'.join(map(str, sorted(k)))} to "
            f"{model}'s {target:g} Hz (every k-th sample as recorded, dropped frames stay dropped; --no-resample refuses)")
    return out, note
