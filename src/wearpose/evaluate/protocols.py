"""Each method's evaluation protocol behind one call: a model -> its paper's metrics on
simulated held-out clips of a corpus split.

:func:`evaluate_model` is what ``wearpose evaluate`` runs for the sparse-IMU methods (the EM-POSE
family compares several checkpoints on shared simulations:
:func:`wearpose.estimators.empose.evaluate.evaluate_models`). Each protocol is the method's own
(``estimators/<method>/evaluate.py``, the code the benchmark tables were made with), so the same
clips and seeds give the committed tables' figures:

- ``pip``: simulated imu6 (bone orientations, free acceleration, default IMU noise), known
  initial state; SIP / angular / positional / mesh error, jitter, translation error
  (:func:`wearpose.estimators.pip.evaluate.evaluate_variants`).
- ``birae``: the clean scenario (ideal segment orientations) at the weights' rate, offline;
  MPJAE per joint group and the +-1 / +-2 sigma coverage of the calibrated uncertainty
  (:func:`wearpose.estimators.birae.evaluate.evaluate`).
- ``miposer``: calibrated and uncalibrated upper-body MPJPE, pelvis-aligned
  (:func:`wearpose.estimators.miposer.evaluate.evaluate_miposer`).
- ``imuposer``: the IMU-only baseline's upper-body MPJPE on the same clips
  (:func:`~wearpose.estimators.miposer.evaluate.evaluate_imuposer`).

Every result has the same top-level keys: ``model``, ``method``, ``kit``, ``split``, ``clips``,
``clip_ids``, ``frames``, ``seed``, ``noise``, ``protocol``, ``metrics`` (flat, report units, the
unit in the key) and ``detail`` (the protocol's own result).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Callable

from wearpose.errors import ConfigError
from wearpose.estimators.base import Estimator
from wearpose.estimators.run import ModelSource
from wearpose.motion import CorpusStore

Progress = Callable[[int, int], None]


def _finite(d: dict[str, Any]) -> dict[str, float]:
    return {k: float(v) for k, v in d.items() if isinstance(v, (int, float)) and not isinstance(v, bool)
            and math.isfinite(float(v))}


def _pip(est: Estimator, store: CorpusStore, split: str, clips: int | None, seed: int, noise: str,
         progress: Progress | None, frame_stride: int = 1) -> dict[str, Any]:
    from wearpose.estimators.pip.evaluate import evaluate_variants

    if frame_stride != 1:
        raise ConfigError("PIP's protocol scores every frame (the physics runs through the whole clip); drop --frame-stride")
    res = evaluate_variants({"model": est}, split, clips, noise=noise, seed=seed, store=store, progress=progress)
    row = res["rows"]["model"]
    metrics = _finite(row)
    metrics.pop("zmp_frames_pct", None)
    return {"frames": res["frames"], "clip_ids": [c["clip"] for c in row["per_clip"]], "metrics": metrics,
            "protocol": res["protocol"], "detail": res}


def _birae(est: Estimator, store: CorpusStore, split: str, clips: int | None, seed: int, noise: str,
           progress: Progress | None, frame_stride: int = 1) -> dict[str, Any]:
    from wearpose.estimators.birae.evaluate import evaluate, public, scenario_recordings, uncertainty_summary

    if noise != "default":
        raise ConfigError(f"--noise {noise!r}: BiRAE's protocol has its own scenarios (the clean one here); "
                          "expected the default")
    recs = scenario_recordings(split, "clean", rate=est.fps, limit=clips, store=store, seed=seed)
    res = evaluate(est, recs, mode="offline", frame_stride=frame_stride, keep_uncertainty=True, progress=progress)
    unc = uncertainty_summary(res)
    metrics = _finite(public(res))
    metrics.update({f"{k}_pct": 100 * float(unc[k]) for k in ("within_1sigma", "within_2sigma")})
    metrics["pearson_r_sigma_error"] = float(unc["pearson_r_sigma_error"])
    for k in ("clips", "frames", "frame_stride", "mc_samples"):
        metrics.pop(k, None)
    return {"frames": res["frames"], "clip_ids": [c for c, _, _ in recs], "metrics": metrics,
            "protocol": "clean scenario (ideal segment orientations), offline, MC-dropout uncertainty calibrated "
                        "with the weights' sigma scale (BiRAE protocol)",
            "detail": {**public(res), "uncertainty": {k: v for k, v in unc.items() if k != "reliability"}}}


def _miposer(est: Estimator, store: CorpusStore, split: str, clips: int | None, seed: int, noise: str,
             progress: Progress | None, frame_stride: int = 1) -> dict[str, Any]:
    from wearpose.estimators.miposer.evaluate import evaluate_miposer

    res = evaluate_miposer({"model": est}, split, clips, seed=seed, noise=noise, frame_stride=frame_stride,
                           store=store, progress=progress)
    m = res["models"]["model"]
    metrics = {f"{cond}_{k}": v for cond, s in m.items() for k, v in _finite(s).items() if k != "frames"}
    return {"frames": m["calibrated"]["frames"], "clip_ids": store.clips(split=split)[: clips or None],
            "metrics": metrics,
            "protocol": "simulated headset VIO + wrist EM after a 1 s T-pose, calibrated and uncalibrated; "
                        "upper-body MPJPE, pelvis-aligned (MI-Poser protocol)", "detail": res}


def _imuposer(est: Estimator, store: CorpusStore, split: str, clips: int | None, seed: int, noise: str,
              progress: Progress | None, frame_stride: int = 1) -> dict[str, Any]:
    from wearpose.estimators.miposer.evaluate import evaluate_imuposer

    res = evaluate_imuposer(est, split, clips, seed=seed, noise=noise, frame_stride=frame_stride, store=store,
                            progress=progress)
    metrics = {k: v for k, v in _finite(res["summary"]).items() if k != "frames"}
    return {"frames": res["summary"]["frames"], "clip_ids": store.clips(split=split)[: clips or None],
            "metrics": metrics, "protocol": "simulated head + wrist IMUs (IMUPoser baseline), upper-body MPJPE, "
                                            "pelvis-aligned, on MI-Poser's clips", "detail": res}


#: method (registry name) -> protocol.
PROTOCOLS: dict[str, Callable[..., dict[str, Any]]] = {"pip": _pip, "birae": _birae, "miposer": _miposer,
                                                       "imuposer": _imuposer}


def evaluate_model(source: ModelSource, *, split: str = "test", clips: int | None = None, seed: int = 0,
                   noise: str = "default", store: CorpusStore | None = None,
                   progress: Progress | None = None, frame_stride: int = 1) -> dict[str, Any]:
    """``source``'s figures under its method's protocol (module doc) on the first ``clips``
    clips of ``split`` (all when None), scoring every ``frame_stride``-th frame (the shipped
    MI-Poser and IMUPoser cards were measured with 4).

    Raises:
        ConfigError: the method has no protocol here, or the split holds no clips (a table of
            nothing must not look like a result).
    """
    if source.method not in PROTOCOLS:
        raise ConfigError(f"{source.name}: no evaluation protocol for method {source.method!r} here; "
                          f"expected one of {', '.join(PROTOCOLS)} (EM-POSE models: evaluate_models)")
    store = store or CorpusStore()
    if not store.clips(split=split):
        raise ConfigError(f"corpus store {store.root}: the {split!r} split has no clips; prepare one with a "
                          f"{split} split (wearpose data prepare) or choose another --split")
    out = PROTOCOLS[source.method](source.make(), store, split, clips, seed, noise, progress, frame_stride)
    return {"model": source.name, "method": source.method, "kit": source.kit, "split": split,
            "clips": len(out["clip_ids"]), "seed": seed, "noise": noise, "frame_stride": frame_stride,
            "store": str(store.root),
            "checkpoint": str(source.path) if source.path else None, **out}


def markdown_table(result: dict[str, Any]) -> str:
    """Rows = metrics, columns = models, of ``{"models": {name: evaluate_model result}}``."""
    models = result["models"]
    keys = list(dict.fromkeys(k for m in models.values() for k in m["metrics"]))
    lines = ["| metric | " + " | ".join(models) + " |", "| --- |" + " --- |" * len(models)]
    for k in keys:
        lines.append(f"| {k} | " + " | ".join(f"{m['metrics'][k]:.4g}" if k in m["metrics"] else "-"
                                              for m in models.values()) + " |")
    return "\n".join(lines)


def write_result(result: dict[str, Any], path_stem: str | Path, *, title: str, produced_by: str,
                 note: str | None = None) -> tuple[Path, Path]:
    """``<stem>.md`` (title, the command, the table, protocol, clips) and ``<stem>.json`` (all of it)."""
    import json
    import platform

    import torch

    stem = Path(path_stem)
    stem.parent.mkdir(parents=True, exist_ok=True)
    first = next(iter(result["models"].values()))
    md = [f"# {title}", "", f"Produced by `{produced_by}` (`wearpose.evaluate.protocols.evaluate_model`).", "",
          f"{first['split']} split, {first['clips']} clips, {first['frames']} frames, kit {first['kit']}, seed "
          f"{first['seed']}, noise {first['noise']}.", "", markdown_table(result), "",
          f"Protocol: {first['protocol']}.", "", "Clips: " + ", ".join(f"`{c}`" for c in first["clip_ids"])]
    if note:
        md += ["", note]
    stem.with_suffix(".md").write_text("\n".join(md) + "\n", encoding="utf-8")
    blob = {**result, "machine": {"python": platform.python_version(), "torch": torch.__version__}}
    stem.with_suffix(".json").write_text(json.dumps(blob, indent=1, default=str) + "\n", encoding="utf-8")
    return stem.with_suffix(".md"), stem.with_suffix(".json")
