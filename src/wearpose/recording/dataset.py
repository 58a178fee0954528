"""Simulated recording sets: a sensor kit simulated on every clip of the prepared motion corpus.

:func:`simulate_corpus` is what ``wearpose simulate`` runs. Layout of an output directory::

    <out>/index.json                               settings, one row per clip, failures
    <out>/<source>/<subject>/<clip>.npz            one recording per clip (load_recording)

Each recording is :func:`wearpose.recording.recording_from_simulation` of one clip: the kit's
streams, the clip as ground truth, the EM offsets applied and (by default) the EM source pose.

Why these choices:

- **Deterministic per clip.** A clip's seed is derived from the base seed and the clip id
  (:func:`clip_seed`), never from its position in the run, so a clip's recording does not depend
  on the split, filters, ``--limit``, the number of workers or the completion order, and a
  re-run reproduces it bit for bit. Workers run torch on one thread each (also for determinism:
  results do not depend on the machine's thread count).
- **One synthetic subject per clip.** With ``offsets="random"`` (default) every clip gets its
  own sensor-to-skin offsets (:func:`wearpose.sensors.random_subject_offsets`, from the clip
  seed), as EM-POSE trains on many subjects' offsets (Sec. 5.3); ``"none"`` puts the sensors
  exactly on the skin frame (EM-POSE Eq. 3).
- **Idempotent.** A clip whose index row has the same settings, the same prepared motion
  (the store's conversion stamp) and whose file is still there with the recorded size is
  skipped. Runs with the same settings accumulate into one index (e.g. ``--split train`` then
  ``--split val``); a directory simulated with other settings is refused unless ``overwrite``.
- **A failing clip does not stop the batch.** Its error (type and message) is recorded under
  ``failures`` in the index and returned; the other clips carry on.
- **Licences travel with the data.** Every row carries the clip's licence and whether it is
  non-commercial; ``include_nc=False`` leaves the CC BY-NC clips out, and the index states
  which choice was made.
"""

from __future__ import annotations

import hashlib
import json
import multiprocessing
import os
import re
import time
import warnings
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path, PurePosixPath
from typing import Any, Iterable, Sequence

import torch
from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn

from wearpose.body import BodyModel
from wearpose.body.asset import DEFAULT_ASSET, load_default_asset
from wearpose.errors import ConfigError, InputFileError
from wearpose.fileio import atomic_write_text
from wearpose.motion import CorpusStore
from wearpose.motion.sequence import MotionSequence
from wearpose.recording.fileformat import save_recording
from wearpose.recording.simulated import simulate_recording
from wearpose.sensors import get_kit

INDEX_NAME = "index.json"
SET_FORMAT = "wearpose.recording-set"
SET_VERSION = 1
#: Bump when what a clip's recording contains changes, so that existing sets are regenerated.
GENERATOR_VERSION = "simset-1"
NOISE_CHOICES = ("default", "none", "ximu3")
EXECUTORS = ("local", "ray")
OFFSETS_CHOICES = ("random", "none")
#: Wearers' body shapes: the motion's own (``none``), or one per clip drawn from the body
#: asset's shape space (:func:`wearpose.sensors.random_body_shape`): ``random`` for training
#: sets, ``heldout`` (a stream no training draw uses) for evaluation sets.
SHAPES_CHOICES = ("none", "random", "heldout")
#: How often (seconds) the index is rewritten during a long run, so an interrupted run keeps
#: most of its work (the next run skips what the index lists).
INDEX_FLUSH_S = 30.0
#: With ``workers=None``, batches with more motion than this (seconds) run in a process pool.
#: Why: one process simulates em12 at ~100x real time (files included; benchmarks/simulate.py),
#: while each pool worker first pays ~5 s (torch import + body model; ~10 s for two on a busy
#: 2-core machine), so below ~20 min of motion a pool does not pay for itself.
AUTO_PARALLEL_MOTION_S = 1200.0


def usable_cores() -> int:
    """CPU cores this process may run on (its affinity mask; else ``os.cpu_count()``), >= 1.

    Not the cores minus the 1-minute load average, which is a momentary figure: a load of 1.2
    on 2 cores sent ``simulate --kit em12 --split train`` to one worker (145 s, issue 25). A core
    held by another job for the whole run does slow two workers (measured once: 1.6x longer than
    one process); pass ``workers=1`` then.
    """
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):  # not on every platform
        return max(1, os.cpu_count() or 1)


def clip_seed(base_seed: int, clip_id: str) -> int:
    """The seed of one clip: a 48-bit hash of ``(base_seed, clip_id)``.

    48 bits: exact in JSON/JavaScript numbers, and collisions among ~10^4 clips are negligible
    (probability ~1e-7).
    """
    h = hashlib.sha256(f"{int(base_seed)}\x00{clip_id}".encode("utf-8")).digest()
    return int.from_bytes(h[:6], "big")


def is_noncommercial(licence: str | None) -> bool:
    """True for licences with a NonCommercial term (``CC-BY-NC-4.0``, ``CC BY-NC-SA 4.0``...)."""
    if not licence:
        return False
    tokens = re.split(r"[\s\-_/]+", licence.upper())
    return "NC" in tokens or "NONCOMMERCIAL" in tokens or "NON-COMMERCIAL" in licence.upper()


def _settings(kit: str, rate: float | None, noise: str, offsets: str, source_pose: bool, body_asset: str,
              base_seed: int, include_nc: bool, tpose: float = 0.0, shapes: str = "none") -> dict[str, Any]:
    # include_nc is a setting (not a filter like split): a set that promises "no NonCommercial
    # clips" must not silently accumulate them from an earlier run into the same directory.
    s = {"generator": GENERATOR_VERSION, "kit": kit, "rate": rate, "noise": noise, "offsets": offsets,
         "source_pose": source_pose, "body_asset": body_asset, "base_seed": int(base_seed), "include_nc": include_nc}
    if tpose:  # only when used, so sets made before the option keep their settings key
        s["tpose_s"] = float(tpose)
    if shapes != "none":  # likewise
        s["shapes"] = shapes
    return s


def default_tpose(kit: Any) -> float:
    """Seconds of calibration T-pose ``simulate`` prepends by default: 1 s for kits of plain IMUs
    only (``imu6``: their estimator, PIP, calibrates sensor-to-bone from a T-pose, PIP Sec. 3.1),
    0 for the others (EM and VIO measure poses; MI-Poser builds its own prefix)."""
    return 1.0 if all(s.kind == "imu" for s in kit.sensors) else 0.0


def _key(settings: dict[str, Any]) -> str:
    return hashlib.sha1(json.dumps(settings, sort_keys=True).encode("utf-8")).hexdigest()[:12]


def _rel_file(clip_id: str) -> str:
    p = PurePosixPath(f"{clip_id}.npz")
    if p.is_absolute() or any(part in ("", ".", "..") for part in p.parts):
        raise ConfigError(f"clip id {clip_id!r} cannot be used as a file path inside the output directory")
    return p.as_posix()


# ---------------------------------------------------------------------------------- workers
_BODY: Any = None


def _init_worker(body: str | None, quiet: bool = True) -> None:
    """Process-pool initialiser: one torch thread, the body model loaded once per worker."""
    global _BODY
    torch.set_num_threads(1)
    if quiet:
        # Site substitutions of custom kits are recorded in each recording's meta instead.
        warnings.simplefilter("ignore")

    _BODY = BodyModel(body)


def _simulate_one(job: dict[str, Any]) -> dict[str, Any]:
    """Simulate, convert and write one clip. Never raises: errors come back as ``ok=False``."""
    t0 = time.perf_counter()
    try:
        rec, res = simulate_recording(
            MotionSequence.load(job["motion_file"]), job["kit"], _BODY, seed=job["seed"], noise=job["noise"],
            rate=job["rate"], offsets="random" if job["offsets"] == "random" else None,
            shape=None if job.get("shapes", "none") == "none" else job["shapes"], tpose_s=job.get("tpose") or None,
            subject=job["subject"], source_pose=job["source_pose"],
            meta={"clip_id": job["id"], "clip_seed": job["seed"], "base_seed": job["base_seed"]})
        motion = rec.ground_truth
        # save_recording writes atomically: an interrupted run never leaves a half-written file.
        out = Path(job["out"])
        save_recording(rec, out)
        frames = max(s.num_frames for s in rec.sensors)
        return {"id": job["id"], "ok": True, "frames": frames, "sensor_frames": res.num_sensor_frames,
                "dropped_sensor_frames": int(sum(int((~s.valid).sum()) for s in rec.sensors)),
                "motion_frames": motion.num_frames, "fps": motion.fps, "seconds": motion.duration,
                "bytes": out.stat().st_size, "time_s": time.perf_counter() - t0}
    except Exception as exc:  # noqa: BLE001 - one bad clip must not stop the batch; reported per clip
        return {"id": job["id"], "ok": False, "error": f"{type(exc).__name__}: {exc}", "time_s": time.perf_counter() - t0}


# ---------------------------------------------------------------------------------- driver
def _as_filter(v: str | Iterable[str] | None) -> str | list[str] | None:
    if v is None or isinstance(v, str):
        return v
    v = list(v)
    return v or None


def simulate_corpus(out_dir: str | Path, kit: str = "em12", split: str | Sequence[str] | None = "train", *,
                    cache_dir: str | Path | None = None, source: str | Sequence[str] | None = None,
                    licence: str | Sequence[str] | None = None, include_nc: bool = True, seed: int = 0,
                    noise: str = "default", offsets: str = "random", rate: float | None = None,
                    limit: int | None = None, workers: int | None = None, source_pose: bool = True,
                    body: str | None = None, overwrite: bool = False, progress: bool = True,
                    clip_ids: Sequence[str] | None = None, executor: str = "local",
                    ray_address: str | None = None, tpose: float | None = None, shapes: str = "none") -> dict[str, Any]:
    """Simulate ``kit`` on the prepared corpus clips and write one recording per clip + an index.

    Args:
        out_dir: output directory (created); layout in the module docstring.
        kit: sensor kit name (:func:`wearpose.sensors.list_kits`).
        split: ``"train"``, ``"val"``, ``"test"``, several, or ``None`` for all.
        cache_dir: the prepared corpus (default :func:`wearpose.motion.cache_dir`).
        source, licence: further clip filters (one value or several), as in
            :meth:`wearpose.motion.CorpusStore.clips`.
        include_nc: keep clips under a NonCommercial licence (:func:`is_noncommercial`).
        seed: base seed; clip seeds are :func:`clip_seed` of it.
        noise: ``"default"`` (documented error models, dropped EM frames) or ``"none"``.
        offsets: ``"random"`` (a synthetic subject's sensor offsets per clip) or ``"none"``.
        rate: every sensor at this rate, Hz (default: the kit's rates).
        limit: only the first ``limit`` selected clips (sorted by id).
        workers: processes; ``1`` runs in this process. Default: the usable cores
            (:func:`usable_cores`) when the clips to simulate hold more than
            :data:`AUTO_PARALLEL_MOTION_S` of motion, else 1 (a pool's start-up costs more than
            it saves on small batches).
        source_pose: store the EM source's world pose in each recording's meta.
        body: body asset (``None``: the embedded one; ``"smpl"`` or a path).
        overwrite: replace a set simulated in ``out_dir`` with other settings (the recordings
            its index lists are deleted, then the selected clips are simulated).
        progress: show a ``rich`` progress bar (on stderr).
        clip_ids: simulate exactly these clip ids (after the other filters), e.g. for tests.
        executor: ``"local"`` (this process or a local process pool of ``workers``) or
            ``"ray"``: ``workers`` Ray actors (default: the cluster's CPUs), each loading the body
            once, on the cluster at ``ray_address`` (default ``$RAY_ADDRESS``, else a local Ray
            started for this run). On a cluster the prepared corpus and ``out_dir`` must be on a
            filesystem every node sees at the same path (workers read clips and write recordings
            themselves). Needs the optional extra: ``pip install "wearpose[ray]"``.
        ray_address: Ray cluster address (``"auto"``, ``"ray://head:10001"``...).
        tpose: seconds of calibration T-pose held before each clip (0: none; ``None``:
            :func:`default_tpose` of the kit, 1 s for ``imu6``). The recording's
            ``meta["calibration_window"]`` marks it (:mod:`wearpose.recording.tpose`) and its
            ground truth includes it; the index's ``motion_frames``/``seconds`` count it too.
        shapes: the wearers (:data:`SHAPES_CHOICES`): ``"none"`` the motion's own body;
            ``"random"`` / ``"heldout"`` a body shape per clip from the clip seed
            (:func:`wearpose.sensors.simulate`'s ``shape``), the motion re-fitted to it and
            stored as the ground truth (its ``betas`` in the recording).

    Returns:
        ``{"out", "index", "selected", "simulated", "skipped", "failed", "excluded_nc",
        "failures": {clip_id: error}, "seconds", "clips_per_s", "sensor_frames",
        "sensor_frames_per_s", "bytes", "workers", "settings"}``; throughput counts the clips
        simulated in this run (not the skipped ones).

    Raises:
        ConfigError: unknown kit/noise/offsets, no clip selected, or ``out_dir`` holds a set
            made with other settings (and not ``overwrite``).
        InputFileError: no prepared corpus (run ``wearpose data prepare``).
    """
    t_start = time.perf_counter()
    kit_obj = get_kit(kit)  # fails early, naming the available kits
    if noise not in NOISE_CHOICES:
        raise ConfigError(f"noise must be one of {NOISE_CHOICES}, got {noise!r}")
    if offsets not in OFFSETS_CHOICES:
        raise ConfigError(f"offsets must be one of {OFFSETS_CHOICES}, got {offsets!r}")
    if rate is not None and not rate > 0:
        raise ConfigError(f"rate must be > 0 Hz, got {rate!r}")
    if limit is not None and limit < 1:
        raise ConfigError(f"limit must be >= 1, got {limit!r}")
    if executor not in EXECUTORS:
        raise ConfigError(f"executor must be one of {EXECUTORS}, got {executor!r}")
    if shapes not in SHAPES_CHOICES:
        raise ConfigError(f"shapes must be one of {SHAPES_CHOICES}, got {shapes!r}")
    if tpose is None:
        tpose = default_tpose(kit_obj)
    if not (tpose == 0 or tpose >= 0.1):
        raise ConfigError(f"tpose must be 0 (no T-pose) or >= 0.1 s, got {tpose!r}")
    ray = _import_ray() if executor == "ray" else None
    try:
        store = CorpusStore(cache_dir)
    except InputFileError as exc:
        raise InputFileError(exc.path, exc.problem, "a prepared motion corpus: run `wearpose data prepare` first "
                             "(or pass the store with --cache / $WEARPOSE_CACHE)", field=exc.field) from None
    ids = store.clips(_as_filter(split), _as_filter(source), _as_filter(licence))
    if clip_ids is not None:
        wanted = set(clip_ids)
        unknown = sorted(wanted - set(store.entries))
        if unknown:
            raise ConfigError(f"clip id(s) {unknown} are not in the prepared corpus at {store.root}")
        ids = [c for c in ids if c in wanted]
    excluded_nc = [c for c in ids if is_noncommercial(store.entry(c).get("licence"))] if not include_nc else []
    ids = [c for c in ids if c not in set(excluded_nc)]
    if limit is not None:
        ids = ids[:limit]
    if not ids:
        raise ConfigError(f"no clip selected (split={split!r}, source={source!r}, licence={licence!r}, "
                          f"include_nc={include_nc}) in the prepared corpus at {store.root} "
                          f"({len(store)} clips; see wearpose data info)")

    body_id = _body_asset_id(body)
    settings = _settings(kit_obj.name, None if rate is None else float(rate), noise, offsets, source_pose, body_id, seed,
                         include_nc, tpose, shapes)
    key = _key(settings)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    index_path = out / INDEX_NAME
    old = _read_index(index_path)
    if old is not None and old.get("settings_key") != key:
        if not overwrite:
            was = old.get("settings") or {}
            diff = ", ".join(f"{k}: {was.get(k)!r} there, {v!r} now" for k, v in settings.items() if was.get(k) != v)
            raise ConfigError(f"{out} already holds a recording set made with other settings ({diff}); "
                              "use another output directory, the same settings, or --overwrite to replace it")
        # Replacing the set: its recordings were made with other settings, so none may stay
        # next to the new index (only files the old index lists, inside out_dir, are removed).
        root = out.resolve()
        for row in (old.get("clips") or {}).values():
            f = (out / str(row.get("file", ""))).resolve()
            if f.is_file() and root in f.parents:
                f.unlink()
        old = None
    clips: dict[str, Any] = dict(old.get("clips", {})) if old else {}
    failures: dict[str, str] = dict(old.get("failures", {})) if old else {}

    subject_note = ("the mocap performer; the sensor offsets are a synthetic subject drawn for this clip"
                    if offsets == "random" else "the mocap performer; sensors on the skin frame (no offsets)")
    todo: list[dict[str, Any]] = []
    for cid in ids:
        e = store.entry(cid)
        rel = _rel_file(cid)
        prev = clips.get(cid)
        f = out / rel
        if (prev and prev.get("motion_stamp") == e.get("stamp") and f.is_file()
                and f.stat().st_size == prev.get("bytes")):
            continue
        s = clip_seed(seed, cid)
        todo.append({"id": cid, "motion_file": str(store.root / e["file"]), "out": str(f), "seed": s, "base_seed": int(seed),
                     "kit": kit_obj.name, "rate": rate, "noise": noise, "offsets": offsets, "source_pose": source_pose,
                     "tpose": float(tpose), "shapes": shapes, "subject": {"id": f"{e['source']}/{e['subject']}", "note": subject_note},
                     "_row": {"file": rel, "seed": s, "kit": kit_obj.name, "split": e["split"], "source": e["source"],
                              "subject": e["subject"], "licence": e.get("licence"),
                              "noncommercial": is_noncommercial(e.get("licence")), "motion_stamp": e.get("stamp")}})
    skipped = len(ids) - len(todo)

    if executor == "ray":
        _ray_init(ray, ray_address)
        n_workers = max(1, int(workers) if workers is not None else int(ray.cluster_resources().get("CPU", 1)))
    elif workers is None:
        todo_s = sum(float(store.entry(j["id"]).get("seconds", 0.0)) for j in todo)
        n_workers = usable_cores() if todo_s > AUTO_PARALLEL_MOTION_S else 1
    else:
        n_workers = max(1, int(workers))
    n_workers = min(n_workers, max(1, len(todo)))
    stats = {"simulated": 0, "sensor_frames": 0, "bytes": 0}
    n_failed = [0]  # a list: updated from the nested finish()
    last_flush = [time.perf_counter()]

    def write_index() -> None:
        _write_index(index_path, settings, key, clips, failures, include_nc, store)

    def finish(job: dict[str, Any], res: dict[str, Any]) -> None:
        cid = job["id"]
        if res["ok"]:
            failures.pop(cid, None)
            clips[cid] = {**job["_row"], **{k: res[k] for k in ("frames", "sensor_frames", "dropped_sensor_frames",
                                                                   "motion_frames", "fps", "seconds", "bytes")}}
            stats["simulated"] += 1
            stats["sensor_frames"] += res["sensor_frames"]
            stats["bytes"] += res["bytes"]
        else:
            failures[cid] = res["error"]
            clips.pop(cid, None)
            n_failed[0] += 1
        if time.perf_counter() - last_flush[0] > INDEX_FLUSH_S:
            write_index()
            last_flush[0] = time.perf_counter()

    columns = (TextColumn(f"[bold]simulating {kit_obj.name}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
               TimeRemainingColumn(), TextColumn("{task.fields[failed]}"))
    # Biggest clips first, so that the workers finish together.
    todo.sort(key=lambda j: -int(store.entry(j["id"]).get("frames", 0)))
    t_sim = time.perf_counter()
    try:
        with Progress(*columns, console=Console(stderr=True), disable=not progress or not todo) as bar:
            task = bar.add_task("simulate", total=len(todo), failed="")

            def advance() -> None:
                bar.update(task, advance=1, failed=f"[red]{n_failed[0]} failed" if n_failed[0] else "")

            for job, res in _run_jobs(todo, n_workers, body, executor, ray_address):
                finish(job, res)
                advance()
    finally:
        # Also on Ctrl-C or an unexpected error: the finished clips stay indexed, so the next
        # run skips them.
        write_index()
    sim_s = time.perf_counter() - t_sim
    run_failures = {j["id"]: failures[j["id"]] for j in todo if j["id"] in failures}
    return {
        "out": str(out), "index": str(index_path), "kit": kit_obj.name, "split": split, "selected": len(ids),
        "simulated": stats["simulated"], "skipped": skipped, "failed": len(run_failures),
        "excluded_nc": len(excluded_nc), "failures": run_failures, "seconds": round(time.perf_counter() - t_start, 3),
        "simulate_seconds": round(sim_s, 3),
        "clips_per_s": round(stats["simulated"] / sim_s, 4) if stats["simulated"] else 0.0,
        "sensor_frames": stats["sensor_frames"],
        "sensor_frames_per_s": round(stats["sensor_frames"] / sim_s, 1) if stats["simulated"] else 0.0,
        "bytes": stats["bytes"], "workers": n_workers, "executor": executor, "settings": settings,
    }


def _import_ray() -> Any:
    try:
        import ray  # optional dependency: ray (extra 'ray')
    except ImportError:
        raise ConfigError("executor 'ray' needs Ray, an optional extra: pip install \"wearpose[ray]\" "
                          "(or use the default local executor)") from None
    return ray


def _ray_init(ray: Any, address: str | None) -> None:
    if ray.is_initialized():
        return
    address = address or os.environ.get("RAY_ADDRESS") or None
    # Without an address Ray starts a local instance for this run (no dashboard, quiet).
    ray.init(address=address, include_dashboard=False, log_to_driver=False, ignore_reinit_error=True,
             **({} if address else {"num_cpus": os.cpu_count() or 1}))


def _run_jobs(todo: list[dict[str, Any]], n_workers: int, body: str | None, executor: str,
              ray_address: str | None) -> Iterable[tuple[dict[str, Any], dict[str, Any]]]:
    """Run ``_simulate_one`` on every job; yields ``(job, result)`` in completion order."""
    def payload(job: dict[str, Any]) -> dict[str, Any]:
        return {k: v for k, v in job.items() if k != "_row"}

    if executor == "ray":
        import ray  # optional dependency: ray (extra 'ray')
        from ray.util import ActorPool  # optional dependency: ray (extra 'ray')

        @ray.remote(num_cpus=1)
        class _Worker:  # one body model per actor, loaded once (as the process pool's initialiser)
            def __init__(self, body: str | None) -> None:
                _init_worker(body)

            def run(self, job: dict[str, Any]) -> dict[str, Any]:
                return _simulate_one(job)

        pool = ActorPool([_Worker.remote(body) for _ in range(min(n_workers, len(todo)))])
        by_id = {j["id"]: j for j in todo}
        for res in pool.map_unordered(lambda a, j: a.run.remote(j), [payload(j) for j in todo]):
            yield by_id[res["id"]], res
        return
    if n_workers <= 1:
        threads = torch.get_num_threads()
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                _init_worker(body, quiet=False)
                for job in todo:
                    yield job, _simulate_one(job)
        finally:
            torch.set_num_threads(threads)
        return
    # "spawn": forking a parent that already ran torch can deadlock its OpenMP pool.
    ctx = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(max_workers=n_workers, mp_context=ctx, initializer=_init_worker, initargs=(body,)) as ex:
        futures = {ex.submit(_simulate_one, payload(job)): job for job in todo}
        for fut in as_completed(futures):
            job = futures[fut]
            try:
                res = fut.result()
            except Exception as exc:  # noqa: BLE001 - a crashed worker (e.g. out of memory) fails its clip only
                res = {"id": job["id"], "ok": False, "error": f"worker crashed: {type(exc).__name__}: {exc} (a worker "
                       "process died: out of memory, or a script without `if __name__ == '__main__':` that "
                       "'spawn' cannot re-import; workers=1 runs in this process)"}
            yield job, res


def _body_asset_id(body: str | None) -> str:
    """The body asset, identified by content: a rebuilt asset (e.g. new sites) changes the key."""
    if body is None or body == "default":
        path, name = DEFAULT_ASSET, load_default_asset().asset_id
    else:
        path = Path(os.environ.get("WEARPOSE_SMPL_MODEL", "")) if body == "smpl" else Path(body)
        name = body
    if path.is_file():
        return f"{name}:{hashlib.sha1(path.read_bytes()).hexdigest()[:10]}"
    return str(name)


def _read_index(path: Path) -> dict[str, Any] | None:
    if not path.is_file():
        return None
    try:
        idx = json.loads(path.read_text(encoding="utf-8"))
    except (ValueError, OSError) as exc:
        raise InputFileError(path, f"unreadable index ({exc})", f"a {SET_FORMAT} index.json, or an empty directory") from exc
    if not isinstance(idx, dict) or idx.get("format") != SET_FORMAT:
        raise InputFileError(path, f"format {idx.get('format') if isinstance(idx, dict) else type(idx).__name__!r}",
                             f"a {SET_FORMAT} index.json (is this the right output directory?)", field="format")
    if idx.get("version") != SET_VERSION:
        raise InputFileError(path, f"version {idx.get('version')!r}", f"version {SET_VERSION}", field="version")
    return idx


def _write_index(path: Path, settings: dict[str, Any], key: str, clips: dict[str, Any], failures: dict[str, str],
                 include_nc: bool, store: Any) -> None:
    lic: dict[str, int] = {}
    for row in clips.values():
        lic[str(row.get("licence"))] = lic.get(str(row.get("licence")), 0) + 1
    index = {
        "format": SET_FORMAT, "version": SET_VERSION, "settings": settings, "settings_key": key,
        "corpus": str(store.root), "include_nc": include_nc,
        "noncommercial_clips": sum(1 for r in clips.values() if r.get("noncommercial")),
        "licences": dict(sorted(lic.items())),
        "clips": dict(sorted(clips.items())), "failures": dict(sorted(failures.items())),
    }
    atomic_write_text(path, json.dumps(index, indent=1, sort_keys=True))


def load_index(out_dir: str | Path) -> dict[str, Any]:
    """The ``index.json`` of a recording set (:class:`InputFileError` if there is none)."""
    path = Path(out_dir) / INDEX_NAME
    idx = _read_index(path)
    if idx is None:
        raise InputFileError(path, "no recording-set index", "an index.json written by wearpose simulate")
    return idx


__all__ = ["simulate_corpus", "clip_seed", "is_noncommercial", "load_index", "usable_cores"]
