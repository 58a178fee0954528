"""Each method's evaluation protocol behind one call: a model -> its paper's metrics on
simulated held-out clips of a corpus split.

:func:`evaluate_model` is what ``wearpose evaluate`` runs for one model of any method whose
declaration names a single-model protocol (:class:`wearpose.estimators.method.EstimatorEntry`
``protocol``; the EM-POSE family instead compares several checkpoints on shared simulations,
its ``compare`` protocol :func:`wearpose.estimators.empose.evaluate.evaluate_models`). Each
protocol is the method's own (``estimators/<method>/entry.py`` over ``evaluate.py``, the code
the benchmark tables were made with), so the same clips and seeds give the committed tables'
figures:

- ``pip``: simulated imu6 (bone orientations, free acceleration, default IMU noise), known
  initial state; SIP / angular / positional / mesh error, jitter, translation error.
- ``birae``: the clean scenario (ideal segment orientations) at the weights' rate, offline;
  MPJAE per joint group and the +-1 / +-2 sigma coverage of the calibrated uncertainty.
- ``miposer``: calibrated and uncalibrated upper-body MPJPE, pelvis-aligned.
- ``imuposer``: the IMU-only baseline's upper-body MPJPE on the same clips.

Every result has the same top-level keys: ``model``, ``method``, ``kit``, ``split``, ``clips``,
``clip_ids``, ``frames``, ``seed``, ``noise``, ``protocol``, ``store`` (which store and corpus
version the clips came from: :meth:`wearpose.motion.CorpusStore.provenance`), ``metrics`` (flat,
report units, the unit in the key) and ``detail`` (the protocol's own result).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Callable

from wearpose.errors import ConfigError
from wearpose.estimators.method import resolve
from wearpose.estimators.run import ModelSource
from wearpose.motion import CorpusStore

Progress = Callable[[int, int], None]


def protocols() -> dict[str, str]:
    """Estimator (registry name) -> its declared single-model protocol (``"module:function"``)."""
    from wearpose.estimators.registry import find_estimator, list_estimators

    out = {}
    for name in list_estimators():
        try:
            entry = find_estimator(name)[1]
        except ConfigError:  # registered with register_estimator only: no declaration, no protocol
            continue
        if entry.protocol:
            out[name] = entry.protocol
    return out


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
    known = protocols()
    if source.method not in known:
        raise ConfigError(f"{source.name}: no evaluation protocol for method {source.method!r} here; "
                          f"expected one of {', '.join(known)} (EM-POSE models: evaluate_models)")
    store = store or CorpusStore()
    if not store.clips(split=split):
        raise ConfigError(f"corpus store {store.root}: the {split!r} split has no clips; prepare one with a "
                          f"{split} split (wearpose data prepare) or choose another --split")
    out = resolve(known[source.method])(source.make(), store, split, clips, seed, noise, progress, frame_stride)
    return {"model": source.name, "method": source.method, "kit": source.kit, "split": split,
            "clips": len(out["clip_ids"]), "seed": seed, "noise": noise, "frame_stride": frame_stride,
            "store": store.provenance(),
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
