"""Generic training loop shared by the estimators.

:func:`train` runs a :class:`TrainTask` with Adam, a per-step learning-rate schedule (constant,
cosine, or exponential ``lr * lr_decay ** (step / lr_decay_steps)`` as TensorFlow's
``exponential_decay``), global gradient-norm clipping, validation after every epoch, ``best.pt`` (lowest
validation metric) and ``last.pt`` (every ``checkpoint_every`` steps and every epoch, with the
optimiser state) checkpoints, resume from ``last.pt`` (mid-epoch: the batch order of an epoch
is a function of the seed and the epoch, so the batches already done are skipped), a
JSON-lines log (``log.jsonl``) and rich progress. It runs unchanged on CUDA when available.

Distributed: started by ``torchrun`` (``WORLD_SIZE`` > 1 in the environment), the same call
trains with :class:`~torch.nn.parallel.DistributedDataParallel` (gloo on CPU, NCCL on CUDA).
Every rank draws the same global batch (the batch order is a function of seed and epoch) and
trains on its slice along the leading dimension (:func:`shard_batch`); the loss is re-weighted
by the slice's share so the gradient DDP averages equals the single-process gradient of the
global batch. Rank 0 validates, logs and saves checkpoints. The global batch is therefore the
same for any number of processes: adding processes divides the work per step, not the batch.
Batch norm statistics are per rank (one slice), the one known difference to a 1-process run.

Run setup shared by the methods' ``train_*`` functions: :func:`train_estimator` (build the
train/val splits, resume bookkeeping, device, :class:`TrainSettings` from the method config, then
:func:`train`), :func:`resume_provenance`, :func:`loop_settings`, and :class:`WindowTask`, the
window batching / epoch seeding / checkpointing common to the window-based tasks.
"""

from __future__ import annotations

import json
import math
import os
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Callable, Iterable, Protocol

import torch
from torch import nn

from wearpose.estimators.checkpoint import load_checkpoint, save_checkpoint
from wearpose.estimators.clipstore import num_batches
from wearpose.estimators.seeding import step_seed
from wearpose.estimators.trainconfig import TrainConfig
from torch.nn.parallel import DistributedDataParallel
from wearpose.errors import ConfigError
import torch.distributed as dist


class TrainTask(Protocol):
    """What :func:`train` needs from a method.

    ``loss`` must run the network through ``self.model`` (not a private reference): under
    torchrun :func:`train` swaps ``task.model`` for its DistributedDataParallel wrapper while it
    trains, and restores the plain module for ``validate`` and ``save``. ``batches`` yields
    tensors, or dicts / lists / tuples of tensors, with the batch as leading dimension.
    """

    model: nn.Module
    val_metric: str  #: key of :meth:`validate`'s result to minimise

    def num_batches(self) -> int: ...

    def batches(self, epoch: int, skip: int) -> Iterable[Any]: ...

    def loss(self, batch: Any, device: torch.device) -> tuple[torch.Tensor, dict[str, float]]: ...

    def validate(self, device: torch.device) -> dict[str, float]: ...

    def save(self, path: Path, meta: dict[str, Any], train_state: dict[str, Any] | None) -> None: ...


@dataclass
class TrainSettings:
    """Loop settings. ``threads``: torch CPU threads (None = torch default); ``device``:
    ``"auto"`` (CUDA if available) or a device string; ``max_steps``: stop after this many
    optimiser steps in total (tests); ``log_every``: steps between log lines. ``seed``: base
    seed of the network's own draws during training (dropout): torch's global generator is
    seeded with :func:`~wearpose.estimators.seeding.step_seed` before every step, so a run is a
    function of its seed and a resumed run draws what the uninterrupted one drew (None: torch's
    generator is left alone, the run is not reproducible). ``lr_schedule``:
    ``"constant"``, ``"cosine"`` (to ``lr_min_factor * lr`` over all epochs) or ``"exp"``
    (``lr * lr_decay ** (step / lr_decay_steps)``, continuous; independent of the run length,
    so a resumed or extended run keeps the same curve)."""

    out_dir: Path
    epochs: int
    lr: float
    lr_schedule: str = "constant"
    lr_min_factor: float = 0.1
    grad_clip: float = 1.0
    resume: bool = False
    threads: int | None = None
    device: str = "auto"
    checkpoint_every: int = 100
    log_every: int = 20
    max_steps: int | None = None
    quiet: bool = False
    lr_decay: float = 0.9
    lr_decay_steps: int = 5000
    seed: int | None = None


def resolve_device(device: str) -> torch.device:
    if device == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    return torch.device(device)


def dist_info() -> tuple[int, int, int]:
    """``(rank, world_size, local_rank)`` from torchrun's environment (``(0, 1, 0)`` when not distributed)."""
    world = int(os.environ.get("WORLD_SIZE", "1"))
    return int(os.environ.get("RANK", "0")), world, int(os.environ.get("LOCAL_RANK", "0"))


def shard_batch(batch: Any, rank: int, world: int) -> tuple[Any, float]:
    """This rank's contiguous slice of ``batch`` along the leading dimension and its weight.

    Args:
        batch: a tensor ``(B, ...)``, or a dict / list / tuple of them (non-tensors are kept whole).
        rank, world: this process and the number of processes.

    Returns:
        ``(slice, weight)`` with ``weight = world * b / B`` (``b`` the slice size): scaling a
        mean-reduced loss by it makes DDP's gradient average equal the global-batch gradient,
        also when ``B`` is not a multiple of ``world``.

    Raises:
        ConfigError: when the batch has fewer samples than processes, or tensors disagree on ``B``.
    """

    sizes: set[int] = set()

    def scan(x: Any) -> None:
        if isinstance(x, torch.Tensor) and x.dim() > 0:
            sizes.add(int(x.shape[0]))
        elif isinstance(x, dict):
            for v in x.values():
                scan(v)
        elif isinstance(x, (list, tuple)):
            for v in x:
                scan(v)

    scan(batch)
    if len(sizes) != 1:
        raise ConfigError(f"distributed training: batch tensors must share one leading batch size, got {sorted(sizes)}")
    B = sizes.pop()
    if B < world:
        raise ConfigError(f"distributed training: global batch of {B} samples cannot feed {world} processes; "
                          f"use a batch size >= the number of processes")
    lo, hi = rank * B // world, (rank + 1) * B // world

    def cut(x: Any) -> Any:
        if isinstance(x, torch.Tensor) and x.dim() > 0:
            return x[lo:hi]
        if isinstance(x, dict):
            return {k: cut(v) for k, v in x.items()}
        if isinstance(x, (list, tuple)):
            return type(x)(cut(v) for v in x)
        return x

    return cut(batch), world * (hi - lo) / B


def _lr_at(s: TrainSettings, step: int, total: int) -> float:
    if s.lr_schedule == "cosine" and total > 0:
        f = min(1.0, step / total)
        return s.lr * (s.lr_min_factor + (1 - s.lr_min_factor) * 0.5 * (1 + math.cos(math.pi * f)))
    if s.lr_schedule == "exp" and s.lr_decay_steps > 0:
        return s.lr * s.lr_decay ** (step / s.lr_decay_steps)
    return s.lr


def train(task: TrainTask, s: TrainSettings, console: Any = None) -> dict[str, Any]:
    """Train ``task.model`` (see module doc). Returns ``{"best": ..., "history": [...],
    "out_dir": ..., "steps": ...}``; the epoch history rows are also in ``log.jsonl``."""
    from rich.console import Console  # start-up: rich adds ~75 ms (58 modules) to import this module
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn  # start-up: rich adds ~75 ms (58 modules) to import this module

    rank, world, local_rank = dist_info()
    distributed = world > 1
    lead = rank == 0
    console = console or Console(quiet=s.quiet)
    if not lead:
        console = Console(quiet=True)
    if s.threads:
        torch.set_num_threads(int(s.threads))
    device = resolve_device(s.device)
    if distributed and device.type == "cuda":
        device = torch.device("cuda", local_rank)
        torch.cuda.set_device(device)
    out = Path(s.out_dir)
    out.mkdir(parents=True, exist_ok=True)
    raw = task.model
    raw.to(device)
    opt = torch.optim.Adam(raw.parameters(), lr=s.lr)
    own_group = False
    if distributed:

        if not dist.is_initialized():
            dist.init_process_group("nccl" if device.type == "cuda" else "gloo")
            own_group = True
        # find_unused_parameters: a method may leave parts of its network out of some steps
        # (e.g. heads used only in validation); DDP would otherwise stop with a reduction error.
        ddp = DistributedDataParallel(raw, device_ids=[device.index] if device.type == "cuda" else None,
                                      find_unused_parameters=True)
    nb = task.num_batches()
    total = s.epochs * nb
    epoch, skip, gstep, best, history = 0, 0, 0, math.inf, []
    last = out / "last.pt"
    if s.resume and last.is_file():
        ck = load_checkpoint(last, map_location=device)
        raw.load_state_dict(ck.weights)
        st = ck.train_state or {}
        if st.get("optimizer"):
            opt.load_state_dict(st["optimizer"])
        epoch, skip, gstep = int(st.get("epoch", 0)), int(st.get("step_in_epoch", 0)), int(st.get("global_step", 0))
        best, history = float(st.get("best", math.inf)), list(st.get("history", []))
        console.print(f"resumed from {last}: epoch {epoch + 1}, batch {skip}/{nb}, step {gstep}")
    log = open(out / "log.jsonl", "a", encoding="utf-8") if lead else None

    def write(row: dict[str, Any]) -> None:
        if log is not None:
            log.write(json.dumps(row) + "\n")
            log.flush()

    def save(path: Path, meta: dict[str, Any], st: dict[str, Any] | None) -> None:
        if lead:
            task.save(path, meta, st)

    def state(ep: int, k: int) -> dict[str, Any]:
        return {"epoch": ep, "step_in_epoch": k, "global_step": gstep, "optimizer": opt.state_dict(),
                "best": best, "history": history, "settings": {k2: str(v) for k2, v in asdict(s).items()}}

    write({"type": "start", "time": time.time(), "device": str(device), "threads": torch.get_num_threads(), "world_size": world,
           "batches_per_epoch": nb, "epochs": s.epochs, "resume_epoch": epoch, "resume_step": skip})
    stop = False
    with Progress(TextColumn("[bold]epoch {task.fields[ep]}"), BarColumn(), TextColumn("{task.completed}/{task.total}"),
                  TextColumn("loss {task.fields[loss]:.4f}"), TimeElapsedColumn(), TimeRemainingColumn(),
                  console=console, disable=s.quiet or not lead) as prog:
        while epoch < s.epochs and not stop:
            bar = prog.add_task("train", total=nb, completed=skip, ep=epoch + 1, loss=float("nan"))
            t0, run, n = time.time(), 0.0, 0
            raw.train()
            if distributed:
                task.model = ddp
            for k, batch in enumerate(task.batches(epoch, skip), start=skip):
                for g in opt.param_groups:
                    g["lr"] = _lr_at(s, gstep, total)
                if s.seed is not None:  # dropout masks: a function of the seed and the step (issue 24)
                    torch.manual_seed(step_seed(s.seed, gstep))
                weight = 1.0
                if distributed:
                    batch, weight = shard_batch(batch, rank, world)
                loss, parts = task.loss(batch, device)
                opt.zero_grad(set_to_none=True)
                (loss * weight if distributed else loss).backward()
                gnorm = float(torch.nn.utils.clip_grad_norm_(raw.parameters(), s.grad_clip)
                              if s.grad_clip > 0 else 0.0)
                opt.step()
                gstep += 1
                loss = loss.detach()
                if distributed:  # the global-batch mean, for the log and the progress bar
                    loss = loss * weight
                    dist.all_reduce(loss)
                    loss = loss / world
                run, n = run + float(loss), n + 1
                prog.update(bar, completed=k + 1, loss=run / n)
                if gstep % s.log_every == 0:
                    row = {"type": "step", "epoch": epoch + 1, "batch": k + 1, "step": gstep, "loss": float(loss),
                           "grad_norm": gnorm, "lr": opt.param_groups[0]["lr"], **parts,
                           "sec_per_step": (time.time() - t0) / n}
                    write(row)
                    if not console.is_terminal:
                        console.print(f"epoch {epoch + 1} batch {k + 1}/{nb} loss {run / n:.5f} "
                                      f"({row['sec_per_step']:.2f} s/step)")
                if gstep % s.checkpoint_every == 0:
                    save(last, {"epoch": epoch + 1, "batch": k + 1}, state(epoch, k + 1))
                if s.max_steps is not None and gstep >= s.max_steps:
                    stop = True
                    break
            prog.remove_task(bar)
            task.model = raw
            if stop and k + 1 < nb:
                save(last, {"epoch": epoch + 1, "batch": k + 1}, state(epoch, k + 1))
                break
            tv = time.time()
            val = task.validate(device) if lead else {}
            if distributed:  # every rank needs the same view of the validation result
                box = [val]
                dist.broadcast_object_list(box, src=0)
                val = box[0]
            row = {"type": "epoch", "epoch": epoch + 1, "train_loss": run / max(n, 1), **val,
                   "train_seconds": tv - t0, "val_seconds": time.time() - tv, "steps": gstep,
                   "lr": opt.param_groups[0]["lr"]}
            history.append(row)
            write(row)
            console.print(" ".join(f"{k2}={v:.4g}" if isinstance(v, float) else f"{k2}={v}" for k2, v in row.items()
                                   if k2 != "type"))
            epoch, skip = epoch + 1, 0
            if val.get(task.val_metric, math.inf) < best:
                best = val[task.val_metric]
                save(out / "best.pt", {"epoch": epoch, **val}, None)
            save(last, {"epoch": epoch, **val}, state(epoch, 0))
    task.model = raw
    if log is not None:
        log.close()
    if distributed:
        del ddp  # its reducer holds the process group: the group must not die with it (below)
        _teardown_process_group(own_group)
    return {"best": best, "history": history, "out_dir": str(out), "steps": gstep}


def _teardown_process_group(own_group: bool) -> None:
    """Wait for every rank, then destroy the process group (when ``train`` created it).

    Why the wait before destroying (issue 20): in torch 2.13, ``~ProcessGroupGloo`` takes the
    group's work mutex on the thread that drops the last reference, with the GIL held, while a
    gloo worker thread that has just completed a collective holds that mutex and waits for the
    GIL to free the work's Python-owned tensors: a lock-order deadlock. It was caught with
    ``py-spy dump --native`` (1 run in 30 of a 2-rank EM-POSE run, main thread in
    ``Reducer::~Reducer -> ~ProcessGroupGloo -> pthread_mutex_lock``, worker in
    ``~AsyncBarrierWork -> decref_pyobject -> gil_scoped_acquire``); the group died with the DDP
    wrapper when ``train`` returned, right after the final barrier. So the group is dropped only
    once the workers are idle: a sleep releases the GIL to them after the barrier (they need it
    for microseconds; 0.2 s leaves room for a loaded machine).
    """

    dist.barrier()
    time.sleep(0.2)
    if own_group:
        dist.destroy_process_group()


# --------------------------------------------------------------------------- run setup of the estimators


class WindowTask:
    """The part of a :class:`TrainTask` common to methods trained on fixed-length windows of
    their training data: ``__init__(est, train_data, val_data)``, :meth:`num_batches`,
    :meth:`batches` (the order of an epoch is seeded by ``config.seed`` and the epoch, so a
    resumed run skips the batches it did) and :meth:`save` (``est.checkpoint(meta, train_state)``).

    Subclasses give :meth:`window` (and :meth:`window_options` for keyword options of the
    data's windowing) and the ``loss`` / ``validate`` / ``val_metric`` of :class:`TrainTask`.
    The data must have ``windows(length, stride, **options)`` and
    ``iter_batches(length, stride, batch_size, generator, skip=..., **options)`` (as
    :class:`~wearpose.estimators.empose.data.EmposeData`).
    """

    def __init__(self, est: Any, train_data: Any, val_data: Any | None) -> None:
        self.est, self.cfg = est, est.config
        self.model = est.model
        self.train_data, self.val_data = train_data, val_data
        self._nw = len(train_data.windows(*self.window(), **self.window_options()))

    def window(self) -> tuple[int, int]:
        """``(length, stride)`` of the training windows, frames."""
        raise NotImplementedError

    def window_options(self) -> dict[str, Any]:
        """Keyword options of the data's ``windows`` / ``iter_batches`` (none by default)."""
        return {}

    def num_batches(self) -> int:
        return num_batches(self._nw, self.cfg.batch_size)

    def batches(self, epoch: int, skip: int) -> Iterable[Any]:
        g = torch.Generator().manual_seed(self.cfg.seed * 100_003 + epoch)
        return self.train_data.iter_batches(*self.window(), self.cfg.batch_size, g, skip=skip, **self.window_options())

    def save(self, path: Path, meta: dict[str, Any], train_state: dict[str, Any] | None) -> None:
        save_checkpoint(self.est.checkpoint(meta, train_state), path)


def loop_settings(cfg: TrainConfig, out_dir: str | Path, epochs: int, *, lr: float | None = None,
                  **loop: Any) -> TrainSettings:
    """:class:`TrainSettings` from a method config's optimisation fields (its
    :class:`~wearpose.estimators.trainconfig.TrainConfig` ``lr``, ``lr_schedule``,
    ``lr_min_factor``, ``grad_clip``, ``seed``, and ``lr_decay`` / ``lr_decay_steps`` where the
    config has them) and the run's ``loop`` options (``resume``, ``threads``, ``device``,
    ``checkpoint_every``, ``max_steps``, ``quiet``). ``lr`` overrides ``cfg.lr``."""
    decay = {k: getattr(cfg, k) for k in ("lr_decay", "lr_decay_steps") if hasattr(cfg, k)}
    return TrainSettings(out_dir=Path(out_dir), epochs=epochs, lr=lr or cfg.lr, lr_schedule=cfg.lr_schedule,
                         lr_min_factor=cfg.lr_min_factor, grad_clip=cfg.grad_clip, seed=cfg.seed, **decay, **loop)


def resume_provenance(est: Any, last: Path, *, resume: bool, train_command: str, console: Any) -> None:
    """Record who trained ``est``, before :func:`train` continues or starts the run.

    Resuming from an existing ``last``: the checkpoint must fit ``est`` (method, kit, body asset:
    :class:`~wearpose.estimators.checkpoint.CheckpointMismatchError` otherwise), a config other
    than the checkpoint's is warned about, ``est.train_command`` stays the command that started
    the run and ``train_command`` goes to ``est.meta["resumed_with"]``. Otherwise a non-empty
    ``train_command`` becomes ``est.train_command``.
    """
    if resume and last.is_file():
        prev = load_checkpoint(last)
        prev.check(method=est.name, kit=est.kit_name, body_asset=est.body_asset_id, path=last)
        if prev.config != est.config.to_dict():
            console.print(f"[yellow]warning[/]: resuming {last} with a different config than it was trained with")
        est.train_command = prev.train_command  # the command that started the run
        est.meta["resumed_with"] = train_command
    elif train_command:
        est.train_command = train_command


def train_estimator(est: Any, out_dir: str | Path, build: Callable[..., Any], make_task: Callable[[Any, Any], TrainTask],
                    *, label: str, epochs: int | None = None, resume: bool = False, threads: int | None = None,
                    device: str = "auto", limit_train: int | None = None, limit_val: int | None = None,
                    max_steps: int | None = None, checkpoint_every: int = 100, train_command: str = "",
                    quiet: bool = False, store: Any = None, cache_root: str | Path | None = None, console: Any = None,
                    progress_every: int = 200, val_frames: bool = True,
                    recipe: dict[str, Any] | None = None, init_from: str | Path | None = None) -> dict[str, Any]:
    """Build the data of a method, set the run up and train ``est`` in place with :func:`train`.

    In order: torch CPU ``threads``; the train and val splits (``build``, progress printed every
    ``progress_every`` clips); ``est.data_fingerprint`` = the training data's;
    :func:`resume_provenance` of ``<out_dir>/last.pt``; ``est.meta`` gets the clip and frame
    counts (and ``train_sources`` for a store restricted to some sources); the task;
    ``est.to(device)``; :func:`train` with :func:`loop_settings`.

    Args:
        est: the estimator: ``config`` (with ``kit``, ``rate``, ``epochs``, ``val_clips`` and the
            fields of :func:`loop_settings`), ``name``, ``kit_name``, ``body_asset_id``,
            ``data_fingerprint``, ``train_command``, ``meta`` and ``to(device)``.
        out_dir: run directory (``last.pt``, ``best.pt``, ``log.jsonl``).
        build: ``build(split, store=, limit=, cache_root=, progress=)`` -> data with
            ``clip_ids``, ``num_frames`` and ``fingerprint``.
        make_task: ``(train_data, val_data)`` -> the :class:`TrainTask`.
        label: the method's name in the log (``"PIP"``).
        epochs: override ``config.epochs``.
        limit_train / limit_val: N clips of the split (default all / ``config.val_clips``, 0 = all).
        max_steps: stop after N optimiser steps (tests).
        val_frames: also print the validation frame count.
        recipe: the recipe the run was started from (``est.meta["recipe"]``, so in every checkpoint).
        init_from: start from this checkpoint's weights (``est.warm_start``; ignored when resuming:
            ``last.pt`` holds the run's own weights).
        The other options are :class:`TrainSettings`'.

    Returns:
        :func:`train`'s result.
    """
    from rich.console import Console  # start-up: rich adds ~75 ms (58 modules) to import this module

    console = console or Console(quiet=quiet)
    if threads:
        torch.set_num_threads(int(threads))
    cfg = est.config
    prog = (lambda d, t: console.print(f"  simulated {d}/{t} clips") if (d % progress_every == 0 or d == t) else None)  # noqa: E731
    console.print(f"{label} data: simulating/loading train split ({cfg.kit}, {cfg.rate:g} Hz)")
    tr = build("train", store=store, limit=limit_train, cache_root=cache_root, progress=prog)
    va = build("val", store=store, limit=limit_val if limit_val is not None else (cfg.val_clips or None),
               cache_root=cache_root, progress=prog)
    val = f"{len(va.clip_ids)} clips, {va.num_frames} frames" if val_frames else f"{len(va.clip_ids)} clips"
    console.print(f"train: {len(tr.clip_ids)} clips, {tr.num_frames} frames; val: {val}; fingerprint {tr.fingerprint[:16]}")
    est.data_fingerprint = tr.fingerprint
    resume_provenance(est, Path(out_dir) / "last.pt", resume=resume, train_command=train_command, console=console)
    est.meta.update({"train_clips": len(tr.clip_ids), "train_frames": tr.num_frames, "val_clips": len(va.clip_ids)})
    if getattr(store, "sources_only", None):  # `--source`: one lab's clips (CorpusStore.subset)
        est.meta["train_sources"] = list(store.sources_only)
    if recipe is not None:
        est.meta["recipe"] = dict(recipe)
    if init_from is not None and not resume:
        est.warm_start(init_from)
        console.print(f"initial weights from {init_from}")
    task = make_task(tr, va)
    est.to(resolve_device(device))  # network and body together: some losses run the body model
    s = loop_settings(cfg, out_dir, epochs or cfg.epochs, resume=resume, threads=threads, device=device,
                      checkpoint_every=checkpoint_every, max_steps=max_steps, quiet=quiet)
    return train(task, s, console)
