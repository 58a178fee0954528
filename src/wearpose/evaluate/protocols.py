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
``clip_ids``, ``frames``, ``seed``, ``noise``, ``bodies`` and ``betas`` (the wearers:
:mod:`wearpose.estimators.bodies`), ``protocol``, ``store`` (which store and corpus
version the clips came from: :meth:`wearpose.motion.CorpusStore.provenance`), ``metrics`` (flat,
report units, the unit in the key), ``per_clip`` (each clip's figures), ``breakdown``
(:func:`breakdown`: the per-clip figures grouped by source and by motion class) and ``detail``
(the protocol's own result). :func:`compare_models` runs a ``compare`` protocol (EM-POSE) and
adds the same breakdown to each of its models.

Protocols: the corpus test split (in-lab), one lab of it (``store.subset(source)``: the
unseen-lab figure of a model trained on the other lab), or the held-out procedural store
(:func:`unseen_motion_store`: motion families the corpus lacks).
"""

from __future__ import annotations

import json
import platform
from pathlib import Path
from typing import Any, Callable

import torch

from wearpose.errors import ConfigError
from wearpose.estimators.bodies import clip_bodies, wearer_store, wearers
from wearpose.estimators.method import resolve
from wearpose.estimators.registry import find_estimator, list_estimators
from wearpose.estimators.run import ModelSource
from wearpose.motion import CorpusStore
from wearpose.motion.procedural_store import UNSEEN_MOTION_PER_FAMILY, build_procedural_store, unseen_motion_dir
from wearpose.motion.store import motion_class

Progress = Callable[[int, int], None]


def protocols() -> dict[str, str]:
    """Estimator (registry name) -> its declared single-model protocol (``"module:function"``)."""
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
                   progress: Progress | None = None, frame_stride: int = 1, bodies: str = "corpus") -> dict[str, Any]:
    """``source``'s figures under its method's protocol (module doc) on the first ``clips``
    clips of ``split`` (all when None), scoring every ``frame_stride``-th frame (the shipped
    MI-Poser and IMUPoser cards were measured with 4), each clip on the wearer ``bodies``
    gives it (:mod:`wearpose.estimators.bodies`: ``"corpus"`` the clip's own body,
    ``"heldout"`` a held-out body per clip, re-fitted before the protocol sees it; the
    result's ``bodies`` and ``betas``, clip id -> the wearer's betas, say which).

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
    est = source.make()
    worn = wearer_store(store, bodies, getattr(est, "body", None), seed)
    out = resolve(known[source.method])(est, worn, split, clips, seed, noise, progress, frame_stride)
    parts = breakdown(out.get("per_clip", []), store)
    return {"model": source.name, "method": source.method, "kit": source.kit, "split": split,
            "clips": len(out["clip_ids"]), "seed": seed, "noise": noise, "frame_stride": frame_stride,
            "store": store.provenance(), "sources": sorted(parts["source"]),
            "checkpoint": str(source.path) if source.path else None, **out, "breakdown": parts,
            "bodies": bodies, "betas": clip_bodies(worn, out["clip_ids"])}


def compare_models(compare: str, checkpoints: dict[str, Path], split: str, clips: int | None, *,
                   store: CorpusStore, **options: Any) -> dict[str, Any]:
    """A ``compare`` protocol (``"module:function"``, EM-POSE's
    :func:`~wearpose.estimators.empose.evaluate.evaluate_models`) on ``checkpoints``, each
    model's per-clip figures grouped by source and class (``models[name]["breakdown"]``);
    ``options`` are the protocol's own (``noise``, ``seed``, ``offsets``, ``spread``, ``progress``)."""
    res = resolve(compare)(checkpoints, split, clips, store=store, **options)
    for m in res["models"].values():
        m["breakdown"] = breakdown(m.get("per_clip", []), store)
    res["sources"] = sorted({s for m in res["models"].values() for s in m["breakdown"]["source"]})
    return res


def breakdown(per_clip: list[dict[str, Any]], store: CorpusStore) -> dict[str, dict[str, dict[str, Any]]]:
    """Per-clip figures grouped by source and by motion class of the clip's store entry
    (:func:`wearpose.motion.store.motion_class`: a procedural clip's family, a corpus clip's
    description without its style).

    Args:
        per_clip: ``[{"clip", "frames", <metric>: value, ...}]``, each value a mean over the
            clip's scored frames.

    Returns:
        ``{"source": {name: row}, "class": {name: row}}``, each ``row`` ``{"clips", "frames",
        <metric>: frame-weighted mean over the group's clips}`` (over every clip these are the
        pooled headline figures for the metrics that are frame means), groups sorted by name.
    """
    keys: dict[str, Callable[[str], str]] = {"source": lambda cid: _entry(store, cid)["source"],
                                              "class": lambda cid: motion_class(_entry(store, cid))}
    out: dict[str, dict[str, dict[str, Any]]] = {}
    for kind, key in keys.items():
        groups: dict[str, list[dict[str, Any]]] = {}
        for row in per_clip:
            groups.setdefault(key(row["clip"]), []).append(row)
        out[kind] = {g: _pool(rows) for g, rows in sorted(groups.items())}
    return out


def _entry(store: Any, cid: str) -> dict[str, Any]:
    """The store's index row of ``cid``; for a store without an index (a test's stand-in), the
    source and clip name that the clip id ``<source>/<subject>/<clip>`` gives."""
    if hasattr(store, "entry"):
        return store.entry(cid)
    return {"source": cid.partition("/")[0], "clip": cid.rpartition("/")[2]}


def _pool(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """``{"clips", "frames", <metric>: frame-weighted mean}`` of per-clip rows (a metric over
    the clips that have it)."""
    sums: dict[str, list[float]] = {}
    for r in rows:
        for k, v in r.items():
            if k not in ("clip", "frames") and isinstance(v, (int, float)) and r["frames"]:
                acc = sums.setdefault(k, [0.0, 0.0])
                acc[0] += float(v) * r["frames"]
                acc[1] += r["frames"]
    return {"clips": len(rows), "frames": sum(int(r["frames"]) for r in rows),
            **{k: a[0] / a[1] for k, a in sums.items() if a[1]}}


def breakdown_markdown(models: dict[str, dict[str, Any]], kind: str) -> str:
    """A markdown table of ``models[name]["breakdown"][kind]`` (``"source"`` or ``"class"``):
    one row per group, clips and frames, then each metric (one column per model and metric)."""
    named = {n: m["breakdown"][kind] for n, m in models.items() if m.get("breakdown", {}).get(kind)}
    if not named:
        return ""
    metrics = list(dict.fromkeys(k for b in named.values() for row in b.values() for k in row
                                 if k not in ("clips", "frames")))
    cols = [(n, k) for k in metrics for n in named]
    head = [k if len(named) == 1 else f"{k} ({n})" for n, k in cols]
    groups = list(dict.fromkeys(g for b in named.values() for g in b))
    first = next(iter(named.values()))
    lines = [f"| {kind} | clips | frames | " + " | ".join(head) + " |", "| --- |" + " --- |" * (2 + len(cols))]
    for g in groups:
        cells = [f"{named[n][g][k]:.4g}" if g in named[n] and k in named[n][g] else "-" for n, k in cols]
        row = first.get(g, {})
        lines.append(f"| {g} | {row.get('clips', '-')} | {row.get('frames', '-')} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def breakdown_sections(models: dict[str, dict[str, Any]]) -> list[str]:
    """Markdown lines: "## By source" and "## By motion class" with :func:`breakdown_markdown`
    (none when no model has a breakdown)."""
    out: list[str] = []
    for kind, title in (("source", "By source"), ("class", "By motion class")):
        table = breakdown_markdown(models, kind)
        if table:
            out += ["", f"## {title}", "", "Frame-weighted means of each clip's figures.", "", table]
    return out


def unseen_motion_store(per_family: int | None = None, seed: int = 0, *,
                        progress: Progress | None = None) -> CorpusStore:
    """The unseen-motion protocol's store (:mod:`wearpose.motion.procedural_store`), built at
    :func:`~wearpose.motion.procedural_store.unseen_motion_dir` the first time (about 1.5 s a
    clip) and opened from there afterwards."""
    n = per_family or UNSEEN_MOTION_PER_FAMILY
    root = unseen_motion_dir(n, seed)
    build_procedural_store(root, per_family=n, seed=seed, progress=progress)
    return CorpusStore(root)


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
    stem = Path(path_stem)
    stem.parent.mkdir(parents=True, exist_ok=True)
    first = next(iter(result["models"].values()))
    md = [f"# {title}", "", f"Produced by `{produced_by}` (`wearpose.evaluate.protocols.evaluate_model`).", "",
          f"{first['split']} split, {first['clips']} clips, {first['frames']} frames, kit {first['kit']}, seed "
          f"{first['seed']}, noise {first['noise']}; {wearers(first.get('bodies', 'corpus'))}.", "",
          markdown_table(result), "",
          f"Protocol: {first['protocol']}.", *breakdown_sections(result["models"]), "",
          "Clips: " + ", ".join(f"`{c}`" for c in first["clip_ids"])]
    if note:
        md += ["", note]
    stem.with_suffix(".md").write_text("\n".join(md) + "\n", encoding="utf-8")
    blob = {**result, "machine": {"python": platform.python_version(), "torch": torch.__version__}}
    stem.with_suffix(".json").write_text(json.dumps(blob, indent=1, default=str) + "\n", encoding="utf-8")
    return stem.with_suffix(".md"), stem.with_suffix(".json")
