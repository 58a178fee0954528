"""BiRAE's training entry (``wearpose train birae``: options -> config -> estimator -> the two
training phases) and evaluation protocol (``wearpose evaluate``), named by its declaration
:data:`wearpose.estimators.birae.METHOD`."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Callable, Mapping

from wearpose.errors import ConfigError
from wearpose.estimators.birae.config import REPS, BiraeConfig
from wearpose.estimators.method import OptionError, TrainRun, finite_metrics


def train_from_options(opts: Mapping[str, Any], run: TrainRun) -> dict[str, Any]:
    """Train BiRAE for input representation ``--rep`` with the ``--config`` preset, overridden by
    the options given: clean synthetic orientations first, then the augmented phase.

    Returns:
        :func:`~wearpose.estimators.birae.train.train_birae`'s result with ``method``, ``rep``
        and ``config``.
    """
    # start-up: wearpose.estimators.birae.estimator adds ~160 ms to importing this module
    from wearpose.estimators.birae.estimator import BiraeEstimator
    # start-up: wearpose.estimators.birae.train adds ~120 ms to importing this module
    from wearpose.estimators.birae.train import train_birae

    rep = opts["rep"]
    if rep not in REPS:
        raise OptionError("--rep", f"unknown representation {rep!r}; expected one of {', '.join(REPS)}")
    cfg = BiraeConfig.preset(run.config, rep).override(
        **{k: opts[k] for k in ("hidden", "width", "batch_size", "train_clips", "lr", "epochs_sigma")}, **run.config_overrides())
    out = run.out or Path("runs") / f"birae_{rep}_{run.config}"
    res = train_birae(BiraeEstimator(cfg), out, resume=run.resume, threads=run.threads, device=run.device,
                      epochs_clean=opts["epochs_clean"], epochs_aug=opts["epochs_aug"],
                      checkpoint_every=run.checkpoint_every, train_command=run.train_command,
                      init_from=run.init_from, quiet=run.quiet, console=run.console, store=run.corpus_store(),
                      recipe=run.recipe)
    return {"method": "birae", "rep": rep, "config": cfg.to_dict(), **res}


def protocol(est: Any, store: Any, split: str, clips: int | None, seed: int, noise: str,
             progress: Callable[[int, int], None] | None, frame_stride: int = 1) -> dict[str, Any]:
    """BiRAE's evaluation protocol for ``wearpose evaluate``: the clean scenario (ideal segment
    orientations) at the weights' rate, offline; MPJAE per joint group and the +-1 / +-2 sigma
    coverage of the calibrated uncertainty and its mean per-joint sigma
    (:func:`wearpose.estimators.birae.evaluate.evaluate`); the same per clip."""
    # start-up: wearpose.estimators.birae.evaluate adds ~120 ms to importing this module
    from wearpose.estimators.birae.evaluate import (
        evaluate, per_clip_uncertainty, public, scenario_recordings, uncertainty_summary,
    )

    if noise != "default":
        raise ConfigError(f"--noise {noise!r}: BiRAE's protocol has its own scenarios (the clean one here); "
                          "expected the default")
    recs = scenario_recordings(split, "clean", rate=est.fps, limit=clips, store=store, seed=seed)
    res = evaluate(est, recs, mode="offline", frame_stride=frame_stride, keep_uncertainty=True, progress=progress)
    unc = uncertainty_summary(res)
    metrics = finite_metrics(public(res))
    metrics.update({f"{k}_pct": 100 * float(unc[k]) for k in ("within_1sigma", "within_2sigma")})
    metrics["pearson_r_sigma_error"] = float(unc["pearson_r_sigma_error"])
    metrics["mean_sigma_deg"] = math.degrees(float(res["_joint_sigma"].mean()))
    for k in ("clips", "frames", "frame_stride", "mc_samples"):
        metrics.pop(k, None)
    per_clip = [{**c, **u} for c, u in zip(res["per_clip"], per_clip_uncertainty(res))]
    return {"frames": res["frames"], "clip_ids": [c for c, _, _ in recs], "metrics": metrics, "per_clip": per_clip,
            "lead": "mpjae_all_deg",
            "protocol": "clean scenario (ideal segment orientations), offline, MC-dropout uncertainty calibrated "
                        "with the weights' sigma scale (BiRAE protocol)",
            "detail": {**public(res), "uncertainty": {k: v for k, v in unc.items() if k != "reliability"}}}
