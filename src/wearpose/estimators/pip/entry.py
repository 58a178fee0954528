"""PIP's training entry (``wearpose train pip``: options -> config -> estimator -> training run)
and evaluation protocol (``wearpose evaluate``), named by its declaration
:data:`wearpose.estimators.pip.METHOD`."""

from __future__ import annotations

from pathlib import Path
from typing import Any, Callable, Mapping

from wearpose.errors import ConfigError
from wearpose.estimators.method import TrainRun, finite_metrics

#: Options that override the :class:`~wearpose.estimators.pip.config.PipConfig` field of the same name.
_SAME_NAME = ("hidden", "batch_size", "learned_init", "sitting_clips", "lr", "seq_len", "window_stride", "min_window",
              "sitting_window", "sitting_transitions", "sitting_hanging_arms")


def train_from_options(opts: Mapping[str, Any], run: TrainRun) -> dict[str, Any]:
    """Train PIP's kinematics RNNs with the ``--config`` preset, overridden by the options given
    (augmentation, synthetic sitting, windows), optionally starting from ``--init-from``'s weights.

    Returns:
        :func:`~wearpose.estimators.pip.train.train_pip`'s result with ``method`` and ``config``.
    """
    # start-up: wearpose.estimators.pip.config (with torch) adds ~1.9 s to importing this module
    from wearpose.estimators.pip.config import PipConfig
    # start-up: wearpose.estimators.pip.estimator (with torch) adds ~1.5 s to importing this module
    from wearpose.estimators.pip.estimator import PipEstimator
    # start-up: wearpose.estimators.pip.sitting (with torch) adds ~2.1 s to importing this module
    from wearpose.estimators.pip.sitting import SIT_HOLD_S
    # start-up: wearpose.estimators.pip.train (with torch) adds ~1.5 s to importing this module
    from wearpose.estimators.pip.train import train_pip

    cfg = PipConfig.preset(run.config).override(
        **{k: opts[k] for k in _SAME_NAME}, **run.config_overrides(),
        sitting_stand_s=SIT_HOLD_S if opts["balanced_sitting"] else None)
    if opts["hidden"] is not None:
        cfg = cfg.override(init_widths=(opts["hidden"], 2 * opts["hidden"]))
    out = run.out or Path("runs") / f"pip_{run.config}{'' if opts['learned_init'] else '_noinit'}"
    est = PipEstimator(cfg, physics=False)
    res = train_pip(est, out, **run.loop())
    return {"method": "pip", "config": cfg.to_dict(), **res}


def protocol(est: Any, store: Any, split: str, clips: int | None, seed: int, noise: str,
             progress: Callable[[int, int], None] | None, frame_stride: int = 1) -> dict[str, Any]:
    """PIP's evaluation protocol for ``wearpose evaluate``: simulated imu6 (bone orientations,
    free acceleration, IMU noise per ``noise``), known initial state; SIP / angular / positional
    / mesh error, jitter, translation error
    (:func:`wearpose.estimators.pip.evaluate.evaluate_variants`)."""
    # start-up: wearpose.estimators.pip.evaluate (with torch) adds ~1.6 s to importing this module
    from wearpose.estimators.pip.evaluate import evaluate_variants

    if frame_stride != 1:
        raise ConfigError("PIP's protocol scores every frame (the physics runs through the whole clip); drop --frame-stride")
    res = evaluate_variants({"model": est}, split, clips, noise=noise, seed=seed, store=store, progress=progress)
    row = res["rows"]["model"]
    metrics = finite_metrics(row)
    metrics.pop("zmp_frames_pct", None)
    per_clip = [{"clip": c["clip"], "frames": c["frames"], **{k: c[k] for k in metrics if k in c}}
                for c in row["per_clip"]]
    return {"frames": res["frames"], "clip_ids": [c["clip"] for c in row["per_clip"]], "metrics": metrics,
            "per_clip": per_clip, "lead": "sip_error_deg", "protocol": res["protocol"], "detail": res}
