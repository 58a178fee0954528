"""EM-POSE Table 2 on our data: several EM-POSE-family checkpoints (LGD-RNN and the learned
baselines) evaluated on the same simulated held-out recordings.

Protocol (the one of :func:`wearpose.estimators.empose.train.evaluate_empose`, which evaluates a
single LGD-RNN checkpoint; :func:`evaluate_models` gives it identical numbers and simulates each
clip only once for all models):

- clips: the corpus ``split`` (default ``test``; sorted ids, first ``limit``);
- each clip is resampled to the checkpoints' rate and simulated with the kit's EM error model
  ``noise`` (default ``"default"``) and a random synthetic subject (offsets ``O_p``) seeded in the
  ``"eval"`` namespace (:func:`~wearpose.estimators.empose.data.clip_seed`), i.e. subjects never
  drawn for training; the recording carries those offsets (the calibrated ``O_p`` EM-POSE
  assumes; the baselines ignore them);
- only frames where every sensor is valid count (EM-POSE Sec. 6.2);
- wearers (``bodies``, :mod:`wearpose.estimators.bodies`): the clip's own body (``"corpus"``,
  beta = 0) or a held-out body per clip (``"heldout"``), the clip re-fitted to it before it is
  simulated;
- ground truth: the clip's pose with the root expressed in the EM source frame (like every
  estimate) and its wearer's betas; joints from the same body model, zero translation;
- metrics (:mod:`wearpose.evaluate`) on the 15 major joints: MPJPE (root-aligned), PA-MPJPE
  (Procrustes-aligned), MPJAE (root-relative global rotations); mean and standard deviation over
  all evaluated frames of all clips, in mm and degrees;
- the shape estimate (EM-POSE estimates one body shape per sequence, Sec. 5.3): per clip the
  height error (standing height of the estimated body vs the wearer's, cm) and the zero-pose
  vertex error (mean skin vertex distance at zero pose, mm), :func:`wearpose.evaluate.metrics.shape_errors`;
  their medians and means over clips.

:func:`table2_markdown` renders the result in the structure of the paper's Table 2 (rows
ResNet, BiRNN, LGD-RNN), :func:`write_table2` writes ``.md`` + ``.json``.
"""

from __future__ import annotations

import json
import math
import platform
import time
from pathlib import Path
from typing import Any, Mapping, Sequence

import torch

from wearpose.errors import ConfigError
from wearpose.body.skeleton import JOINT_NAMES, MAJOR_JOINTS
from wearpose.estimators.bodies import clip_bodies, wearer_store
from wearpose.estimators.bodies import wearers
from wearpose.estimators.seeding import clip_seed
from wearpose.evaluate.metrics import (JointErrorSplit, joint_error_split, mpjae, mpjpe, pa_mpjpe,
                                       pool_joint_error_splits)
from wearpose.evaluate.metrics import shape_errors
from wearpose.geometry import axis_angle_to_matrix
import dataclasses
import inspect
import numpy as np

#: Paper's Table 2 (real test set, 12 sensors), for context in the report: mean, std.
PAPER_TABLE2_12 = {
    "ResNet": {"mpjpe_mm": (41.5, 27.6), "pa_mpjpe_mm": (30.9, 21.7), "mpjae_deg": (14.6, 9.8)},
    "BiRNN": {"mpjpe_mm": (37.3, 24.1), "pa_mpjpe_mm": (28.5, 18.6), "mpjae_deg": (14.1, 9.1)},
    "LGD-RNN": {"mpjpe_mm": (31.8, 21.0), "pa_mpjpe_mm": (24.8, 16.4), "mpjae_deg": (13.3, 9.2)},
}


#: Paper's Table 3 (ablations, 12 sensors, real test set), same layout.
PAPER_TABLE3_12 = {
    "no [R,t]": {"mpjpe_mm": (167.6, 212.7), "pa_mpjpe_mm": (134.3, 113.3), "mpjae_deg": (37.5, 34.7)},
    "no t": {"mpjpe_mm": (35.6, 25.8), "pa_mpjpe_mm": (29.0, 19.4), "mpjae_deg": (14.4, 10.0)},
    "ori only": {"mpjpe_mm": (50.8, 30.0), "pa_mpjpe_mm": (31.2, 20.4), "mpjae_deg": (14.3, 9.8)},
    "pos only": {"mpjpe_mm": (33.6, 28.3), "pa_mpjpe_mm": (27.5, 20.8), "mpjae_deg": (16.2, 11.3)},
    "no RNN": {"mpjpe_mm": (36.9, 25.4), "pa_mpjpe_mm": (26.5, 19.9), "mpjae_deg": (14.3, 10.3)},
    "full": {"mpjpe_mm": (31.8, 21.0), "pa_mpjpe_mm": (24.8, 16.4), "mpjae_deg": (13.3, 9.2)},
}
#: Paper's Table 4 (cross-subject: trained on subjects 1-4, tested on subject 5), same layout.
PAPER_TABLE4 = {
    "BiRNN 6": {"mpjpe_mm": (37.2, 26.7), "pa_mpjpe_mm": (33.8, 19.2), "mpjae_deg": (15.0, 7.8)},
    "LGD-RNN 6": {"mpjpe_mm": (32.0, 25.0), "pa_mpjpe_mm": (29.5, 17.7), "mpjae_deg": (13.6, 7.3)},
    "BiRNN 12": {"mpjpe_mm": (45.9, 34.3), "pa_mpjpe_mm": (40.2, 22.7), "mpjae_deg": (15.1, 8.0)},
    "LGD-RNN 12": {"mpjpe_mm": (31.2, 25.7), "pa_mpjpe_mm": (24.5, 18.0), "mpjae_deg": (12.3, 7.2)},
}

#: Evaluation subjects (``offsets`` of :func:`evaluate_models`): ``random`` = synthetic subjects
#: from the training prior (:func:`wearpose.sensors.em.random_subject_offsets`) drawn in the
#: ``"eval"`` seed namespace; ``unseen`` = subjects from a *wider* distribution never used for
#: training (:func:`unseen_subject_offsets`, ``"unseen"`` namespace), EM-POSE Table 4.
SUBJECT_MODES = ("random", "unseen")
#: Default spread factor of the ``unseen`` subjects.
UNSEEN_SPREAD = 2.0


def unseen_subject_offsets(num_sensors: int, generator: torch.Generator, spread: float = UNSEEN_SPREAD) -> Any:
    """A synthetic subject from outside the training distribution (EM-POSE Table 4 on our data).

    Every size parameter of the training prior :func:`~wearpose.sensors.em.random_subject_offsets`
    (tilt and spin of the rotation offset, skin standoff and its spread, tangential slide,
    per-sequence translation jitter) is multiplied by ``spread``: with 2, sensors sit twice as far
    off the skin and are twice as mis-rotated / displaced as any training subject is likely to be
    (e.g. straps over thick clothing). Returns an :class:`~wearpose.sensors.em.EMOffsets`.
    """

    from wearpose.sensors.em import random_subject_offsets  # start-up: sensors.em adds ~164 ms to import this module

    sizes = {k: float(p.default) * spread for k, p in inspect.signature(random_subject_offsets).parameters.items()
             if isinstance(p.default, float)}
    return random_subject_offsets(num_sensors, generator, **sizes)


def simulate_eval_clip(motion: Any, est: Any, clip_id: str, seed: int, *, noise: str = "default",
                       offsets: str = "random", spread: float = UNSEEN_SPREAD) -> dict[str, Any]:
    """The evaluation simulation of one clip (:func:`~wearpose.estimators.empose.data.simulate_clip`
    with the sensor noise seeded in the ``"eval"`` namespace, so ``random`` and ``unseen`` share the
    noise draw and differ only in the subject)."""
    from wearpose.estimators.empose.data import simulate_clip  # start-up: empose.data adds ~256 ms to import this module

    if offsets not in SUBJECT_MODES:
        raise ConfigError(f"evaluation offsets: expected one of {', '.join(SUBJECT_MODES)}, got {offsets!r}")
    sub: Any = "random"
    if offsets == "unseen":
        g = torch.Generator().manual_seed(clip_seed(clip_id, seed, "unseen"))
        sub = unseen_subject_offsets(len(est.sensor_names), g, spread)
    return simulate_clip(motion, est.config, est.body, clip_seed(clip_id, seed, "eval"), noise=noise, offsets=sub)


def miscalibrate(recording: Any, error_deg: float, error_mm: float, generator: torch.Generator) -> Any:
    """A copy of ``recording`` whose ``subject["offsets"]`` are off the simulated ones by what a
    calibration gets wrong: per sensor, the rotation offset composed with a rotation of
    ``error_deg`` degrees about a random axis, and the translation moved ``error_mm`` mm in a
    random direction (site frame). The measurements are untouched: the estimator is given
    offsets that do not quite match the sensors it reads, as with real sensors.

    Args:
        recording: a :class:`~wearpose.recording.Recording` with ``subject["offsets"]``
            (``rotation`` (S, 3, 3), ``translation_mean_m`` (S, 3)).
        error_deg, error_mm: sizes of the two errors (each sensor gets exactly these sizes).
        generator: the random axes and directions.
    """
    off = dict(recording.subject["offsets"])
    R = torch.as_tensor(np.asarray(off["rotation"], dtype=np.float64))
    t = torch.as_tensor(np.asarray(off["translation_mean_m"], dtype=np.float64))
    S = R.shape[0]
    unit = lambda: torch.nn.functional.normalize(torch.randn(S, 3, generator=generator, dtype=torch.float64), dim=-1)  # noqa: E731
    dR = axis_angle_to_matrix(unit() * math.radians(error_deg))
    off["rotation"] = (R @ dR).tolist()
    off["translation_mean_m"] = (t + unit() * (error_mm / 1000.0)).tolist()
    return dataclasses.replace(recording, subject={**recording.subject, "offsets": off})


def _stats(xs: list[torch.Tensor], k: float) -> tuple[float, float]:
    x = torch.cat(xs) * k if xs else torch.zeros(0)
    return (float(x.mean()), float(x.std())) if x.numel() else (math.nan, math.nan)


def _clip_row(cid: str, errs: Mapping[str, list[torch.Tensor]]) -> dict[str, Any]:
    """The last clip's row of ``errs`` (its per-frame errors just appended): ``{"clip", "frames",
    "mpjpe_mm", "pa_mpjpe_mm", "mpjae_deg"}`` (means over the clip's valid frames)."""
    pe = errs["pe"][-1]
    row: dict[str, Any] = {"clip": cid, "frames": int(pe.numel())}
    if pe.numel():
        row.update(mpjpe_mm=float(pe.mean()) * 1000.0, pa_mpjpe_mm=float(errs["pa"][-1].mean()) * 1000.0,
                   mpjae_deg=math.degrees(float(errs["ae"][-1].mean())))
    return row


def _shape_row(body: Any, betas_pred: torch.Tensor, betas_true: torch.Tensor) -> dict[str, float]:
    """One clip's shape figures (:func:`wearpose.evaluate.metrics.shape_errors`) in report units."""

    e = shape_errors(body, betas_pred.reshape(-1), betas_true.reshape(-1))
    return {"height_error_cm": float(e.height_error) * 100.0, "height_difference_cm": float(e.height_difference) * 100.0,
            "zero_pose_vertex_error_mm": float(e.zero_pose_vertex_error) * 1000.0,
            "wearer_height_cm": float(e.height_true) * 100.0}


def _shape_summary(rows: list[dict[str, Any]]) -> dict[str, float]:
    """Median and mean over clips of :func:`_shape_row`'s figures (none when no clip has them)."""
    out: dict[str, float] = {}
    for k in ("height_error_cm", "height_difference_cm", "zero_pose_vertex_error_mm"):
        x = torch.tensor([r[k] for r in rows if k in r], dtype=torch.float64)
        if x.numel():
            name, unit = k.rsplit("_", 1)
            out[f"{name}_median_{unit}"], out[f"{name}_mean_{unit}"] = float(x.median()), float(x.mean())
    return out


def _refined_summary(rows: list[dict[str, Any]]) -> dict[str, float]:
    """``{"refined_fraction"}``: the fraction of scored frames the refinement gate refined
    (frame-weighted over clips); none when the model has no refinement on."""
    have = [r for r in rows if "refined_fraction" in r]
    n = sum(r["frames"] for r in have)
    return {"refined_fraction": sum(r["refined_fraction"] * r["frames"] for r in have) / n} if n else {}


def _per_joint_summary(splits: list[JointErrorSplit]) -> dict[str, Any]:
    """``{"per_joint": {joint: {"mpjpe_mm", "rms_mm", "bias_mm", "varying_mm"}}, "bias_share"}``
    over the 15 major joints and every scored frame (:func:`wearpose.evaluate.metrics.joint_error_split`,
    pooled over clips); ``bias_share`` = the
    constant part's share of the mean squared error; none without a scored frame."""
    if not splits:
        return {}
    p = pool_joint_error_splits(splits)
    rows = {JOINT_NAMES[j]: {"mpjpe_mm": float(p.mean[j]) * 1000.0, "rms_mm": float(p.rms[j]) * 1000.0,
                             "bias_mm": float(p.bias[j]) * 1000.0, "varying_mm": float(p.varying[j]) * 1000.0}
            for j in MAJOR_JOINTS}
    major = list(MAJOR_JOINTS)
    share = float(p.bias[major].square().sum() / p.rms[major].square().sum().clamp_min(1e-30))
    return {"per_joint": rows, "bias_share": share}


def per_joint_markdown(result: Mapping[str, Any], digits: int = 1) -> list[str]:
    """Markdown lines: each model's error per major joint, split into the constant part per clip
    and the part that varies (:func:`_per_joint_summary`); none when no model has it."""
    models = {n: m for n, m in result["models"].items() if "per_joint" in m}
    if not models:
        return []
    lines = ["", "## Per joint", "",
             "Root-relative position error per major joint, mm: MPJPE / the part constant over a clip "
             "(its offset in the true pelvis frame, RMS over clips) / the part that varies "
             "(RMS; constant² + varying² = RMS²). "
             + "; ".join(f"{n}: {m['bias_share'] * 100:.0f} % of the squared error is constant"
                         for n, m in models.items()) + ".", "",
             "| joint | " + " | ".join(models) + " |", "| --- | " + " | ".join("---" for _ in models) + " |"]
    for j in next(iter(models.values()))["per_joint"]:
        cells = [f"{m['per_joint'][j]['mpjpe_mm']:.{digits}f} / {m['per_joint'][j]['bias_mm']:.{digits}f} / "
                 f"{m['per_joint'][j]['varying_mm']:.{digits}f}" for m in models.values()]
        lines.append(f"| {j} | " + " | ".join(cells) + " |")
    return lines


def _provenance(store: Any) -> dict[str, Any] | None:
    """Which store and corpus version the clips came from (:meth:`wearpose.motion.CorpusStore.provenance`;
    None for a stand-in store without it)."""
    fn = getattr(store, "provenance", None)
    return fn() if callable(fn) else None


def evaluate_models(checkpoints: Mapping[str, Any], split: str = "test", limit: int | None = None, *,
                    noise: str = "default", seed: int = 0, store: Any = None, progress: Any = None,
                    offsets: str = "random", spread: float = UNSEEN_SPREAD, clips: Sequence[str] | None = None,
                    bodies: str = "corpus", calibration_error: tuple[float, float] = (0.0, 0.0)) -> dict[str, Any]:
    """Evaluate several checkpoints on the same simulated recordings (module doc).

    Args:
        checkpoints: display name -> checkpoint path (any EM-POSE model, loaded with
            :func:`~wearpose.estimators.empose.baselines.load_any`) or a loaded estimator. All
            must share kit, rate and body asset.
        split: corpus split (``test`` for the held-out numbers).
        limit: first ``limit`` clips only.
        noise: EM error model of the simulation (``"default"`` / ``"none"``).
        seed: base seed of the evaluation subjects and noise.
        store: a :class:`~wearpose.motion.CorpusStore` (default: the prepared cache).
        progress: optional ``progress(done, total)``.
        offsets: evaluation subjects, :data:`SUBJECT_MODES` (``unseen``: EM-POSE Table 4, wider
            distribution scaled by ``spread``).
        clips: explicit clip ids of ``split`` (instead of the first ``limit``).
        bodies: the wearers, :data:`wearpose.estimators.bodies.BODIES` (module doc).
        calibration_error: ``(degrees, mm)``: the offsets the models are given are off the
            simulated ones by this much per sensor (:func:`miscalibrate`, seeded per clip in the
            ``"calibration"`` namespace); ``(0, 0)`` gives them the simulated offsets.

    Returns:
        ``{"split", "clips", "frames", "noise", "seed", "kit", "joints", "bodies", "betas" (clip
        id -> the held-out wearer's betas; ``{}`` for ``"corpus"``), "models": {name: {
        "mpjpe_mm", "mpjpe_std_mm", "pa_mpjpe_mm", "pa_mpjpe_std_mm", "mpjae_deg", "mpjae_std_deg",
        "height_error_median_cm", "height_error_mean_cm", "height_difference_median_cm", ...,
        "zero_pose_vertex_error_median_mm", ..., "frames", "method", "checkpoint", "epoch",
        "val_mpjpe_mm", "data_fingerprint", "train_command", "seconds", "per_clip": [{"clip",
        "frames", "mpjpe_mm", "pa_mpjpe_mm", "mpjae_deg", "height_error_cm",
        "height_difference_cm", "zero_pose_vertex_error_mm", "wearer_height_cm"}], "per_joint":
        {joint: {"mpjpe_mm", "rms_mm", "bias_mm", "varying_mm"}}, "bias_share"}}}`` (per joint: the
        error split into its constant part per clip and the rest, :func:`_per_joint_summary`); with EM-POSE's
        refinement on (``config.refine_steps > 0``) also ``"refined_fraction"`` (frames the gate
        refined) per model and per clip.
    """
    from wearpose.estimators.empose.baselines import load_any  # start-up: empose.baselines adds ~368 ms to import this module
    from wearpose.estimators.empose.data import recording_from_clip  # start-up: empose.data adds ~256 ms to import this module
    from wearpose.motion import CorpusStore  # start-up: motion adds ~231 ms to import this module

    if not checkpoints:
        raise ConfigError("evaluate_models: no checkpoints given")
    ests = {name: (c if not isinstance(c, (str, Path)) else load_any(c)) for name, c in checkpoints.items()}
    first = next(iter(ests.values()))
    for name, e in ests.items():
        if (e.kit_name, e.fps, e.body_asset_id) != (first.kit_name, first.fps, first.body_asset_id):
            raise ConfigError(f"evaluate_models: {name!r} is for kit {e.kit_name} at {e.fps} Hz on body "
                              f"{e.body_asset_id}, but the first model is for kit {first.kit_name} at {first.fps} Hz "
                              f"on body {first.body_asset_id}; one table needs one setting")
    store = wearer_store(store or CorpusStore(), bodies, first.body, seed)
    ids = list(clips) if clips is not None else store.clips(split=split)[: limit or None]
    errs: dict[str, dict[str, list[torch.Tensor]]] = {n: {"pe": [], "pa": [], "ae": []} for n in ests}
    secs = {n: 0.0 for n in ests}
    per_clip: dict[str, list[dict[str, Any]]] = {n: [] for n in ests}
    splits: dict[str, list[JointErrorSplit]] = {n: [] for n in ests}
    frames = 0
    for i, cid in enumerate(ids):
        # One simulation per clip for all models (same subject, same noise draw).
        r = simulate_eval_clip(store.load(cid), first, cid, seed, noise=noise, offsets=offsets, spread=spread)
        rec = recording_from_clip(r, first.config)
        if any(calibration_error):
            g = torch.Generator().manual_seed(clip_seed(cid, seed, "calibration"))
            rec = miscalibrate(rec, *calibration_error, g)
        for name, est in ests.items():
            t0 = time.perf_counter()
            track = est.estimate(rec)
            secs[name] += time.perf_counter() - t0
            with torch.no_grad():
                pj = est.body(track.local_rot, track.betas, None, return_vertices=False).joints
            ok = track.valid
            errs[name]["pe"].append(mpjpe(pj, r["joints"], MAJOR_JOINTS)[ok])
            errs[name]["pa"].append(pa_mpjpe(pj, r["joints"], MAJOR_JOINTS)[ok])
            errs[name]["ae"].append(mpjae(track.local_rot, r["pose"])[ok])
            if bool(ok.any()):
                splits[name].append(joint_error_split(pj[ok], r["joints"][ok], r["pose"][ok, 0]))
            row = _clip_row(cid, errs[name])
            if getattr(track, "betas", None) is not None:  # the family's shape estimate
                row.update(_shape_row(est.body, track.betas, r["betas"]))
            if "refined" in track.extras and bool(ok.any()):  # EM-POSE's measurement-consistency gate
                row["refined_fraction"] = float(track.extras["refined"][ok].float().mean())
            per_clip[name].append(row)
        frames += int(ok.sum())
        if progress is not None:
            progress(i + 1, len(ids))
    models: dict[str, Any] = {}
    for name, est in ests.items():
        (m1, s1), (m2, s2), (m3, s3) = (_stats(errs[name]["pe"], 1000.0), _stats(errs[name]["pa"], 1000.0),
                                        _stats(errs[name]["ae"], 180.0 / math.pi))
        src = checkpoints[name]
        models[name] = {"mpjpe_mm": m1, "mpjpe_std_mm": s1, "pa_mpjpe_mm": m2, "pa_mpjpe_std_mm": s2,
                        "mpjae_deg": m3, "mpjae_std_deg": s3, **_shape_summary(per_clip[name]),
                        **_refined_summary(per_clip[name]),
                        **_per_joint_summary(splits[name]),
                        "frames": sum(int(x.numel()) for x in errs[name]["pe"]),
                        "method": est.name, "checkpoint": str(src) if isinstance(src, (str, Path)) else None,
                        "epoch": est.meta.get("epoch"), "val_mpjpe_mm": est.meta.get("val_mpjpe_mm"),
                        "data_fingerprint": est.data_fingerprint, "train_command": est.train_command,
                        "config": est.config.to_dict(),
                        "parameters": sum(p.numel() for p in est.model.parameters()), "seconds": secs[name],
                        "per_clip": per_clip[name]}
    subjects = ("random synthetic offsets per clip, evaluation seed namespace (never drawn for training)"
                if offsets == "random" else
                f"unseen subjects: synthetic offsets from a {spread:g}x wider distribution than the training prior "
                f"(tilt, spin, standoff, slide and jitter scaled), own seed namespace")
    return {"split": split, "clips": len(ids), "frames": frames, "noise": noise, "seed": seed, "kit": first.kit_name,
            "rate_hz": first.fps, "body_asset": first.body_asset_id, "joints": "15 major (DIP/EM-POSE)",
            "offsets": offsets, "spread": spread if offsets == "unseen" else None, "subjects": subjects,
            "bodies": bodies, "betas": clip_bodies(store, ids), "store": _provenance(store),
            "calibration_error": {"deg": calibration_error[0], "mm": calibration_error[1]}, "models": models}


def table2_markdown(result: Mapping[str, Any], digits: int = 1) -> str:
    """Markdown table in the structure of EM-POSE Table 2: one row per model, ``mean ± std`` of
    MPJPE [mm], PA-MPJPE [mm], MPJAE [°], the best mean per column in bold; then the setting."""
    models = result["models"]
    cols = [("mpjpe_mm", "mpjpe_std_mm", "MPJPE [mm]"), ("pa_mpjpe_mm", "pa_mpjpe_std_mm", "PA-MPJPE [mm]"),
            ("mpjae_deg", "mpjae_std_deg", "MPJAE [°]")]

    n_s = {"em12": 12, "em6": 6}.get(result.get("kit", ""), "")
    best = {k: min((m[k] for m in models.values() if not math.isnan(m[k])), default=math.nan) for k, _, _ in cols}
    lines = ["| Model | " + " | ".join(c[2] for c in cols) + " |", "| --- | " + " | ".join("---" for _ in cols) + " |"]
    for name, m in models.items():
        cells = []
        for k, ks, _ in cols:
            s = f"{m[k]:.{digits}f} ± {m[ks]:.{digits}f}"
            cells.append(f"**{s}**" if m[k] == best[k] else s)
        lines.append(f"| {name} {n_s} | " + " | ".join(cells) + " |")
    lines.append("")
    lines.append(f"Split `{result['split']}` ({result['clips']} clips, {result['frames']} frames with all sensors "
                 f"valid), kit `{result['kit']}` at {result.get('rate_hz', 0):g} Hz, simulated EM noise "
                 f"`{result['noise']}`, {result.get('subjects', '')}, seed {result['seed']}; "
                 f"{result['joints']} joints; mean ± std over frames; {wearers(result.get('bodies', 'corpus'))}.")
    return "\n".join(lines)


def shape_markdown(result: Mapping[str, Any], digits: int = 1) -> list[str]:
    """Markdown lines: the shape estimate of each model (:func:`evaluate_models`' height and
    zero-pose vertex errors, median and mean over clips); none when no model has them."""
    models = {n: m for n, m in result["models"].items() if "height_error_median_cm" in m}
    if not models:
        return []
    lines = ["", "## Body shape estimate", "",
             "Per clip: the estimated body (one shape per sequence) against the wearer at zero pose; "
             "median (mean) over clips. Height difference: + = estimated taller.", "",
             "| Model | height error [cm] | height difference [cm] | zero-pose vertex error [mm] |",
             "| --- | --- | --- | --- |"]
    for name, m in models.items():
        cells = [f"{m[f'{k}_median_{u}']:.{digits}f} ({m[f'{k}_mean_{u}']:.{digits}f})"
                 for k, u in (("height_error", "cm"), ("height_difference", "cm"), ("zero_pose_vertex_error", "mm"))]
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    return lines


def write_table2(result: Mapping[str, Any], path_stem: str | Path, extra: Mapping[str, Any] | None = None) -> tuple[Path, Path]:
    """Write ``<stem>.md`` (title, table, per-model training details, the paper's numbers for
    context) and ``<stem>.json`` (``result`` plus ``extra`` and the machine)."""
    return write_table(result, path_stem, extra=extra)


def write_table(result: Mapping[str, Any], path_stem: str | Path, *, title: str = "EM-POSE Table 2 on simulated data (12 sensors)",
                produced_by: str = "benchmarks/empose_eval.py", paper: Mapping[str, Any] | None = PAPER_TABLE2_12,
                paper_caption: str = "the paper's Table 2", extra: Mapping[str, Any] | None = None,
                appendix: Sequence[str] = ()) -> tuple[Path, Path]:
    """:func:`write_table2` for any table of :func:`evaluate_models` results: ``title``, the command
    that ``produced_by`` it, the paper's rows ``paper`` (name -> metric -> (mean, std); None = none);
    ``appendix``: markdown lines after the models (the per-source and per-class breakdowns)."""
    stem = Path(path_stem)
    stem.parent.mkdir(parents=True, exist_ok=True)
    md = [f"# {title}", "",
          f"Produced by `{produced_by}` "
          "(`wearpose.estimators.empose.evaluate.evaluate_models`).", "", table2_markdown(result),
          *shape_markdown(result), *per_joint_markdown(result), "", "## Models", "", "| Model | method | checkpoint | epoch | val MPJPE [mm] | parameters | estimate time [s] |",
          "| --- | --- | --- | --- | --- | --- | --- |"]
    for name, m in result["models"].items():
        v = m.get("val_mpjpe_mm")
        md.append(f"| {name} | {m['method']} | `{m.get('checkpoint')}` | {m.get('epoch')} | "
                  f"{'' if v is None else f'{v:.2f}'} | {m.get('parameters')} | {m.get('seconds', 0):.1f} |")
    md += ["", "Training commands:", ""]
    for name, m in result["models"].items():
        md.append(f"- {name}: `{m.get('train_command') or '?'}`")
    if paper:
        md += ["", f"For context, {paper_caption} (*real* test set, GPU-trained full-size models; "
               "not comparable number for number):", "", "| Model | MPJPE [mm] | PA-MPJPE [mm] | MPJAE [°] |",
               "| --- | --- | --- | --- |"]
        suffix = " 12" if paper is PAPER_TABLE2_12 else ""
        for name, m in paper.items():
            md.append(f"| {name}{suffix} | " + " | ".join(f"{a} ± {b}" for a, b in m.values()) + " |")
    md += list(appendix)
    if extra and extra.get("note"):
        md += ["", str(extra["note"])]
    (stem.with_suffix(".md")).write_text("\n".join(md) + "\n", encoding="utf-8")
    blob = {**result, **(dict(extra) if extra else {}), "paper": dict(paper or {}),
            "machine": {"python": platform.python_version(), "torch": torch.__version__,
                        "processor": platform.processor() or platform.machine(), "threads": torch.get_num_threads()}}
    (stem.with_suffix(".json")).write_text(json.dumps(blob, indent=2, default=str) + "\n", encoding="utf-8")
    return stem.with_suffix(".md"), stem.with_suffix(".json")


# --------------------------------------------------------------------------- Table 10 (dropped sensors)
#: Drop events of :func:`drop_sensors`: span length and gap between spans, frames (30 Hz: 0.5-1.5 s
#: spans, 0.5-2 s gaps), and the number of sensors removed per span.
DROP_SPAN = (15, 45)
DROP_GAP = (15, 60)
DROP_COUNTS = (1, 2)


def drop_sensors(recording: Any, sensor_names: list[str], g: torch.Generator,
                 span: tuple[int, int] = DROP_SPAN) -> tuple[Any, torch.Tensor]:
    """A copy of ``recording`` with EM sensors removed over random spans (Table 10 protocol).

    Spans of ``span`` (default ``DROP_SPAN``) frames separated by ``DROP_GAP`` frames (uniform), each removing 1 or
    2 (``DROP_COUNTS``, equally likely) random sensors of ``sensor_names``: their samples become
    invalid (NaN), the way a recording marks dropped EM frames.

    Returns:
        the new recording and ``removed`` ``(T, S)`` bool (True = removed by this function).
    """


    streams = {s.name: s for s in recording.sensors}
    T = len(streams[sensor_names[0]].valid)
    S = len(sensor_names)
    removed = torch.zeros(T, S, dtype=torch.bool)
    t = int(torch.randint(0, min(DROP_GAP[1], T // 4) + 1, (), generator=g))  # first span starts early enough
    while t < T:
        L = int(torch.randint(span[0], span[1] + 1, (), generator=g))
        k = DROP_COUNTS[int(torch.randint(0, len(DROP_COUNTS), (), generator=g))]
        removed[t:t + L, torch.randperm(S, generator=g)[:k]] = True
        t += L + int(torch.randint(DROP_GAP[0], DROP_GAP[1] + 1, (), generator=g))
    new = []
    for s in recording.sensors:
        if s.name not in sensor_names:
            new.append(s)
            continue
        rm = removed[:, sensor_names.index(s.name)].numpy()
        valid = s.valid & ~rm
        pos, ori = s.position.copy(), s.orientation.copy()
        pos[~valid], ori[~valid] = np.nan, np.nan
        new.append(dataclasses.replace(s, valid=valid, position=pos, orientation=ori))
    return dataclasses.replace(recording, sensors=new), removed


def zero_dropped(recording: Any, sensor_names: list[str]) -> Any:
    """A copy of ``recording`` where every invalid sample of ``sensor_names`` is a *valid* zero
    measurement (position 0, i.e. at the source, and identity orientation; a Recording only holds
    proper rotations): what some EM SDKs deliver for a lost sensor, so an estimator cannot tell it
    is missing (EM-POSE supp. Fig. 12)."""


    new = []
    for s in recording.sensors:
        if s.name in sensor_names and not bool(np.all(s.valid)):
            bad = ~s.valid
            pos, ori = s.position.copy(), s.orientation.copy()
            pos[bad] = 0.0
            ori[bad] = np.eye(3, dtype=ori.dtype) if ori.shape[-2:] == (3, 3) else np.array([1, 0, 0, 0], ori.dtype)
            s = dataclasses.replace(s, valid=np.ones_like(s.valid), position=pos, orientation=ori)
        new.append(s)
    return dataclasses.replace(recording, sensors=new)


def evaluate_dropped(checkpoints: Mapping[str, Any], split: str = "test", limit: int | None = None, *,
                     noise: str = "default", seed: int = 0, store: Any = None, progress: Any = None,
                     span: tuple[int, int] = DROP_SPAN, zeros: Sequence[str] = ()) -> dict[str, Any]:
    """EM-POSE Table 10 on our data: models on recordings with dropped sensors.

    Each clip is simulated as in :func:`evaluate_models` (same subjects and noise), then
    :func:`drop_sensors` removes 1-2 sensors over random spans of ``span`` frames (generator seeded per clip in the
    ``"table10"`` namespace). Every model estimates the whole recording and *every* frame is scored
    (a model's own ``valid`` flag is ignored: the LGD-RNN holds a dropped sensor at its last value,
    the two-stage model fills it in). Frame sets: ``all``; ``avail`` (every sensor valid);
    ``miss`` (at least one sensor missing), and ``miss1`` / ``miss2`` (exactly one / two missing).
    Models named in ``zeros`` get every missing sample as a valid all-zero measurement instead
    (:func:`zero_dropped`; the frame sets stay those of the dropped recording).

    Returns:
        ``{"split", "clips", "frame_counts": {set: n}, "models": {name: {set: {"mpjpe_mm", ...}}},
        ...}`` (mean and std per set, mm / degrees, 15 major joints).
    """
    from wearpose.estimators.empose.baselines import load_any  # start-up: empose.baselines adds ~368 ms to import this module
    from wearpose.estimators.empose.data import recording_from_clip, simulate_clip  # start-up: empose.data adds ~256 ms to import this module
    from wearpose.motion import CorpusStore  # start-up: motion adds ~231 ms to import this module

    if not checkpoints:
        raise ConfigError("evaluate_dropped: no checkpoints given")
    ests = {name: (c if not isinstance(c, (str, Path)) else load_any(c)) for name, c in checkpoints.items()}
    first = next(iter(ests.values()))
    for name, e in ests.items():
        if (e.kit_name, e.fps, e.body_asset_id) != (first.kit_name, first.fps, first.body_asset_id):
            raise ConfigError(f"evaluate_dropped: {name!r} is for kit {e.kit_name} at {e.fps} Hz, the first model for "
                              f"kit {first.kit_name} at {first.fps} Hz; one table needs one setting")
    unknown = sorted(set(zeros) - set(ests))
    if unknown:
        raise ConfigError(f"evaluate_dropped: zeros names {unknown}, which are not among the models {sorted(ests)}")
    store = store or CorpusStore()
    ids = store.clips(split=split)[: limit or None]
    names = list(first.sensor_names)
    errs: dict[str, dict[str, list[torch.Tensor]]] = {n: {"pe": [], "pa": [], "ae": []} for n in ests}
    nmiss: list[torch.Tensor] = []
    secs = {n: 0.0 for n in ests}
    for i, cid in enumerate(ids):
        r = simulate_clip(store.load(cid), first.config, first.body, clip_seed(cid, seed, "eval"), noise=noise,
                          offsets="random")
        g = torch.Generator().manual_seed(clip_seed(cid, seed, "table10"))
        rec, _ = drop_sensors(recording_from_clip(r, first.config), names, g, span)
        grid = rec.on_common_grid(names)
        nmiss.append((~torch.as_tensor(grid.valid)).sum(1))
        rec0 = zero_dropped(rec, names) if zeros else None
        for name, est in ests.items():
            t0 = time.perf_counter()
            track = est.estimate(rec0 if name in zeros else rec)
            secs[name] += time.perf_counter() - t0
            with torch.no_grad():
                pj = est.body(track.local_rot, track.betas, None, return_vertices=False).joints
            errs[name]["pe"].append(mpjpe(pj, r["joints"], MAJOR_JOINTS))
            errs[name]["pa"].append(pa_mpjpe(pj, r["joints"], MAJOR_JOINTS))
            errs[name]["ae"].append(mpjae(track.local_rot, r["pose"]))
        if progress is not None:
            progress(i + 1, len(ids))
    miss = torch.cat(nmiss) if nmiss else torch.zeros(0, dtype=torch.long)
    sets = {"all": torch.ones_like(miss, dtype=torch.bool), "avail": miss == 0, "miss": miss > 0,
            "miss1": miss == 1, "miss2": miss == 2}
    models: dict[str, Any] = {}
    for name, est in ests.items():
        pe, pa, ae = (torch.cat(errs[name][k]) for k in ("pe", "pa", "ae"))
        rows = {}
        for sname, m in sets.items():
            (m1, s1), (m2, s2), (m3, s3) = _stats([pe[m]], 1000.0), _stats([pa[m]], 1000.0), _stats([ae[m]], 180.0 / math.pi)
            rows[sname] = {"mpjpe_mm": m1, "mpjpe_std_mm": s1, "pa_mpjpe_mm": m2, "pa_mpjpe_std_mm": s2,
                           "mpjae_deg": m3, "mpjae_std_deg": s3}
        src = checkpoints[name]
        models[name] = {"sets": rows, "method": est.name, "checkpoint": str(src) if isinstance(src, (str, Path)) else None,
                        "epoch": est.meta.get("epoch"), "val_mpjpe_mm": est.meta.get("val_mpjpe_mm"),
                        "train_command": est.train_command, "config": est.config.to_dict(),
                        "parameters": sum(p.numel() for p in est.model.parameters()), "seconds": secs[name],
                        "dropped_input": "zeros" if name in zeros else "missing"}
    return {"split": split, "clips": len(ids), "noise": noise, "seed": seed, "kit": first.kit_name, "rate_hz": first.fps,
            "store": _provenance(store),
            "body_asset": first.body_asset_id, "joints": "15 major (DIP/EM-POSE)",
            "frame_counts": {k: int(v.sum()) for k, v in sets.items()},
            "drops": {"span_frames": tuple(span), "gap_frames": DROP_GAP, "sensors_per_span": DROP_COUNTS},
            "subjects": "random synthetic offsets per clip, evaluation seed namespace (never drawn for training)",
            "models": models}


#: Paper's Table 10 (12 sensors, real test set): set -> model -> MPJPE, PA-MPJPE, MPJAE (mean, std).
PAPER_TABLE10_12 = {
    "all": {"LGD-RNN": ((33.3, 24.3), (26.2, 18.8), (13.4, 9.2)), "2-stage": ((38.8, 22.0), (28.2, 17.3), (13.8, 9.1))},
    "avail": {"LGD-RNN": ((31.8, 21.0), (24.8, 16.4), (13.3, 9.2)), "2-stage": ((39.1, 21.3), (28.1, 16.7), (13.7, 9.1))},
    "miss": {"LGD-RNN": ((45.6, 40.6), (37.7, 30.0), (15.0, 9.3)), "2-stage": ((36.2, 27.0), (29.1, 21.9), (14.6, 9.1))},
}


def table10_markdown(result: Mapping[str, Any], digits: int = 1) -> str:
    """Markdown in the structure of EM-POSE Table 10: rows (frame set, model), best mean per set in
    bold among the models that got the dropped samples as missing (a ``zeros`` row, a secondary
    scenario, is shown in italics and never bold)."""
    cols = [("mpjpe_mm", "mpjpe_std_mm"), ("pa_mpjpe_mm", "pa_mpjpe_std_mm"), ("mpjae_deg", "mpjae_std_deg")]
    lines = ["| Frames | Model | frames | MPJPE [mm] | PA-MPJPE [mm] | MPJAE [°] |", "| --- | --- | --- | --- | --- | --- |"]
    counts = result["frame_counts"]
    for sname in ("all", "avail", "miss", "miss1", "miss2"):
        rows = {n: m["sets"][sname] for n, m in result["models"].items()}
        main = [n for n, m in result["models"].items() if m.get("dropped_input", "missing") != "zeros"]
        best = {k: min((rows[n][k] for n in main if not math.isnan(rows[n][k])), default=math.nan) for k, _ in cols}
        for n, r in rows.items():
            cells = []
            for k, ks in cols:
                s = f"{r[k]:.{digits}f} ± {r[ks]:.{digits}f}"
                if n not in main:
                    s = f"*{s}*"
                cells.append(f"**{s}**" if n in main and r[k] == best[k] and len(main) > 1 else s)
            lines.append(f"| {sname} | {n} | {counts[sname]} | " + " | ".join(cells) + " |")
    return "\n".join(lines)
