"""Model arguments shared by the commands that run an estimator (``estimate``, ``serve``,
``view-recording``, ``evaluate``): clear errors for names that are not pose-estimator weights,
and for recordings that do not fit the weights (kit, rate), and the ``--set KEY=VALUE`` cost
settings of ``bench latency``, ``serve``, ``estimate``, ``view-recording`` and ``evaluate``.
Resolving a model, fitting the rate and running it is :mod:`wearpose.estimators.run`'s."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, TypeVar

import typer
from wearpose.errors import ConfigError, InputFileError, RecordingInputError
from wearpose.weights import card, list_weights

if TYPE_CHECKING:
    from wearpose.estimators.base import Estimator
    from wearpose.estimators.run import ModelSource

E = TypeVar("E", bound="Estimator")


def pose_weights() -> list[str]:
    """Shipped weights whose card names a registered pose estimator (the others, e.g. the N-BEATS
    forecaster of MI-Poser's interference correction, are parts of a method, not estimators)."""
    from wearpose.estimators.registry import list_estimators  # start-up: wearpose.estimators.registry adds ~25 ms to wearpose --help

    known = set(list_estimators())
    return [n for n in list_weights() if card(n).get("method") in known]


def check_pose_weights(model: str, param_hint: str = "--model") -> None:
    """Refuse shipped weights ``model`` that are not a pose estimator, naming what they are and
    which shipped weights are estimators. Anything else (a checkpoint file, an unknown name) is
    left to the loader, whose errors already say what is wrong."""

    if model not in list_weights() or model in pose_weights():
        return
    what = card(model).get("method", "?")
    raise typer.BadParameter(f"{model!r} is not a pose estimator (its card says: {what}); pose-estimator weights: "
                             f"{', '.join(pose_weights())}", param_hint=param_hint)


def recording_mismatch(recording: Path, source: ModelSource, exc: Exception) -> Exception:
    """An :class:`~wearpose.errors.InputFileError` for a recording the weights cannot read: the
    file, the estimator's complaint (without its own naming of the file), and what a fitting
    recording looks like."""

    problem = f"{exc.problem}; {exc.expected}" if isinstance(exc, RecordingInputError) else str(exc)

    if not source.kit:
        return InputFileError(recording, problem, f"a recording made for {source.name}")
    rate = f" at {source.fps:g} Hz" if source.fps else ""
    sim = f"`wearpose simulate --kit {source.kit}" + (f" --rate {source.fps:g}`" if source.fps else "`")
    return InputFileError(recording, f"does not fit {source.name} ({problem})",
                          f"a recording of kit {source.kit}{rate} with sensors {', '.join(source.sensors)} "
                          f"(e.g. {sim}), or weights for this recording's sensors")


def parse_settings(values: list[str] | None) -> dict[str, str]:
    """``--set KEY=VALUE`` options (repeatable) as ``{KEY: VALUE}``; the values are parsed and
    checked against the estimator by :func:`wearpose.evaluate.latency.apply_settings`.

    Raises:
        typer.BadParameter: an option without ``=``.
    """
    pairs = dict(v.split("=", 1) for v in values or [] if "=" in v)
    if len(pairs) != len(values or []):
        bad = [v for v in values or [] if "=" not in v]
        raise typer.BadParameter(f"{bad}: expected KEY=VALUE, e.g. online=stream", param_hint="--set")
    return pairs


def with_settings(est: E, settings: dict[str, str], name: str) -> E:
    """``est`` (an estimator) with the ``--set`` settings applied
    (:func:`wearpose.evaluate.latency.apply_settings`); a setting it does not have is a
    ``--set`` error naming the model ``name`` and the settings it has."""
    from wearpose.evaluate.latency import apply_settings  # start-up: loads torch, +1.8 s to wearpose --help

    try:
        apply_settings(est, settings)
    except ConfigError as exc:
        raise typer.BadParameter(f"{name}: {exc}", param_hint="--set") from None
    return est
