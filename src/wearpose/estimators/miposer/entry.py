"""MI-Poser's training entry (``wearpose train miposer``: options -> config -> estimator ->
training run) and the evaluation protocols of MI-Poser and its IMUPoser baseline
(``wearpose evaluate``), named by its declaration :data:`wearpose.estimators.miposer.METHOD`."""

from __future__ import annotations

import dataclasses
from collections import Counter
from pathlib import Path
from typing import Any, Callable, Mapping

from wearpose.estimators.method import OptionError, TrainRun, finite_metrics
from wearpose.estimators.miposer.config import MiposerConfig
from wearpose.estimators.trainconfig import TrainConfig


def train_from_options(opts: Mapping[str, Any], run: TrainRun) -> dict[str, Any]:
    """Train the ``--model`` network (MI-Poser's IK network or the IMUPoser baseline) for
    ``--wrists`` wrist sensors with the ``--config`` preset.

    Returns:
        :func:`~wearpose.estimators.miposer.train.train_miposer`'s result with ``method`` (the
        estimator's registry name), ``model``, ``wrists`` and ``config``.
    """
    # start-up: wearpose.estimators.miposer.train (with torch) adds ~1.6 s to importing this module
    from wearpose.estimators.miposer.train import train_miposer

    model, wrists = opts["model"], opts["wrists"]
    if model not in ("avatarposer", "imuposer"):
        raise OptionError("--model", f"unknown model {model!r}; expected avatarposer or imuposer")
    if wrists not in (1, 2):
        raise OptionError("--wrists", f"expected 1 or 2, got {wrists}")
    cfg = MiposerConfig.preset(run.config, wrists=wrists, model=model).override(
        batch_size=opts["batch_size"], lr=opts["lr"], **run.config_overrides())
    if model == "imuposer":
        # start-up: wearpose.estimators.miposer.baselines (with torch) adds ~2.0 s to importing this module
        from wearpose.estimators.miposer.baselines import ImuPoserEstimator

        est: Any = ImuPoserEstimator(cfg)
        out = run.out or Path("runs") / f"imuposer_{run.config}"
    else:
        # start-up: wearpose.estimators.miposer.estimator (with torch) adds ~2.1 s to importing this module
        from wearpose.estimators.miposer.estimator import MiposerEstimator

        est = MiposerEstimator(cfg)
        out = run.out or Path("runs") / f"miposer{wrists}_{run.config}"
    res = train_miposer(est, out, **run.loop())
    return {"method": est.name, "model": model, "wrists": wrists, "config": cfg.to_dict(), **res}


def train_nbeats_from_options(opts: Mapping[str, Any], run: TrainRun) -> dict[str, Any]:
    """``wearpose train nbeats``: MIM's N-BEATS trajectory forecaster
    (:func:`wearpose.interference.nbeats.train`) with the ``--config`` preset (``--epochs`` and
    ``--seed`` overriding it) on the train split of ``--source``'s clips (all labs by default),
    at most ``--max-train-clips`` of them, plus the training mix (``--mirror``, ``--speed-copies``,
    ``--procedural``, ...; :mod:`wearpose.estimators.trainmix`); or, with ``--ship CHECKPOINT``,
    no training: that checkpoint measured on the test split and shipped as package weights
    ``--name`` (:func:`~wearpose.interference.nbeats.ship_tested`).

    Returns:
        ``{"method": "nbeats", "best_val_mae_cm", "epochs", "out_dir", "config", "summary"}``, or
        with ``--ship`` ``{"method": "nbeats", "shipped", "test", "summary"}`` (``summary``: the
        line printed when done).
    """
    import torch  # start-up: torch adds ~1.3 s to importing this module

    # start-up: wearpose.interference (with torch) adds ~2.2 s to importing this module
    from wearpose.interference import nbeats
    from wearpose.motion import CorpusStore  # start-up: loaded with nbeats above; named here for the store

    torch.set_num_threads(run.threads or 1)
    if opts["ship"] is not None:
        res = nbeats.ship_tested(opts["ship"], opts["name"], opts["notes"])
        return {"method": "nbeats", "summary": f"shipped {res['shipped']} (test MAE {res['test']['mae_cm']:.3f} cm)",
                **res}
    cfg = nbeats.NBeatsConfig.preset(run.config)
    cfg = dataclasses.replace(cfg, **{k: v for k, v in (("epochs", run.epochs), ("seed", run.seed)) if v is not None})
    out = Path(run.out) if run.out is not None else Path("runs/nbeats_cpu")
    log = (lambda s: None) if run.quiet else (lambda s: print(s, flush=True))
    store = run.corpus_store() or CorpusStore()
    source, provenance = _nbeats_train_source(store, cfg.seed, run, opts["max_train_clips"])
    res = nbeats.train(cfg, out, resume=run.resume, threads=run.threads or 1, command=run.train_command,
                       log=log, store=store, train_source=source,
                       provenance={**provenance, "recipe": dict(run.recipe) if run.recipe else None})
    return {"method": "nbeats", "out_dir": str(out), "config": cfg.to_dict(), **res,
            "summary": f"best val MAE {res['best_val_mae_cm']:.3f} cm after {res['epochs']} epochs; checkpoints in {out}"}


def _nbeats_train_source(store: Any, seed: int, run: TrainRun, limit: int | None) -> tuple[Any, dict[str, Any]]:
    """The forecaster's train clips: ``store``'s train split (``limit`` corpus clips at most,
    spread over it) and the run's training mix (:class:`~wearpose.estimators.trainmix.TrainingMix`)
    -> ``((store, ids), what the checkpoint keeps of them)``: the clips per source and per kind
    (corpus, augmented, procedural), and with a mix its settings and the card's sentence. The
    mix applies to the motion only: the forecaster reads wrist trajectories, no simulated
    sensors (the command takes no ``--site-jitter``)."""
    # start-up: the training mix loads torch and the motion stack (~1.6 s); the entry module stays torch-free
    from wearpose.estimators.trainmix import TrainingMix, training_source
    from wearpose.motion.procedural import PREFIX  # start-up: as above (the motion stack)
    # start-up: as above (with torch)
    from wearpose.interference.nbeats import spread

    mix_cfg = TrainConfig().override(**{**run.mix_overrides(), "seed": seed})
    mix = TrainingMix.from_config(mix_cfg)
    ids = spread(sorted(store.clips(split="train")), limit)
    per_source = Counter(store.entry(c).get("source", "?") for c in ids)
    tstore, all_ids, fingerprint = training_source("train", store, ids, mix_cfg, None, namespace="nbeats")
    procedural = sum(c.startswith(PREFIX) for c in all_ids)  # the rest of the added ids are augmented copies
    provenance: dict[str, Any] = {"clips_per_source": dict(sorted(per_source.items())),
                                  "train_clips_by_kind": {"corpus": len(ids),
                                                          "augmented": len(all_ids) - len(ids) - procedural,
                                                          "procedural": procedural}}
    if fingerprint:
        provenance["mix"] = {**fingerprint["mix"], "description": mix.describe()}
    return (tstore, all_ids), provenance


def protocol(est: Any, store: Any, split: str, clips: int | None, seed: int, noise: str,
             progress: Callable[[int, int], None] | None, frame_stride: int = 1) -> dict[str, Any]:
    """MI-Poser's protocol: simulated headset VIO + wrist EM after a 1 s T-pose, calibrated and
    uncalibrated upper-body MPJPE, pelvis-aligned (:func:`wearpose.estimators.miposer.evaluate.evaluate_miposer`)."""
    # start-up: wearpose.estimators.miposer.evaluate (with torch) adds ~2.6 s to importing this module
    from wearpose.estimators.miposer.evaluate import evaluate_miposer

    res = evaluate_miposer({"model": est}, split, clips, seed=seed, noise=noise, frame_stride=frame_stride,
                           store=store, progress=progress)
    m = res["models"]["model"]
    metrics = {f"{cond}_{k}": v for cond, s in m.items() for k, v in finite_metrics(s).items() if k != "frames"}
    ids = store.clips(split=split)[: clips or None]
    res["detection"] = detection_protocol(est, store, split, ids, seed)
    metrics.update({f"detection_{k}_at_{e}cm": v for e, dm in res["detection"]["metrics"].items()
                    for k, v in finite_metrics(dm).items() if k != "frames"})
    return {"frames": m["calibrated"]["frames"], "clip_ids": ids, "metrics": metrics,
            "per_clip": res["per_clip"]["model"], "lead": "calibrated_mpjpe_upper_cm",
            "protocol": "simulated headset VIO + wrist EM after a 1 s T-pose, calibrated and uncalibrated; "
                        "upper-body MPJPE, pelvis-aligned (MI-Poser protocol); interference detection on the same "
                        f"clips: each wrist against a room-fixed source, condition {DETECTION_CONDITION!r}, "
                        f"interfered = EM position error > {' or '.join(f'{e:g}' for e in DETECTION_E_P_CM)} cm, "
                        "MIM's threshold (MI-Poser Table 3 / Fig. 8)", "detail": res}


#: MI-Poser Table 3's setting for ``wearpose evaluate``: the "standard" condition, a frame is
#: interfered when its EM position error exceeds 10 cm (benchmarks/results/interference_detection);
#: also 2 cm (a Fig. 8 point): the first 20 test clips hold no frame above 10 cm (the study's 10
#: minutes of sessions 0.29 %), so on a few clips only the 2 cm MCC is defined.
DETECTION_CONDITION, DETECTION_E_P_CM = "standard", (10.0, 2.0)


def detection_protocol(est: Any, store: Any, split: str, ids: list[str], seed: int) -> dict[str, Any]:
    """MIM's interference detection on clips ``ids`` as MI-Poser Table 3 scores it: each wrist
    simulated against the room-fixed source of User Study 2 under :data:`DETECTION_CONDITION`
    (:func:`wearpose.interference.study.world_clips`, wrists leaving 1.5 m left out), flagged
    at the estimator's MIM threshold (``est.mim_config``, else
    :func:`~wearpose.estimators.miposer.mim.default_mim_config`), scored against "EM position
    error > e_P" for each e_P (cm) of :data:`DETECTION_E_P_CM`
    (:func:`~wearpose.interference.study.detection_metrics`: MCC, F1, precision, recall; None
    when no frame is interfered or flagged).

    Returns:
        ``{"metrics": {f"{e_P:g}": metrics}, "threshold_deg", "condition", "e_p_cm", "wrists",
        "out_of_range"}``.
    """
    # start-up: wearpose.estimators.miposer.mim (with torch) adds ~1.5 s to importing this module
    from wearpose.estimators.miposer.mim import default_mim_config
    # start-up: wearpose.interference (with torch) adds ~2.2 s to importing this module
    from wearpose.interference import study

    th = (est.mim_config or default_mim_config()).threshold_deg
    clips, skipped = study.world_clips(((c, store.load(c)) for c in ids), split, DETECTION_CONDITION, est.body, seed)
    metrics = {f"{e:g}": study.detection_metrics(clips, th, e) for e in DETECTION_E_P_CM}
    return {"metrics": metrics, "threshold_deg": th,
            "condition": DETECTION_CONDITION, "e_p_cm": DETECTION_E_P_CM, "wrists": len(clips),
            "out_of_range": skipped}


def imuposer_protocol(est: Any, store: Any, split: str, clips: int | None, seed: int, noise: str,
                      progress: Callable[[int, int], None] | None, frame_stride: int = 1) -> dict[str, Any]:
    """The IMU-only baseline's upper-body MPJPE on MI-Poser's clips
    (:func:`~wearpose.estimators.miposer.evaluate.evaluate_imuposer`)."""
    # start-up: wearpose.estimators.miposer.evaluate (with torch) adds ~2.6 s to importing this module
    from wearpose.estimators.miposer.evaluate import evaluate_imuposer

    res = evaluate_imuposer(est, split, clips, seed=seed, noise=noise, frame_stride=frame_stride, store=store,
                            progress=progress)
    metrics = {k: v for k, v in finite_metrics(res["summary"]).items() if k != "frames"}
    return {"frames": res["summary"]["frames"], "clip_ids": store.clips(split=split)[: clips or None],
            "metrics": metrics, "per_clip": res["per_clip"], "lead": "mpjpe_upper_cm",
            "protocol": "simulated head + wrist IMUs (IMUPoser baseline), upper-body MPJPE, "
                        "pelvis-aligned, on MI-Poser's clips", "detail": res}
