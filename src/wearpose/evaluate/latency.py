"""Timing helpers shared by the benchmarks: a machine reference, latency statistics, the machine's
state, and an older checkout of the library imported beside this one.

Machines of one kind differ by 3x in speed (issue 25), so every timing result records
:func:`reference_timing` (a fixed float32 matrix-product loop on one thread) and the load
average, and code versions are compared as ratios measured in one run (:func:`import_baseline`).
"""

from __future__ import annotations

import importlib
import os
import platform
import sys
import time
from pathlib import Path
from types import ModuleType
from typing import Any, Callable, Sequence

import numpy as np
import torch

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
    return mod


#: Config fields and estimator attributes that change what one online step costs (recorded beside
#: every figure): EM-POSE's LGD iterations N, BiRAE's MC-dropout samples M, window and online
#: mode, MI-Poser's window and metal-interference mitigation, the networks' widths, PIP's physics.
COST_SETTINGS = ("iterations", "mc_samples", "window", "online", "physics", "dual_pd", "mim", "hidden", "width",
                 "d_model", "layers", "rnn_layers")


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
    from wearpose.errors import ConfigError

    for key, raw in settings.items():
        value = _parse(raw)
        setter = getattr(est, f"set_{key}", None)
        if key in COST_SETTINGS and callable(setter):
            setter(*value) if isinstance(value, tuple) else setter(value)
        elif key in COST_SETTINGS and getattr(est, key, None) is not None:
            setattr(est, key, value)
        else:
            have = [k for k in COST_SETTINGS if callable(getattr(est, f"set_{k}", None)) or getattr(est, k, None) is not None]
            raise ConfigError(f"--set {key}={raw}: {type(est).__name__} has no setting {key!r} that can be changed "
                              f"after loading (it has: {', '.join(have) or 'none'})")


def step_latency(source: Any, recording: Any, *, frames: int = 300, warmup: int = 10,
                 path: str | Path = "<recording>", settings: dict[str, str] | None = None) -> dict[str, Any]:
    """Online step latency of one model on one recording, as the stream server runs it.

    The recording is brought to the model's rate (:func:`wearpose.estimators.run.fit_rate`, every
    sensor, by integer decimation; a rate that does not decimate is an error), the
    estimator is made once (:meth:`ModelSource.make`), given the recording's subject calibration
    and T-pose window (:func:`wearpose.estimators.run.start_online`), reset, and stepped through
    ``warmup + frames`` frames in order; the first ``warmup`` steps (first allocations, lazy
    set-up) are not counted. Every step is timed in wall time and in the calling thread's CPU
    time (``time.thread_time``, which other processes' load does not inflate).

    Args:
        source: a :class:`wearpose.estimators.run.ModelSource` (:func:`~wearpose.estimators.run.open_model`).
        recording: a :class:`wearpose.recording.Recording` with the model's sensors.
        frames: steps timed (fewer when the recording is shorter: ``frames`` in the result says).
        settings: cost settings changed before the run (:func:`apply_settings`).

    Returns:
        ``model``, ``method``, ``kit``, ``rate_hz``, ``frame_period_ms``, ``settings``
        (:func:`cost_settings`), ``online_ms`` and ``online_cpu_ms`` (:func:`latency_stats`: the
        same keys for every method), ``stages_ms`` (the same statistics of every ``*_ms`` timing
        the estimator reports in its frames' ``extras``, e.g. PIP's ``kin_ms`` / ``physics_ms``),
        ``p99_within_frame_period``, ``frames``, ``warmup``, ``note``.
    """
    from wearpose.estimators.base import iter_frames
    from wearpose.estimators.run import fit_rate, start_online

    from wearpose.errors import ConfigError
    from wearpose.estimators.base import OfflineOnlyError

    # resample=True: kits mixing rates by design (MI-Poser: 60 Hz headset, 120 Hz EM) are stepped
    # at the trained rate too, as a stream at that rate delivers them (integer decimation only).
    rec, note = fit_rate(source, path, recording, True)
    est = source.make()
    if not est.sensor_names:
        raise ConfigError(f"{source.name}: the estimator names its sensors only once it sees a whole recording "
                          "(offline only, e.g. segments); the latency bench times online steps")
    apply_settings(est, settings or {})
    start_online(est, rec)
    wall: list[float] = []
    cpu: list[float] = []
    parts: dict[str, list[float]] = {}  # the estimator's own timings of its stages (PIP: kin_ms, physics_ms)
    for k, frame in enumerate(iter_frames(rec, est.sensor_names)):
        if k >= warmup + frames:
            break
        t0, c0 = time.perf_counter(), time.thread_time()
        try:
            pose = est.step(frame)
        except OfflineOnlyError as exc:  # bidirectional networks (imuposer, empose-birnn)
            raise ConfigError(f"{source.name} has no online step: {exc}") from None
        if k >= warmup:
            wall.append(time.perf_counter() - t0)
            cpu.append(time.thread_time() - c0)
            for key, v in (getattr(pose, "extras", None) or {}).items():
                if key.endswith("_ms") and isinstance(v, (int, float)):
                    parts.setdefault(key, []).append(float(v) / 1000)
    rate = float(est.fps) if getattr(est, "fps", 0) else float(rec.sensor(est.sensor_names[0]).info.rate)
    stats = latency_stats(wall)
    return {"model": source.name, "method": source.method, "kit": source.kit or getattr(est, "kit", None),
            "rate_hz": rate, "frame_period_ms": 1000.0 / rate, "settings": cost_settings(est),
            "online_ms": stats, "online_cpu_ms": latency_stats(cpu),
            "stages_ms": {key: latency_stats(v) for key, v in parts.items()},
            "p99_within_frame_period": bool(stats["p99_ms"] <= 1000.0 / rate), "frames": len(wall),
            "warmup": warmup, "note": note}


__all__ = ["reference_timing", "latency_stats", "machine_info", "time_calls", "import_baseline",
           "COST_SETTINGS", "cost_settings", "apply_settings", "step_latency"]
