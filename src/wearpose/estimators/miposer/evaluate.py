"""MI-Poser evaluation on simulated recordings of held-out corpus clips (Fig. 5 structure).

:func:`evaluate_miposer`: per test clip, the kit is simulated at its own rates (headset 60 Hz,
wrist EM 120 Hz, default noise, a held-out random subject's EM sensor offsets, seeds in an
``eval`` namespace never used for training) after a 1 s T-pose (:func:`~.data.tpose_then`); the
T-pose window is calibrated (:func:`wearpose.calibration.calibrate`, ``miposer-tpose``) and the
estimator runs with the calibration ("with sensor-position calibration") and with only its world
alignment ("without", :func:`~.data.uncalibrated`). Errors: root(pelvis)-aligned joint position
error of the upper-body joints (:data:`~.config.UPPER_BODY`, as MI-Poser aligns the hip) per
joint and per motion type (:func:`wearpose.motion.store.motion_class`: the corpus description
without its style, e.g. ``wave-left-hand``; a procedural clip's family),
on clip frames only (not the T-pose) where every input sensor is valid, in cm. Ground truth and
estimate are posed on the same body, the wearer's (the corpus clips' mean shape, or the
held-out wearer of ``wearpose evaluate --bodies heldout``: MI-Poser calibrates the wearer in
the T-pose and has no shape of its own); the ground-truth root orientation is expressed
in the calibrated world (the calibration's alignment of the simulated VIO world).

``frame_stride`` evaluates every k-th clip frame: each estimate depends only on its own 40-frame
window, so a subset gives exactly the values of a full run at those frames (CPU time).

:func:`evaluate_imuposer`: the IMU-only baseline on the same clips and frames (its own simulated
IMUs, no T-pose needed: segment-calibrated orientations).
"""

from __future__ import annotations

import dataclasses
import math
import time
import warnings

import numpy as np
from typing import Any, Callable, Sequence

import torch

from wearpose.body.skeleton import JOINT_NAMES
from wearpose.calibration import calibrate
from wearpose.estimators.seeding import clip_seed
from wearpose.estimators.miposer.config import UPPER_BODY
from wearpose.estimators.miposer.mim import make_mim, mitigate_recording
from wearpose.evaluate.metrics import joint_position_errors
from wearpose.interference import simulate_condition
from wearpose.interference.study import SOURCE_DOWN, SOURCE_FORWARD
from wearpose.motion import CorpusStore, resample
from wearpose.motion.store import motion_class
from wearpose.sensors import get_kit, simulate

#: Metres -> report centimetres (MI-Poser reports cm).
CM = 100.0


def joint_errors(body: Any, pred_rot: torch.Tensor, gt_rot: torch.Tensor, betas: torch.Tensor | None = None
                 ) -> torch.Tensor:
    """Root-aligned joint position errors ``(N, 24)`` m of two local-rotation tracks ``(N, 24, 3, 3)``
    posed on ``body`` with the wearer's shape ``betas`` ``(10,)`` (None: the mean shape; the
    corpus clips' own body is the mean shape, so this is the same)."""
    with torch.no_grad():
        a = body(pred_rot, betas, None, return_vertices=False).joints
        b = body(gt_rot.to(pred_rot.dtype), betas, None, return_vertices=False).joints
    return joint_position_errors(a, b)


class ErrorTable:
    """Accumulates per-frame upper-body joint errors by motion type (and clip, when given);
    :meth:`summary` in cm."""

    def __init__(self) -> None:
        self.rows: list[tuple[str, torch.Tensor]] = []
        self.clips: list[str | None] = []

    def add(self, mtype: str, err: torch.Tensor, clip: str | None = None) -> None:
        """``err`` ``(N, 24)`` m, the joint errors of ``N`` frames of one clip of type ``mtype``."""
        self.rows.append((mtype, err[:, list(UPPER_BODY)].float()))
        self.clips.append(clip)

    def per_clip(self, key: str = "mpjpe_upper_cm") -> list[dict[str, Any]]:
        """``[{"clip", "frames", key}]`` of the rows added with a clip id, in order (``key``: the
        clip's upper-body MPJPE, cm)."""
        return [{"clip": c, "frames": int(e.shape[0]), **({key: float(e.mean()) * CM} if e.shape[0] else {})}
                for c, (_, e) in zip(self.clips, self.rows) if c is not None]

    def summary(self) -> dict[str, Any]:
        if not self.rows:
            return {"frames": 0}
        allE = torch.cat([e for _, e in self.rows])
        types = sorted({t for t, _ in self.rows})
        by_type = {t: torch.cat([e for tt, e in self.rows if tt == t]) for t in types}
        return {
            "frames": int(allE.shape[0]),
            "mpjpe_upper_cm": float(allE.mean()) * CM,
            "mpjpe_upper_std_cm": float(allE.mean(1).std()) * CM if allE.shape[0] > 1 else 0.0,
            "per_joint_cm": {JOINT_NAMES[j]: float(allE[:, i].mean()) * CM for i, j in enumerate(UPPER_BODY)},
            "per_motion_cm": {t: float(e.mean()) * CM for t, e in by_type.items()},
            "per_motion_frames": {t: int(e.shape[0]) for t, e in by_type.items()},
            "per_motion_joint_cm": {t: {JOINT_NAMES[j]: float(e[:, i].mean()) * CM for i, j in enumerate(UPPER_BODY)}
                                    for t, e in by_type.items()},
        }


def _frames(valid: torch.Tensor, prefix: int, stride: int) -> torch.Tensor:
    idx = torch.arange(prefix, valid.shape[0], max(1, stride))
    return idx[valid[idx]]


def evaluate_miposer(estimators: dict[str, Any], split: str = "test", limit: int | None = None, *, seed: int = 0,
                     noise: str = "default", frame_stride: int = 1, store: Any = None,
                     conditions: Sequence[str] = ("calibrated", "uncalibrated"),
                     progress: Callable[[int, int], None] | None = None) -> dict[str, Any]:
    """Upper-body errors of MI-Poser estimators (module doc).

    Args:
        estimators: name -> :class:`~.estimator.MiposerEstimator` (e.g. the two-wrist model and the
            smartwatch variant); each is evaluated on recordings of its own kit.
        split, limit: clips (sorted ids of ``split``, first ``limit``).
        seed: evaluation seed. noise: simulated sensor noise. frame_stride: every k-th clip frame.
        conditions: ``"calibrated"`` and/or ``"uncalibrated"``.

    Returns:
        ``{"split", "clips", "seed", "noise", "frame_stride", "models": {name: {condition: summary}},
        "per_clip": {name: [{"clip", "frames", "<condition>_mpjpe_upper_cm"}]}}`` (summaries from
        :meth:`ErrorTable.summary`, cm) and timing.
    """
    # start-up: wearpose.estimators.miposer.data adds ~50 ms to importing this module
    from wearpose.estimators.miposer.data import calibrated_inputs, raw_inputs, simulate_clip, uncalibrated

    store = store or CorpusStore()
    ids = store.clips(split=split)[: limit or None]
    tables = {n: {c: ErrorTable() for c in conditions} for n in estimators}
    t0 = time.time()
    for k, cid in enumerate(ids):
        motion = store.load(cid)
        mtype = motion_class(store.entry(cid))
        for name, est in estimators.items():
            r = simulate_clip(motion, est.config, est.body, clip_seed(cid, seed, "eval"), noise=noise, native_rates=True)
            raw = raw_inputs(r["recording"], est.kit_name, est.fps)
            f = _frames(raw["valid"].all(1), r["prefix"], frame_stride)
            for cond in conditions:
                res = r["calibration"] if cond == "calibrated" else uncalibrated(r["calibration"])
                R, p = calibrated_inputs(raw, res)
                rot, _ = est.infer(R, p, f)
                tables[name][cond].add(mtype, joint_errors(est.body, rot, r["pose"][f], r["betas"]), cid)
        if progress is not None:
            progress(k + 1, len(ids))
    return {"split": split, "clips": len(ids), "seed": seed, "noise": noise, "frame_stride": frame_stride,
            "joints": [JOINT_NAMES[j] for j in UPPER_BODY], "root_aligned": "pelvis position",
            "models": {n: {c: t.summary() for c, t in d.items()} for n, d in tables.items()},
            "per_clip": {n: _merge_clips({c: t.per_clip(f"{c}_mpjpe_upper_cm") for c, t in d.items()})
                         for n, d in tables.items()},
            "seconds": time.time() - t0}


def _merge_clips(by_condition: dict[str, list[dict[str, Any]]]) -> list[dict[str, Any]]:
    """One row per clip from each condition's :meth:`ErrorTable.per_clip` rows (same clips,
    same frames, in the same order)."""
    rows = [dict(r) for r in next(iter(by_condition.values()), [])]
    for part in by_condition.values():
        for row, r in zip(rows, part):
            row.update(r)
    return rows


def evaluate_imuposer(est: Any, split: str = "test", limit: int | None = None, *, seed: int = 0, noise: str = "default",
                      frame_stride: int = 1, store: Any = None, progress: Callable[[int, int], None] | None = None
                      ) -> dict[str, Any]:
    """The IMU-only baseline's upper-body errors on the same clips (module doc); the BiLSTM runs
    over the whole clip (offline), frames are then subsampled as in :func:`evaluate_miposer`."""
    # start-up: wearpose.estimators.miposer.baselines adds ~70 ms to importing this module
    from wearpose.estimators.miposer.baselines import simulate_imu_clip

    store = store or CorpusStore()
    ids = store.clips(split=split)[: limit or None]
    table = ErrorTable()
    t0 = time.time()
    for k, cid in enumerate(ids):
        r = simulate_imu_clip(store.load(cid), est.config, est.body, clip_seed(cid, seed, "eval-imu"), noise=noise)
        rot = est.infer(r["R"], r["a"])
        f = _frames(r["valid"].all(1), 0, frame_stride)
        table.add(motion_class(store.entry(cid)), joint_errors(est.body, rot[f], r["pose"][f], r["motion"].betas),
                  cid)
        if progress is not None:
            progress(k + 1, len(ids))
    return {"split": split, "clips": len(ids), "seed": seed, "noise": noise, "frame_stride": frame_stride,
            "summary": table.summary(), "per_clip": table.per_clip(), "seconds": time.time() - t0}


def _to_head(rec: Any, kit: str, em_name: str, R_src: np.ndarray, p_src: np.ndarray,
             source_pose: tuple[np.ndarray, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """EM poses measured against a room-fixed source -> relative to the headset (the kit's EM
    convention), through the recording's headset VIO pose (held to the EM instants): composing
    them back with the headset (as :func:`~.data.raw_inputs` does) gives the room-fixed
    measurement in the headset's world (MI-Poser App. A)."""
    # start-up: wearpose.estimators.miposer.data adds ~50 ms to importing this module
    from wearpose.estimators.miposer.data import input_spec

    vio = input_spec(kit).sensor_names[0]
    h, s = rec.sensor(vio), rec.sensor(em_name)
    n = min(len(R_src), s.num_frames)
    i = np.clip(np.searchsorted(np.asarray(h.timestamps), np.asarray(s.timestamps[:n]) + 1e-6) - 1, 0, h.num_frames - 1)
    hR = np.asarray(h.orientation, dtype=np.float64)[i]
    hp = np.asarray(h.position, dtype=np.float64)[i]
    SR, Sp = (np.asarray(x, dtype=np.float64) for x in source_pose)
    Rw = np.einsum("ij,tjk->tik", SR, R_src[:n])
    pw = p_src[:n] @ SR.T + Sp
    return np.einsum("tji,tjk->tik", hR, Rw), np.einsum("tji,tj->ti", hR, pw - hp)


def world_source_pose(motion: Any, body: Any, forward: float = SOURCE_FORWARD,
                      down: float = SOURCE_DOWN) -> tuple[np.ndarray, np.ndarray]:
    """The room-fixed source of :mod:`wearpose.interference.study` (MI-Poser User Study 2): ``forward``
    m in front of the first-frame head (its horizontal facing), ``down`` m lower, world-aligned."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        so = body.sites(motion.pose[:1], motion.betas, motion.trans[:1], ["head"])
    hR, hp = so.rotations[0, 0].double().numpy(), so.positions[0, 0].double().numpy()
    f = hR[:, 2].copy()
    f[1] = 0.0
    f /= max(np.linalg.norm(f), 1e-9)
    return np.eye(3), hp + forward * f - np.array([0.0, down, 0.0])


def interference_recording(motion: Any, est: Any, cs: Any, which: str, seed: int,
                           override: dict[str, tuple[np.ndarray, np.ndarray]] | None = None,
                           source_pose: tuple[np.ndarray, np.ndarray] | None = None) -> Any:
    """A MI-Poser recording of ``motion`` (T-pose prefix included) whose wrist EM streams are the
    interference simulation ``cs`` (:func:`wearpose.interference.simulate_condition`, sensors on
    the wrist sites, head-worn source): ``which="measured"`` (interfered) or ``"true"``. The
    headset stream is simulated with the default VIO noise; EM sensors sit on the sites
    (identity offsets, as the interference simulator models them)."""
    # start-up: wearpose.recording adds ~40 ms to importing this module
    from wearpose.recording import Recording

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sim = simulate(motion, est.kit_name, est.body, seed=seed, noise="default", offsets=None)
    rec = Recording.from_simulation(sim, motion)
    for spec in get_kit(est.kit_name).of_kind("em6dof"):
        s, c = rec.sensor(spec.name), cs[spec.site]
        n = min(s.num_frames, c.num_frames)
        R, p = (c.R, c.p) if which == "measured" else (c.R_true, c.p_true)
        if override and spec.site in override:
            R, p = override[spec.site]
        if source_pose is not None:
            R, p = _to_head(rec, est.kit_name, spec.name, np.asarray(R, np.float64), np.asarray(p, np.float64), source_pose)
            n = min(n, len(R))
        s.orientation = np.asarray(R[:n], dtype=np.float32)
        s.position = np.asarray(p[:n], dtype=np.float32)
        s.valid = np.asarray(c.valid[:n], dtype=bool).copy()
        s.timestamps = s.timestamps[:n]
    return rec


def evaluate_end_to_end(est: Any, split: str = "test", limit: int | None = None, *, clip_stride: int = 1,
                        condition: str = "standard", seed: int = 0, frame_stride: int = 1, mim_config: Any = None,
                        store: Any = None, progress: Callable[[int, int], None] | None = None,
                        references: bool = True, mim_variants: dict[str, Any] | None = None,
                        source: str = "head", max_range: float = 1.5) -> dict[str, Any]:
    """End-to-end upper-body error under simulated metal interference, with and without MIM.

    Per clip (every ``clip_stride``-th of ``split``): the T-pose + clip motion at 60 Hz, the wrist
    EM sensors simulated among metal (:func:`wearpose.interference.simulate_condition`,
    ``condition``), the headset simulated as usual; four runs of the same estimator: interference-
    free EM ("true"), interference-free EM with MIM (its false alarms), interfered EM without MIM,
    interfered EM with MIM (the wrists' IMU streams of the simulation as MIM's input). Each run
    calibrates on its own T-pose (the first second of every scene is metal-free). Errors as
    :func:`evaluate_miposer` (cm, upper body, root-aligned, clip frames), over all evaluated
    frames and over the frames where a wrist's *true* EM error exceeds 2 cm or 5 deg
    ("interfered frames"). ``references=False`` skips the two interference-free runs;
    ``mim_variants`` (name -> ``MIMConfig``, default ``{"MIM": mim_config}``) adds one interfered
    run per MIM setting (``"<condition>+<name>"``); the interference-free reference with MIM and
    the detection counts use the first.

    ``source="world"``: the wrists are tracked against a room-fixed source (MI-Poser User Study 2,
    :func:`world_source_pose`), MIM runs on those streams at 120 Hz, and the (corrected) poses
    reach the estimator through the headset's VIO pose (:func:`_to_head`); clips whose wrists
    leave ``max_range`` m of the source are skipped.
    """
    # start-up: wearpose.estimators.miposer.data adds ~50 ms to importing this module
    from wearpose.estimators.miposer.data import calibrated_inputs, raw_inputs
    # start-up: wearpose.recording.tpose adds ~45 ms to importing this module
    from wearpose.recording.tpose import tpose_then

    store = store or CorpusStore()
    ids = store.clips(split=split)[:: max(1, clip_stride)][: limit or None]
    variants = dict(mim_variants or {"MIM": mim_config})
    first = next(iter(variants))
    runs = {"true": ("true", None), f"true+{first}": ("true", first)} if references else {}
    runs[condition] = ("measured", None)
    runs.update({f"{condition}+{v}": ("measured", v) for v in variants})
    tables = {k: ErrorTable() for k in runs}
    hit = {k: ErrorTable() for k in runs}
    sites = [s.site for s in get_kit(est.kit_name).of_kind("em6dof")]
    names = [s.name for s in get_kit(est.kit_name).of_kind("em6dof")]
    det = {"frames": 0, "interfered_true": 0, "detected": 0, "detected_and_true": 0}
    fallback = None
    mim_was = est.mim
    skipped = 0
    t0 = time.time()
    try:
        for k, cid in enumerate(ids):
            m = resample(store.load(cid), est.fps)
            mm, prefix = tpose_then(m, est.config.tpose_s, est.config.blend_s)
            s = clip_seed(cid, seed, "e2e")
            sp = None
            if source == "world":
                sp = world_source_pose(mm, est.body)
                cs = simulate_condition(mm, condition, sensors=sites, seed=s, body=est.body, source="world", source_pose=sp)
                if max(float(np.linalg.norm(cs[site].p_true, axis=1).max()) for site in sites) > max_range:
                    skipped += 1
                    continue
            else:
                cs = simulate_condition(mm, condition, sensors=sites, seed=s, body=est.body)
            imu = {n: (cs[site].gyro, cs[site].acc) for n, site in zip(names, sites)}
            bad120 = np.zeros(cs[sites[0]].num_frames, bool)
            for site in sites:
                bad120 |= (cs[site].pos_error > 0.02) | (cs[site].rot_error > math.radians(5.0))
            hold = int(round(est.config.tpose_s * est.fps))
            window = (min(0.1, 0.25 * est.config.tpose_s), max(hold - 1, 1) / est.fps)
            mtype = motion_class(store.entry(cid))
            for run, (which, use_mim) in runs.items():
                info = None
                if sp is not None:
                    over = None
                    if use_mim is not None:
                        over, info = {}, {}
                        for n, site in zip(names, sites):
                            c = cs[site]
                            R0, p0 = (c.R, c.p) if which == "measured" else (c.R_true, c.p_true)
                            o = make_mim(variants[use_mim]).process(R0, p0, c.gyro, c.acc, c.fps)
                            over[site] = (o["R"], o["p"])
                            info[n] = o
                    rec = interference_recording(mm, est, cs, which, s, override=over, source_pose=sp)
                else:
                    rec = interference_recording(mm, est, cs, which, s)
                if use_mim is not None and sp is None:
                    rec, info = mitigate_recording(rec, est.kit_name, variants[use_mim], imu)
                    fallback = info.get("fallback", fallback)
                res = calibrate(rec, "miposer-tpose", window=window, body=est.body)
                raw = raw_inputs(rec, est.kit_name, est.fps)
                f = _frames(raw["valid"].all(1), prefix, frame_stride)
                R, p = calibrated_inputs(raw, res)
                rot, _ = est.infer(R, p, f)
                gt = mm.pose.float().clone()
                gt[:, 0] = res.world_rotation[0].float() @ gt[:, 0]
                err = joint_errors(est.body, rot, gt[f])
                tables[run].add(mtype, err)
                b60 = torch.as_tensor(bad120[: 2 * raw["valid"].shape[0]:2][: raw["valid"].shape[0]])
                sel = b60[f] if len(b60) == raw["valid"].shape[0] else torch.zeros(len(f), dtype=torch.bool)
                if bool(sel.any()):
                    hit[run].add(mtype, err[sel])
                if run == f"{condition}+{first}" and info is not None:
                    flag = np.zeros_like(bad120)
                    for n in names:
                        flag[: len(info[n]["interfered"])] |= info[n]["interfered"][: len(flag)]
                    det["frames"] += int(len(flag))
                    det["interfered_true"] += int(bad120.sum())
                    det["detected"] += int(flag.sum())
                    det["detected_and_true"] += int((flag & bad120).sum())
            if progress is not None:
                progress(k + 1, len(ids))
    finally:
        est.mim = mim_was
    return {"split": split, "clips": len(ids) - skipped, "skipped_out_of_range": skipped, "source": source,
            "clip_stride": clip_stride, "condition": condition, "seed": seed,
            "frame_stride": frame_stride, "mim_position_fallback": fallback,
            "mim_variants": {k: (dataclasses.asdict(v) if dataclasses.is_dataclass(v) else v) for k, v in variants.items()},
            "runs": {r: {"all": tables[r].summary(), "interfered_frames": hit[r].summary()} for r in runs},
            "detection_any_wrist": det, "seconds": time.time() - t0}


def format_fig5(result: dict[str, Any], baseline: dict[str, Any] | None = None) -> str:
    """Markdown tables (per joint, per motion type; cm) of :func:`evaluate_miposer` output."""
    lines: list[str] = []
    cols: list[tuple[str, dict[str, Any]]] = []
    for name, conds in result["models"].items():
        for cond, s in conds.items():
            cols.append((f"{name} ({cond})", s))
    if baseline is not None:
        cols.append(("IMU-only BiLSTM (imuposer)", baseline["summary"]))
    head = "| | " + " | ".join(c for c, _ in cols) + " |"
    sep = "|---|" + "---:|" * len(cols)
    fmt = lambda v: "-" if v is None or (isinstance(v, float) and math.isnan(v)) else f"{v:.2f}"  # noqa: E731
    lines += ["**Overall upper-body MPJPE (cm, root-aligned)**", "", head, sep,
              "| all frames | " + " | ".join(fmt(s.get("mpjpe_upper_cm")) for _, s in cols) + " |",
              "| frames | " + " | ".join(str(s.get("frames", 0)) for _, s in cols) + " |", ""]
    lines += ["**Per joint (cm)**", "", head, sep]
    for j in result["joints"]:
        lines.append(f"| {j} | " + " | ".join(fmt(s.get("per_joint_cm", {}).get(j)) for _, s in cols) + " |")
    types = sorted({t for _, s in cols for t in s.get("per_motion_cm", {})})
    lines += ["", "**Per motion type (cm)**", "", head, sep]
    for t in types:
        lines.append(f"| {t} | " + " | ".join(fmt(s.get("per_motion_cm", {}).get(t)) for _, s in cols) + " |")
    return "\n".join(lines) + "\n"
