"""MI-Poser's interference study on simulated sessions: the computations behind
``benchmarks/interference.py`` (error statistics per condition, Table 1; detection, Table 3 and
the Fig. 8 sweep; correction per position method, Figs. 9-10), as library functions.

Sessions (:func:`world_sessions`, MI-Poser User Study 2): clips of a corpus split in a seeded
random order, each with a room-fixed source in front of the subject (:data:`SOURCE_FORWARD`,
:data:`SOURCE_DOWN`), kept when the wrist stays within :data:`MAX_RANGE` of it, grouped until
at least ``seconds`` long; one wrist per session (left and right built in parallel).
:func:`head_sessions`: consecutive clips with the source on the head (MI-Poser's deployment).
:func:`simulate_sessions` simulates each clip separately (:func:`simulate_condition`, the
tracker restarts per clip) at 120 Hz and caches the streams of a split and condition in one
``.npz``; :func:`load_sessions` reads it back as per-clip dicts.

A per-clip dict holds ``R_true``, ``R`` ``(T, 3, 3)`` (sensor orientation in the source frame,
true and tracked), ``p_true``, ``p`` ``(T, 3)`` m, ``gyro`` ``(T, 3)`` rad/s (sensor frame),
``acc`` ``(T, 3)`` m/s^2, ``carried`` ``(T,)`` bool, ``pos_error`` ``(T,)`` m,
``rot_error`` ``(T,)`` rad, and ``session``, ``clip``, ``site``.

Detection thresholds are chosen on the val split and applied on test (the paper searched them
on its evaluation data; that "oracle" figure is reported beside): :func:`evaluate_condition`.
"""

from __future__ import annotations

import time
import zlib
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping

import numpy as np
import torch

from wearpose.body import BodyModel
from wearpose.interference.metrics import binary_metrics
from wearpose.interference.mim import MIM, MIMConfig, detect
from wearpose.interference.simulate import rotation_error, simulate_condition
from wearpose.interference.trajectories import EM_RATE, SiteTrajectories, body_trajectories
from wearpose.motion import CorpusStore

#: Ground-truth thresholds e_P (cm) of the Fig. 8 sweep.
E_P_SWEEP_CM = (0.5, 1.0, 2.0, 3.0, 5.0, 7.5, 10.0, 15.0, 20.0)
#: Detection thresholds (deg) searched on val.
THRESHOLDS_DEG = (1.0, 2.0, 3.0, 5.0, 8.0, 10.0, 12.0, 15.0)
#: Correction thresholds (deg) searched on val (lowest in-window rotation error).
CORRECTION_THRESHOLDS_DEG = (2.0, 3.0, 5.0, 8.0, 10.0)
#: Position methods compared (rotation is corrected by the gyro in all of them): "fusion-eq3" is
#: the literal reading of MI-Poser Eq. 3, "fusion" our Kalman blend (:mod:`.mim`).
METHODS = ("none", "hold", "odometry", "nbeats", "fusion-eq3", "fusion")
#: The paper-literal anchor (the previous frame), for the ablation rows.
LITERAL = {"anchor_frames": 1, "position_anchor_frames": 1}
#: Room-fixed source of MI-Poser User Study 2 ("the EMF source is fixed to the environment";
#: participants moved "within a roughly 1.5-meter range from the EMF source"): placed in front of
#: the subject's first-frame head by SOURCE_FORWARD m (horizontal facing) and SOURCE_DOWN m lower
#: (a desk-top / shelf source at chest height); clips whose sensor leaves MAX_RANGE m are skipped.
SOURCE_FORWARD, SOURCE_DOWN, MAX_RANGE = 1.1, 0.1, 1.5
#: The streams a session cache holds per frame.
STREAMS = ("R_true", "p_true", "R", "p", "gyro", "acc", "carried")
#: Clips shorter than this (s) are left out: the N-BEATS input window (1 s) and a bit.
MIN_CLIP_S = 1.5

Clip = dict[str, Any]
Session = list[tuple[str, str, Any]]


def _store(store: Any) -> Any:
    return store if store is not None else CorpusStore()


def head_sessions(split: str, seconds: float, limit: int | None, store: Any = None) -> list[list[str]]:
    """Head-source sessions: consecutive clips of ``split`` (sorted ids, those of at least
    :data:`MIN_CLIP_S`) grouped until >= ``seconds``; the first ``limit`` (all when None)."""
    store = _store(store)
    out: list[list[str]] = []
    cur: list[str] = []
    acc = 0.0
    for c in sorted(store.clips(split=split)):
        e = store.entry(c)
        if e["frames"] / e["fps"] < MIN_CLIP_S:
            continue
        cur.append(c)
        acc += e["frames"] / e["fps"]
        if acc >= seconds:
            out.append(cur)
            cur, acc = [], 0.0
    return out[:limit] if limit else out


def world_source_trajectories(motion: Any, body: Any, site: str) -> tuple[SiteTrajectories, np.ndarray]:
    """``site``'s trajectories relative to the room-fixed Study 2 source (module doc) and its
    range from the source per frame ``(T,)`` m."""
    tr = body_trajectories(motion, body, (site, "head"), source="world")
    hR, hp = tr.R[0, 1].numpy(), tr.p[0, 1].numpy()
    f = hR[:, 2].copy()  # the head's facing axis (SMPL +Z), horizontal part
    f[1] = 0.0
    f /= max(np.linalg.norm(f), 1e-9)
    src = hp + SOURCE_FORWARD * f - np.array([0.0, SOURCE_DOWN, 0.0])
    tr = body_trajectories(motion, body, (site,), source="world",
                           source_pose=(torch.eye(3, dtype=torch.float64), torch.from_numpy(src)))
    ranges = np.linalg.norm(tr.p[:, 0].numpy() - src, axis=1)
    return tr, ranges


def world_sessions(split: str, seconds: float, limit: int | None, body: Any, store: Any = None) -> list[Session]:
    """Study 2 sessions: clips of ``split`` in a seeded random order (varied motion per session);
    each wrist of a clip is a separate candidate, kept when it stays within :data:`MAX_RANGE` of
    the room-fixed source; one session holds one wrist's clips (MI-Poser's sessions had one
    sensor), grouped until >= ``seconds``; left- and right-wrist sessions are built in parallel.

    Returns:
        sessions, each a list of ``(clip id, site, SiteTrajectories)``.
    """
    store = _store(store)
    clips = [c for c in sorted(store.clips(split=split))
             if store.entry(c)["frames"] / store.entry(c)["fps"] >= MIN_CLIP_S]
    np.random.default_rng(zlib.crc32(split.encode())).shuffle(clips)
    out: list[Session] = []
    cur: dict[str, tuple[Session, float]] = {"left_wrist": ([], 0.0), "right_wrist": ([], 0.0)}
    for c in clips:
        m = store.load(c)
        for site in cur:
            tr, r = world_source_trajectories(m, body, site)
            if r.max() > MAX_RANGE:
                continue
            lst, acc = cur[site]
            lst.append((c, site, tr))
            acc += tr.num_frames / tr.fps
            if acc >= seconds:
                out.append(lst)
                lst, acc = [], 0.0
            cur[site] = (lst, acc)
        if limit and len(out) >= limit:
            break
    return out[:limit] if limit else out


def simulate_clip(motion_or_trajectories: Any, split: str, cond: str, clip: str, site: str, body: Any,
                  source: str = "world", seed: int = 0) -> Any:
    """One clip's wrist ``site`` under condition ``cond`` (:func:`simulate_condition`), seeded by
    the CRC-32 of ``"<split>:<cond>:<clip>[:<site>]"`` (the site with ``source="world"``;
    ``":<seed>"`` appended when ``seed`` is not 0), so a session is reproducible clip by clip.

    Returns:
        the site's :class:`~wearpose.interference.simulate.SensorStreams`.
    """
    key = f"{split}:{cond}:{clip}" + (f":{site}" if source == "world" else "") + (f":{seed}" if seed else "")
    sim = simulate_condition(motion_or_trajectories, cond, sensors=(site,), seed=zlib.crc32(key.encode()) % (2 ** 31),
                             body=body)
    return sim[site]


def as_clip(streams: Mapping[str, np.ndarray], session: int, clip: str, site: str) -> Clip:
    """A per-clip dict (module doc) of ``streams`` (:data:`STREAMS` by name, a cache's slice or a
    :class:`~wearpose.interference.simulate.SensorStreams`' attributes) with its errors."""
    d: Clip = {k: streams[k] for k in STREAMS}
    d.update(session=int(session), clip=str(clip), site=str(site))
    d["pos_error"] = np.linalg.norm(d["p"] - d["p_true"], axis=1)
    d["rot_error"] = rotation_error(d["R"], d["R_true"])
    return d


def world_clips(motions: Iterable[tuple[str, Any]], split: str, cond: str, body: Any,
                seed: int = 0) -> tuple[list[Clip], int]:
    """Each wrist of each ``(clip id, motion)`` with the room-fixed Study 2 source
    (:func:`world_source_trajectories`), simulated under ``cond`` as :func:`simulate_sessions`
    does (:func:`simulate_clip`); a wrist that leaves :data:`MAX_RANGE` is left out. Every
    kept wrist is its own session.

    Returns:
        ``(clips, wrists left out of range)``.
    """
    out: list[Clip] = []
    skipped = 0
    for cid, motion in motions:
        for site in ("left_wrist", "right_wrist"):
            tr, r = world_source_trajectories(motion, body, site)
            if r.max() > MAX_RANGE:
                skipped += 1
                continue
            s = simulate_clip(tr, split, cond, cid, site, body, "world", seed)
            out.append(as_clip({k: getattr(s, k) for k in STREAMS}, len(out), cid, site))
    return out, skipped


def detection_metrics(clips: list[Clip], threshold_deg: float, e_p_cm: float, **config: Any) -> dict[str, Any]:
    """MI-Poser Table 3 of ``clips`` at one detection threshold: :func:`binary_metrics` of the
    :func:`detect_all` flags against "position error above ``e_p_cm``". MCC, F1, precision and
    recall are None (undefined, not 0) when no frame is interfered or none is flagged."""
    if not clips:
        return {"mcc": None, "f1": None, "precision": None, "recall": None, "positive_ratio": None, "frames": 0}
    flags = detect_all(clips, threshold_deg, **config)
    truth = _errors(clips) > e_p_cm / 100
    m: dict[str, Any] = binary_metrics(flags, truth)
    if not truth.any() or not flags.any():
        m.update(mcc=None, f1=None, precision=None, recall=None)
    return m


def cache_path(cache_dir: str | Path, split: str, cond: str) -> Path:
    """The session cache of ``split`` under condition ``cond``: ``<cache_dir>/<split>_<cond>.npz``."""
    return Path(cache_dir) / f"{split}_{cond}.npz"


def simulate_sessions(split: str, seconds: float, limit: int | None, conds: list[str], cache_dir: str | Path,
                      source: str = "world", store: Any = None,
                      log: Callable[[str], None] = lambda s: print(s, flush=True)) -> list[Path]:
    """Simulate the sessions of ``split`` (``source="world"``: :func:`world_sessions`; ``"head"``:
    :func:`head_sessions`, wrists alternating per session) under each condition of ``conds`` and
    cache them (:func:`cache_path`). Each clip's seed is the CRC-32 of
    ``"<split>:<cond>:<clip>[:<site>]"``, so a cache is reproducible clip by clip.

    Returns:
        the cache files written, one per condition.
    """
    body = BodyModel()
    store = _store(store)
    if source == "world":
        sess = world_sessions(split, seconds, limit, body, store)
    else:
        sess = [[(c, "left_wrist" if si % 2 == 0 else "right_wrist", None) for c in clips]
                for si, clips in enumerate(head_sessions(split, seconds, limit, store))]
    written = []
    for cond in conds:
        path = cache_path(cache_dir, split, cond)
        path.parent.mkdir(parents=True, exist_ok=True)
        arrays: dict[str, list[np.ndarray]] = {k: [] for k in STREAMS}
        index = []
        t0 = time.time()
        frames = 0
        for si, clips in enumerate(sess):
            for cid, site, tr in clips:
                s = simulate_clip(tr if tr is not None else store.load(cid), split, cond, cid, site, body, source)
                for k in arrays:
                    arrays[k].append(getattr(s, k))
                index.append((si, cid, site, s.num_frames))
                frames += s.num_frames
            log(f"{cond} {split} session {si + 1}/{len(sess)}: {frames} frames, {time.time() - t0:.0f} s")
        np.savez_compressed(path, **{k: np.concatenate(v) for k, v in arrays.items()},
                            session=np.array([i[0] for i in index]), clip=np.array([i[1] for i in index]),
                            site=np.array([i[2] for i in index]), frames=np.array([i[3] for i in index]),
                            source=np.array(source))
        written.append(path)
    return written


def load_sessions(path: str | Path) -> list[Clip]:
    """The per-clip dicts (module doc) of a :func:`simulate_sessions` cache, with their
    ``pos_error`` (m) and ``rot_error`` (rad)."""
    z = np.load(path)
    out, o = [], 0
    for si, cid, site, n in zip(z["session"], z["clip"], z["site"], z["frames"]):
        out.append(as_clip({k: z[k][o:o + n] for k in STREAMS}, si, cid, site))
        o += n
    return out


def mean_sd(x: np.ndarray) -> tuple[float, float]:
    """``(mean, population SD)`` of ``x``."""
    return float(np.mean(x)), float(np.std(x))


def condition_stats(clips: list[Clip]) -> dict[str, Any]:
    """MI-Poser Table 1 of ``clips``: per-session mean and max position (cm) and rotation (deg)
    errors, as ``(mean, SD)`` over sessions; with ``sessions``, ``frames``, ``minutes`` (120 Hz)
    and ``carried_fraction``."""
    ses = sorted({c["session"] for c in clips})
    per: dict[str, list[float]] = {k: [] for k in ("mean_pos_cm", "max_pos_cm", "mean_rot_deg", "max_rot_deg")}
    for s in ses:
        pe = np.concatenate([c["pos_error"] for c in clips if c["session"] == s])
        re = np.concatenate([c["rot_error"] for c in clips if c["session"] == s])
        per["mean_pos_cm"].append(100 * pe.mean())
        per["max_pos_cm"].append(100 * pe.max())
        per["mean_rot_deg"].append(np.degrees(re.mean()))
        per["max_rot_deg"].append(np.degrees(re.max()))
    frames = sum(len(c["pos_error"]) for c in clips)
    return {"sessions": len(ses), "frames": frames, "minutes": frames / EM_RATE / 60,
            **{k: mean_sd(np.array(v)) for k, v in per.items()},
            "carried_fraction": float(np.concatenate([c["carried"] for c in clips]).mean())}


def detect_all(clips: list[Clip], threshold_deg: float, **config: Any) -> np.ndarray:
    """:func:`~wearpose.interference.mim.detect` flags of every clip at ``threshold_deg``,
    concatenated ``(N,)`` bool; ``config``: further ``detect`` settings (:data:`LITERAL`)."""
    return np.concatenate([detect(c["R"], c["gyro"], EM_RATE, threshold_deg, **config)[0] for c in clips])


def detection_flags(clips: list[Clip], thresholds: tuple[float, ...] = THRESHOLDS_DEG,
                    **config: Any) -> dict[float, np.ndarray]:
    """Threshold (deg) -> :func:`detect_all` flags."""
    return {th: detect_all(clips, th, **config) for th in thresholds}


def run_mim(clips: list[Clip], cfg: MIMConfig, timing: bool = False) -> dict[str, np.ndarray]:
    """MIM (``cfg``) run online over each clip (reset per clip) at 120 Hz.

    Returns:
        concatenated ``(N,)`` arrays: ``rot_error`` (rad) and ``pos_error`` (m) of the output
        against the truth, the ``interfered``, ``corrected`` and ``degraded`` flags; with
        ``timing`` also ``times`` and ``corr_times`` (s per uncorrected / corrected frame).
    """
    mim = MIM(cfg)
    out: dict[str, list[np.ndarray]] = {k: [] for k in ("rot_error", "pos_error", "interfered", "corrected", "degraded")}
    times, corr_times = [], []
    for c in clips:
        mim.reset()
        T = len(c["p"])
        R_o, p_o = np.empty((T, 3, 3)), np.empty((T, 3))
        fl, co, de = np.zeros(T, bool), np.zeros(T, bool), np.zeros(T, bool)
        for t in range(T):
            t0 = time.perf_counter()
            o = mim.step(c["R"][t], c["p"][t], c["gyro"][t], c["acc"][t], 1 / EM_RATE)
            dtm = time.perf_counter() - t0
            if timing:
                (corr_times if o["corrected"] else times).append(dtm)
            R_o[t], p_o[t], fl[t], co[t], de[t] = o["R"], o["p"], o["interfered"], o["corrected"], o["degraded"]
        out["rot_error"].append(rotation_error(R_o, c["R_true"]))
        out["pos_error"].append(np.linalg.norm(p_o - c["p_true"], axis=1))
        out["interfered"].append(fl)
        out["corrected"].append(co)
        out["degraded"].append(de)
    res = {k: np.concatenate(v) for k, v in out.items()}
    if timing:
        res["times"] = np.array(times)
        res["corr_times"] = np.array(corr_times)
    return res


def per_session(clips: list[Clip], values: np.ndarray) -> list[np.ndarray]:
    """``values`` ``(N,)`` (frames of ``clips`` concatenated) split by session, in session order."""
    sess = np.concatenate([np.full(len(c["p"]), c["session"]) for c in clips])
    return [values[sess == s] for s in sorted(set(sess.tolist()))]


def _errors(clips: list[Clip]) -> np.ndarray:
    return np.concatenate([c["pos_error"] for c in clips])


def best_threshold(flags: dict[float, np.ndarray], truth: np.ndarray) -> float:
    """The detection threshold whose flags have the highest MCC against ``truth`` (the first
    of equals, in ``flags``' order)."""
    return max(flags, key=lambda th: binary_metrics(flags[th], truth)["mcc"])


def detection_sweep(test: list[Clip], val: list[Clip] | None, e_p_cm: tuple[float, ...] = E_P_SWEEP_CM,
                    thresholds: tuple[float, ...] = THRESHOLDS_DEG) -> list[dict[str, Any]]:
    """Fig. 8: for each ground-truth threshold ``e_P`` (a frame is interfered when its EM
    position error exceeds it): the oracle (best MCC on test) and, with ``val``, the threshold
    chosen on val (``val_threshold_deg``) and its ``test`` metrics (:func:`binary_metrics`);
    the detection thresholds searched are ``thresholds`` (deg)."""
    err_t, flags_t = _errors(test), detection_flags(test, thresholds)
    flags_v = detection_flags(val, thresholds) if val else None
    err_v = _errors(val) if val else None
    sweep = []
    for e in e_p_cm:
        y_t = err_t > e / 100
        oracle = max(((th, binary_metrics(f, y_t)) for th, f in flags_t.items()), key=lambda x: x[1]["mcc"])
        row: dict[str, Any] = {"e_p_cm": e, "oracle_threshold_deg": oracle[0], "oracle": oracle[1]}
        if val:
            th_v = best_threshold(flags_v, err_v > e / 100)
            row["val_threshold_deg"] = th_v
            row["test"] = binary_metrics(flags_t[th_v], y_t)
        sweep.append(row)
    return sweep


def literal_detection(test: list[Clip], val: list[Clip], e_p_cm: float,
                      thresholds: tuple[float, ...] = THRESHOLDS_DEG) -> dict[str, Any]:
    """The paper-literal detector (:data:`LITERAL` anchor), its threshold chosen on val like
    :func:`detection_sweep`'s: ``{"val_threshold_deg", "test": binary_metrics}`` at ``e_p_cm``."""
    y_v, y_t = _errors(val) > e_p_cm / 100, _errors(test) > e_p_cm / 100
    th = best_threshold(detection_flags(val, thresholds, **LITERAL), y_v)
    return {"val_threshold_deg": th, "test": binary_metrics(detect_all(test, th, **LITERAL), y_t)}


def correction_threshold(val: list[Clip] | None, window_cm: float) -> float:
    """The rotation-correction threshold (deg) of :data:`CORRECTION_THRESHOLDS_DEG` with the
    lowest in-window rotation error on ``val``; MIM's default when val has no window."""
    if val:
        w_v = _errors(val) > window_cm / 100
        if w_v.any():
            scores = {th: float(run_mim(val, MIMConfig(threshold_deg=th, position="none"))["rot_error"][w_v].mean())
                      for th in CORRECTION_THRESHOLDS_DEG}
            return min(scores, key=scores.get)
    return MIMConfig().threshold_deg


def _latency_ms(r: dict[str, np.ndarray]) -> dict[str, Any]:
    ct = r["corr_times"]
    return {"all_frames_mean": float(1e3 * np.concatenate([r["times"], ct]).mean()),
            "uncorrected_mean": float(1e3 * r["times"].mean()),
            "uncorrected_p99": float(1e3 * np.percentile(r["times"], 99)),
            "corrected_mean": float(1e3 * ct.mean()) if len(ct) else None,
            "corrected_p99": float(1e3 * np.percentile(ct, 99)) if len(ct) else None,
            "corrected_frames": int(len(ct))}


def _method_row(test: list[Clip], r: dict[str, np.ndarray], w_t: np.ndarray) -> dict[str, Any]:
    ps, rs = per_session(test, r["pos_error"]), per_session(test, r["rot_error"])
    return {
        "mean_pos_cm": mean_sd(np.array([100 * x.mean() for x in ps])),
        "max_pos_cm": mean_sd(np.array([100 * x.max() for x in ps])),
        "mean_rot_deg": mean_sd(np.array([np.degrees(x.mean()) for x in rs])),
        "max_rot_deg": mean_sd(np.array([np.degrees(x.max()) for x in rs])),
        "window_pos_cm": float(100 * r["pos_error"][w_t].mean()) if w_t.any() else None,
        "window_rot_deg": float(np.degrees(r["rot_error"][w_t].mean())) if w_t.any() else None,
        "corrected_fraction": float(r["corrected"].mean()), "degraded_fraction": float(r["degraded"].mean()),
    }


def correction(test: list[Clip], val: list[Clip] | None, forecaster: str, window_cm: float,
               timing: bool = False) -> tuple[dict[str, Any], dict[str, Any] | None]:
    """Figs. 9-10: every position method of :data:`METHODS` run on ``test`` at the threshold
    :func:`correction_threshold` chose on ``val``; errors per session and inside the
    interference windows (frames whose raw position error exceeds ``window_cm``); the
    paper-literal anchor beside.

    Returns:
        ``(correction row, latency_ms per method or None)`` (latency with ``timing``).
    """
    err_t = _errors(test)
    w_t = err_t > window_cm / 100
    rot_raw = np.concatenate([c["rot_error"] for c in test])
    best_th = correction_threshold(val, window_cm)
    methods, latency = {}, {}
    for m in METHODS:
        r = run_mim(test, MIMConfig(threshold_deg=best_th, position=m, forecaster=forecaster), timing=timing)
        methods[m] = _method_row(test, r, w_t)
        if "times" in r:
            latency[m] = _latency_ms(r)
    raw_w_rot = float(np.degrees(rot_raw[w_t].mean())) if w_t.any() else None
    literal = None
    if w_t.any():
        r = run_mim(test, MIMConfig(threshold_deg=best_th, position="none", **LITERAL))
        literal = {"window_rot_deg": float(np.degrees(r["rot_error"][w_t].mean()))}
        r = run_mim(test, MIMConfig(threshold_deg=best_th, position="fusion", forecaster=forecaster, **LITERAL))
        literal["fusion_window_pos_cm"] = float(100 * r["pos_error"][w_t].mean())
    row = {"threshold_deg": best_th, "window_frames": int(w_t.sum()), "window_raw_rot_deg": raw_w_rot,
           "window_raw_pos_cm": float(100 * err_t[w_t].mean()) if w_t.any() else None,
           "rotation_reduction": (1 - methods["none"]["window_rot_deg"] / raw_w_rot) if raw_w_rot else None,
           "methods": methods, "literal_anchor": literal,
           "mim_config": {k: v for k, v in MIMConfig().__dict__.items()}}
    return row, (latency or None)


def evaluate_condition(test: list[Clip], val: list[Clip] | None, forecaster: str, window_cm: float,
                       table_e_p_cm: float, timing: bool = False) -> dict[str, Any]:
    """One condition's study: ``conditions`` (:func:`condition_stats` of test),
    ``detection_sweep`` (:func:`detection_sweep`), ``detection_table`` (its row at
    ``table_e_p_cm``, with the :func:`literal_detection` ablation when there is val),
    ``correction`` (:func:`correction`) and, with ``timing``, ``latency_ms``."""
    sweep = detection_sweep(test, val)
    table = next(r for r in sweep if abs(r["e_p_cm"] - table_e_p_cm) < 1e-9)
    if val:
        table["literal_anchor"] = literal_detection(test, val, table_e_p_cm)
    corr, latency = correction(test, val, forecaster, window_cm, timing)
    out = {"conditions": condition_stats(test), "detection_table": table, "detection_sweep": sweep,
           "correction": corr}
    if latency is not None:
        out["latency_ms"] = latency
    return out


def correction_windows(test: list[Clip], threshold_deg: float,
                       window_cms: tuple[float, ...] = (5.0, 10.0)) -> dict[str, dict[str, Any]]:
    """Robustness of the in-window correction to the window definition: windows = raw position
    error above each of ``window_cms``; rotation (our anchor and the paper-literal one),
    odometry and fusion at ``threshold_deg``.

    Returns:
        ``f"{window_cm:g}"`` -> ``threshold_deg``, ``window_frames``, ``raw_rot_deg``,
        ``raw_pos_cm`` and per run ``{"rot_deg", "pos_cm"}`` (windows with no frame left out).
    """
    err = _errors(test)
    rot = np.concatenate([c["rot_error"] for c in test])
    runs = {"rotation": MIMConfig(threshold_deg=threshold_deg, position="none"),
            "rotation_literal_anchor": MIMConfig(threshold_deg=threshold_deg, position="none", **LITERAL),
            "odometry": MIMConfig(threshold_deg=threshold_deg, position="odometry"),
            "fusion": MIMConfig(threshold_deg=threshold_deg, position="fusion")}
    outs = {k: run_mim(test, v) for k, v in runs.items()}
    rows = {}
    for e in window_cms:
        w = err > e / 100
        if not w.any():
            continue
        row: dict[str, Any] = {"threshold_deg": threshold_deg, "window_frames": int(w.sum()),
                               "raw_rot_deg": float(np.degrees(rot[w].mean())), "raw_pos_cm": float(100 * err[w].mean())}
        row.update({k: {"rot_deg": float(np.degrees(o["rot_error"][w].mean())),
                        "pos_cm": float(100 * o["pos_error"][w].mean())} for k, o in outs.items()})
        rows[f"{e:g}"] = row
    return rows
