"""Timing helpers shared by the benchmarks: a machine reference, latency statistics, the machine's
state, and an older checkout of the library imported beside this one.

Machines of one kind differ by 3x in speed (issue 25), so every timing result records
:func:`reference_timing` (a fixed float32 matrix-product loop on one thread) and the load
average, and code versions are compared as ratios measured in one run (:func:`import_baseline`).
"""

from __future__ import annotations

import dataclasses
import importlib
import itertools
import os
import platform
import subprocess
import sys
import tempfile
import time
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from types import ModuleType
from typing import Any, Callable, Iterator, Sequence

import numpy as np
import torch

from wearpose.errors import ConfigError

#: The reference loop: ``REF_ITERS`` products of two ``REF_SIZE`` x ``REF_SIZE`` float32 matrices.
REF_SIZE = 256
REF_ITERS = 200


def reference_timing(repeats: int = 5) -> dict[str, float]:
    """Time the fixed float32 matmul loop on the current torch threads (best and median of
    ``repeats``), in ms, and the GFLOP/s of the best run. Figures from different machines are
    comparable after dividing by ``best_ms``."""
    g = torch.Generator().manual_seed(0)
    a = torch.randn(REF_SIZE, REF_SIZE, generator=g)
    b = torch.randn(REF_SIZE, REF_SIZE, generator=g)
    out = torch.empty(REF_SIZE, REF_SIZE)
    times = []
    for _ in range(repeats + 1):
        t0 = time.perf_counter()
        for _ in range(REF_ITERS):
            torch.mm(a, b, out=out)
        times.append(time.perf_counter() - t0)
    times = times[1:]  # the first run warms caches and the allocator
    best = min(times)
    return {"loop": f"{REF_ITERS} x float32 ({REF_SIZE}x{REF_SIZE}) @ ({REF_SIZE}x{REF_SIZE})",
            "threads": torch.get_num_threads(), "best_ms": 1000 * best, "median_ms": 1000 * float(np.median(times)),
            "gflops": 2 * REF_SIZE ** 3 * REF_ITERS / best / 1e9}


def latency_stats(seconds: Sequence[float]) -> dict[str, float]:
    """Median / p99 / max (ms) and count of per-call times in seconds."""
    ms = np.asarray(seconds, dtype=np.float64) * 1000
    if ms.size == 0:
        return {"median_ms": float("nan"), "p99_ms": float("nan"), "max_ms": float("nan"), "calls": 0}
    return {"median_ms": float(np.median(ms)), "p99_ms": float(np.percentile(ms, 99)), "max_ms": float(ms.max()),
            "calls": int(ms.size)}


def machine_info() -> dict[str, Any]:
    """Platform, CPU count, torch version and threads, 1/5/15-minute load average now."""
    try:
        load = list(os.getloadavg())
    except (AttributeError, OSError):
        load = []
    return {"platform": platform.platform(), "cpus": os.cpu_count(), "torch": torch.__version__,
            "torch_threads": torch.get_num_threads(), "load_average": load}


def time_calls(fns: dict[str, Callable[[], Any]], repeats: int, warmup: int = 1) -> dict[str, list[float]]:
    """Call every function ``repeats`` times, interleaved (a load spike hits all alike); seconds per call."""
    for fn in fns.values():
        for _ in range(warmup):
            fn()
    out: dict[str, list[float]] = {k: [] for k in fns}
    for _ in range(repeats):
        for k, fn in fns.items():
            t0 = time.perf_counter()
            fn()
            out[k].append(time.perf_counter() - t0)
    return out


def import_baseline(src: str | Path, module: str, package: str = "wearpose") -> ModuleType:
    """Import ``module`` from another checkout's ``src`` folder beside the loaded ``package``.

    The other version's modules are loaded under their own names while this version's are set
    aside, then both sets are restored: the returned module (and everything it imported at
    import time) is the old code; this process keeps using the new one. Imports the old code
    does later, inside functions, resolve to the new package.

    Args:
        src: the other checkout's source folder (e.g. a ``git worktree`` of an older commit + ``/src``).
        module: dotted name inside ``package``, e.g. ``"wearpose.body"``.
    """
    src = str(Path(src).resolve())
    if not (Path(src) / package).is_dir():
        raise FileNotFoundError(f"{src}: no {package}/ package folder here (give the checkout's src/ folder)")
    mine = {k: v for k, v in sys.modules.items() if k == package or k.startswith(package + ".")}
    for k in mine:
        del sys.modules[k]
    sys.path.insert(0, src)
    try:
        mod = importlib.import_module(module)
        theirs = {k: v for k, v in sys.modules.items() if k == package or k.startswith(package + ".")}
    finally:
        sys.path.remove(src)
        for k in [k for k in sys.modules if k == package or k.startswith(package + ".")]:
            del sys.modules[k]
        sys.modules.update(mine)
    if not str(getattr(mod, "__file__", "")).startswith(src):
        raise ImportError(f"{module} came from {getattr(mod, '__file__', '?')}, not from {src}")
    mod.__dict__.setdefault("_baseline_modules", theirs)
    mod.__dict__.setdefault("_baseline_src", src)
    return mod


#: Config fields and estimator attributes that change what one online step costs (recorded beside
#: every figure): EM-POSE's LGD iterations N, BiRAE's MC-dropout samples M, window and online
#: mode, MI-Poser's window and metal-interference mitigation, the networks' widths, PIP's physics,
#: EM-POSE's measurement-consistency refinement (iterations, gate, prior weight and centre) and per-recording
#: shape fit (frames, iterations, prior weight).
COST_SETTINGS = ("iterations", "mc_samples", "window", "online", "physics", "dual_pd", "mim", "hidden", "width",
                 "d_model", "layers", "rnn_layers", "refine_steps", "refine_threshold", "refine_weight", "refine_solver",
                 "refine_centre", "refine_centre_frames",
                 "refine_centre_every", "shape_fit_frames", "shape_fit_steps", "shape_fit_prior")


def cost_settings(est: Any) -> dict[str, Any]:
    """The :data:`COST_SETTINGS` an estimator has, from its attributes first, then its config."""
    cfg = getattr(est, "config", None)
    out: dict[str, Any] = {}
    for key in COST_SETTINGS:
        v = getattr(est, key, None)
        if v is None and cfg is not None:
            v = getattr(cfg, key, None)
        if isinstance(v, (bool, int, float, str)) or (isinstance(v, tuple) and all(isinstance(x, int) for x in v)):
            out[key] = list(v) if isinstance(v, tuple) else v
    return out


def _parse(value: str) -> Any:
    """``--set`` value: ``true``/``false`` (any case) -> bool, ``a,b`` -> int tuple, else int, float or str."""
    if value.lower() in ("true", "false"):
        return value.lower() == "true"
    if "," in value:
        return tuple(int(v) for v in value.split(","))
    for kind in (int, float):
        try:
            return kind(value)
        except ValueError:
            pass
    return value


def apply_settings(est: Any, settings: dict[str, str]) -> None:
    """Change an estimator's cost settings before it runs: ``{"online": "stream", "window":
    "130,30", "mc_samples": "0"}``. A setting goes through the estimator's ``set_<key>`` method
    when it has one (which checks and resets), else its attribute of that name.

    Raises:
        ConfigError: a key that is not a :data:`COST_SETTINGS` name, or one the estimator does
            not have as an attribute (names what it has).
    """
    for key, raw in settings.items():
        value = _parse(raw)
        setter = getattr(est, f"set_{key}", None)
        if key in COST_SETTINGS and callable(setter):
            setter(*value) if isinstance(value, tuple) else setter(value)
        elif key in COST_SETTINGS and getattr(est, key, None) is not None:
            setattr(est, key, value)
        else:
            have = [k for k in COST_SETTINGS
                    if callable(getattr(est, f"set_{k}", None)) or getattr(est, k, None) is not None]
            raise ConfigError(f"--set {key}={raw}: {type(est).__name__} has no setting {key!r} that can be changed "
                              f"after loading (it has: {', '.join(have) or 'none'})")


@dataclass
class Baseline:
    """An older checkout's model, timed beside this one's (:func:`open_baseline`).

    Attributes:
        src: the older checkout's ``src`` folder; commit: its git commit (None if unknown).
        run: that checkout's ``wearpose.estimators.run`` module (:func:`import_baseline`).
        source: its :class:`~wearpose.estimators.run.ModelSource` of the same model.
    """

    src: str
    commit: str | None
    run: ModuleType
    source: Any


@contextmanager
def baseline_modules(mod: ModuleType, package: str = "wearpose") -> Iterator[None]:
    """Run the older checkout's code of :func:`import_baseline`'s ``mod``: its modules stand in
    ``sys.modules`` (and its ``src`` first on ``sys.path``) for the duration, so imports it does
    inside functions (lazy imports, the estimator registry's modules) load its own code; modules
    first imported meanwhile are kept with it. This version's modules are restored after."""
    theirs: dict[str, ModuleType] = mod.__dict__["_baseline_modules"]
    src: str = mod.__dict__["_baseline_src"]
    mine = {k: v for k, v in sys.modules.items() if k == package or k.startswith(package + ".")}
    for k in mine:
        del sys.modules[k]
    sys.modules.update(theirs)
    sys.path.insert(0, src)
    try:
        yield
    finally:
        sys.path.remove(src)
        for k in [k for k in sys.modules if k == package or k.startswith(package + ".")]:
            theirs[k] = sys.modules.pop(k)
        sys.modules.update(mine)


def open_baseline(src: str | Path, model: str) -> Baseline:
    """``model`` (shipped weights name, checkpoint or weight-free estimator) opened by an older
    checkout's code (``src``: its ``src`` folder, e.g. of ``git worktree add /tmp/old <commit>``)."""
    src = str(Path(src).resolve())
    run = import_baseline(src, "wearpose.estimators.run")
    with baseline_modules(run):
        source = run.open_model(model)
    try:
        commit = subprocess.run(["git", "-C", src, "rev-parse", "HEAD"], capture_output=True, text=True,
                                check=True).stdout.strip() or None
    except (OSError, subprocess.CalledProcessError):
        commit = None
    return Baseline(src, commit, run, source)


def _apply_baseline_settings(est: Any, settings: dict[str, str]) -> list[str]:
    """:func:`apply_settings` on the older code's estimator; a setting its code cannot change
    after loading (e.g. EM-POSE's N before ``set_iterations``) is set in its config (and its
    network's, ``model.cfg``) instead. Returns notes naming every such setting."""
    notes = []
    for key, raw in settings.items():
        try:
            apply_settings(est, {key: raw})
        except ConfigError:
            cfg = getattr(est, "config", None)
            if key not in COST_SETTINGS or not dataclasses.is_dataclass(cfg) or not hasattr(cfg, key):
                raise
            est.config = dataclasses.replace(cfg, **{key: _parse(raw)})
            if getattr(getattr(est, "model", None), "cfg", None) is cfg:
                est.model.cfg = est.config
            est.reset()
            notes.append(f"{key} set in the baseline's config (its code has no setter)")
    return notes


@dataclass
class _Run:
    """One estimator stepped through its frames: timings and outputs."""

    label: str
    est: Any
    frames: list[Any]
    wall: list[float] = field(default_factory=list)
    cpu: list[float] = field(default_factory=list)
    parts: dict[str, list[float]] = field(default_factory=dict)
    rots: list[Any] = field(default_factory=list)

    def step(self, k: int, timed: bool, keep: bool) -> None:
        t0, c0 = time.perf_counter(), time.thread_time()
        try:
            pose = self.est.step(self.frames[k])
        except Exception as exc:  # OfflineOnlyError of either version (bidirectional networks)
            if type(exc).__name__ == "OfflineOnlyError":
                raise ConfigError(f"{self.label} has no online step: {exc}") from None
            raise
        if timed:
            self.wall.append(time.perf_counter() - t0)
            self.cpu.append(time.thread_time() - c0)
            for key, v in (getattr(pose, "extras", None) or {}).items():
                if key.endswith("_ms") and isinstance(v, (int, float)):
                    self.parts.setdefault(key, []).append(float(v) / 1000)
        if keep:
            self.rots.append(pose.local_rot)

    def summary(self) -> dict[str, Any]:
        return {"online_ms": latency_stats(self.wall), "online_cpu_ms": latency_stats(self.cpu),
                "stages_ms": {key: latency_stats(v) for key, v in self.parts.items()}}


def _ready(run: ModuleType, source: Any, recording: Any, path: str | Path, settings: dict[str, str],
           baseline: bool) -> tuple[Any, Any, str | None, list[str]]:
    """Estimator of ``source`` readied for ``recording`` by the ``run`` module of one code version."""
    # resample=True: kits mixing rates by design (MI-Poser: 60 Hz headset, 120 Hz EM) are stepped
    # at the trained rate too, as a stream at that rate delivers them (integer decimation only).
    rec, note = run.fit_rate(source, path, recording, True)
    est = source.make()
    if not est.sensor_names:
        raise ConfigError(f"{source.name}: the estimator names its sensors only once it sees a whole recording "
                          "(offline only, e.g. segments); the latency bench times online steps")
    notes = _apply_baseline_settings(est, settings) if baseline else []
    if not baseline:
        apply_settings(est, settings)
    run.start_online(est, rec)
    return est, rec, note, notes


def step_latency(source: Any, recording: Any, *, frames: int = 300, warmup: int = 10,
                 path: str | Path = "<recording>", settings: dict[str, str] | None = None,
                 baseline: Baseline | None = None) -> dict[str, Any]:
    """Online step latency of one model on one recording, as the stream server runs it.

    The recording is brought to the model's rate (:func:`wearpose.estimators.run.fit_rate`, every
    sensor, by integer decimation; a rate that does not decimate is an error), the
    estimator is made once (:meth:`ModelSource.make`), given the recording's subject calibration
    and T-pose window (:func:`wearpose.estimators.run.start_online`), reset, and stepped through
    ``warmup + frames`` frames in order; the first ``warmup`` steps (first allocations, lazy
    set-up) are not counted. Every step is timed in wall time and in the calling thread's CPU
    time (``time.thread_time``, which other processes' load does not inflate).

    With ``baseline`` (:func:`open_baseline`) the older checkout's estimator of the same model is
    readied the same way by its own code and stepped through the same frames, interleaved frame
    by frame (which one goes first alternates), so load hits both alike.

    Args:
        source: a :class:`wearpose.estimators.run.ModelSource` (:func:`~wearpose.estimators.run.open_model`).
        recording: a :class:`wearpose.recording.Recording` with the model's sensors.
        frames: steps timed (fewer when the recording is shorter: ``frames`` in the result says).
        settings: cost settings changed before the run (:func:`apply_settings`; on the baseline too).
        baseline: an older version of the model to time beside it.

    Returns:
        ``model``, ``method``, ``kit``, ``rate_hz``, ``frame_period_ms``, ``settings``
        (:func:`cost_settings`), ``online_ms`` and ``online_cpu_ms`` (:func:`latency_stats`: the
        same keys for every method), ``stages_ms`` (the same statistics of every ``*_ms`` timing
        the estimator reports in its frames' ``extras``, e.g. PIP's ``kin_ms`` / ``physics_ms``),
        ``p99_within_frame_period``, ``frames``, ``warmup``, ``note``; with a baseline also
        ``baseline`` (``src``, ``commit``, its ``settings``, ``notes`` and the same statistics),
        ``speedup`` (baseline / this version: ``median``, ``p99``, ``cpu_median``) and
        ``max_abs_diff_local_rot`` (largest difference of the two versions' output rotations).
    """
    # start-up: estimators.run adds ~54 ms (27 modules) to import this module
    from wearpose.estimators import run as this_run
    from wearpose.estimators.base import iter_frames  # start-up: as above

    settings = settings or {}
    old: _Run | None = None
    notes: list[str] = []
    with tempfile.TemporaryDirectory() as tmp:
        if baseline is not None:
            # The recording crosses to the older code as a file (its own classes check their inputs'
            # types); both versions read that file, each with its own loader: the same samples.
            # start-up: recording adds ~49 ms (25 modules) to import this module
            from wearpose.recording import load_recording, save_recording

            file = save_recording(recording, Path(tmp) / "rec.npz")
            recording = load_recording(file)
            with baseline_modules(baseline.run):
                # the baseline's own modules, looked up inside baseline_modules (not this version's)
                old_iter_frames = importlib.import_module("wearpose.estimators.base").iter_frames
                old_load = importlib.import_module("wearpose.recording").load_recording

                old_est, old_rec, _, notes = _ready(baseline.run, baseline.source, old_load(file), path, settings, True)
                old_frames = itertools.islice(old_iter_frames(old_rec, old_est.sensor_names), warmup + frames)
                old = _Run(f"{source.name} (baseline)", old_est, list(old_frames))
        est, rec, note, _ = _ready(this_run, source, recording, path, settings, False)
        new = _Run(source.name, est, list(itertools.islice(iter_frames(rec, est.sensor_names), warmup + frames)))
    runs = [new] if old is None else [new, old]
    n = min(len(r.frames) for r in runs)
    for k in range(n):
        for r in (runs if k % 2 == 0 else runs[::-1]):
            if r is old:
                with baseline_modules(baseline.run):
                    r.step(k, k >= warmup, True)
            else:
                r.step(k, k >= warmup, old is not None)
    rate = float(est.fps) if getattr(est, "fps", 0) else float(rec.sensor(est.sensor_names[0]).info.rate)
    res = {"model": source.name, "method": source.method, "kit": source.kit or getattr(est, "kit", None),
           "rate_hz": rate, "frame_period_ms": 1000.0 / rate, "settings": cost_settings(est), **new.summary()}
    res.update({"p99_within_frame_period": bool(res["online_ms"]["p99_ms"] <= 1000.0 / rate),
                "frames": len(new.wall), "warmup": warmup, "note": note})
    if old is not None:
        b = old.summary()
        res["baseline"] = {"src": baseline.src, "commit": baseline.commit, "settings": cost_settings(old.est),
                           "notes": notes, **b}
        res["speedup"] = {"median": b["online_ms"]["median_ms"] / res["online_ms"]["median_ms"],
                          "p99": b["online_ms"]["p99_ms"] / res["online_ms"]["p99_ms"],
                          "cpu_median": b["online_cpu_ms"]["median_ms"] / res["online_cpu_ms"]["median_ms"]}
        res["max_abs_diff_local_rot"] = max(float((a.float() - c.float()).abs().max())
                                            for a, c in zip(new.rots, old.rots))
    return res


__all__ = ["reference_timing", "latency_stats", "machine_info", "time_calls", "import_baseline",
           "baseline_modules", "Baseline", "open_baseline", "COST_SETTINGS", "cost_settings", "apply_settings",
           "step_latency"]
