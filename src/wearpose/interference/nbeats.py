"""N-BEATS trajectory forecaster of MI-Poser's interference correction (Sec. 3.3, Sec. 4.3).

MI-Poser Eq. 2: ``{x(t0), ..., x(t0 + dt_out)} = N-BEATS({x(t0 - dt_in), ..., x(t0)})`` with
"two stacks where there are two blocks per stack with 512 hidden layer units. The model takes
120 samples (1 s) as input and outputs 60 samples (0.5 s) position data" at 120 Hz, trained
with Adam, batch 16, up to 20 epochs on ~40 min of interference-free sensor motion (Sec. 4.3).

Architecture (Oreshkin et al. 2020, generic blocks): each block is ``layers`` fully connected
ReLU layers of ``width`` units followed by two linear heads, a backcast over the input window
and a forecast over the horizon; a block's input is the previous block's input minus its
backcast, and the forecast is the sum of all blocks' forecasts. N-BEATS is univariate; a 3-D
position is fed as the flattened ``(120, 3)`` window (all axes in one model) -- our choice.

Normalisation (ours): positions are expressed relative to the last input sample ``x(t0)``
(translation invariance) and divided by ``scale`` (0.1 m); the output is the future
displacement from ``x(t0)``.

Presets: ``paper`` (2 x 2 x 512, 4 layers per block, N-BEATS' default depth: 5.0 M parameters,
20 MB float32) and ``cpu`` (2 x 2 x 256: 1.3 M parameters, 5 MB) for this 2-core machine.

Training data (:func:`forecast_windows`): both wrists' trajectories relative to the head-worn
source (the MI-Poser setting), from the corpus train split at 120 Hz, windows of 180 samples.
The corpus motion is interference-free by construction; a white measurement noise (EM-like,
``input_noise``) is added to the input windows only. The caller may hand :func:`train` another
train source (a store and clip ids: ``wearpose train nbeats`` passes the training mix of
:mod:`wearpose.estimators.trainmix`, mirror copies and procedural clips, which this layer does
not import); validation and test windows always come from the corpus splits.
"""

from __future__ import annotations

import hashlib
import json
import math
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

import numpy as np
import torch
from torch import nn

from wearpose.body import BodyModel
from wearpose.errors import ConfigError, ShapeError
from wearpose.interference.trajectories import body_trajectories
from wearpose.motion import CorpusStore
from wearpose import weights  # WEIGHTS_DIR read at call time: tests point it elsewhere


@dataclass(frozen=True)
class NBeatsConfig:
    """N-BEATS forecaster settings (module doc)."""

    input_len: int = 120
    output_len: int = 60
    stacks: int = 2
    blocks: int = 2
    width: int = 256
    layers: int = 4
    scale: float = 0.1
    fps: float = 120.0
    # training
    lr: float = 1e-3
    batch_size: int = 256
    epochs: int = 30
    stride: int = 12
    input_noise: float = 0.002
    val_clips: int = 80
    seed: int = 0
    sites: tuple[str, ...] = ("left_wrist", "right_wrist")

    @staticmethod
    def preset(name: str) -> NBeatsConfig:
        if name == "paper":
            return NBeatsConfig(width=512, batch_size=16, epochs=20)
        if name == "cpu":
            return NBeatsConfig()
        if name == "tiny":
            return NBeatsConfig(width=32, layers=2, epochs=1, val_clips=2)
        raise ConfigError(f"NBeatsConfig.preset: unknown preset {name!r}; expected 'paper', 'cpu' or 'tiny'")

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["sites"] = list(self.sites)
        return d

    @staticmethod
    def from_dict(d: dict[str, Any]) -> NBeatsConfig:
        d = dict(d)
        if "sites" in d:
            d["sites"] = tuple(d["sites"])
        return NBeatsConfig(**d)


class _Block(nn.Module):
    def __init__(self, n_in: int, n_out: int, width: int, layers: int):
        super().__init__()
        mods: list[nn.Module] = []
        d = n_in
        for _ in range(layers):
            mods += [nn.Linear(d, width), nn.ReLU()]
            d = width
        self.fc = nn.Sequential(*mods)
        self.backcast = nn.Linear(width, n_in)
        self.forecast = nn.Linear(width, n_out)

    def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        h = self.fc(x)
        return self.backcast(h), self.forecast(h)


class NBeats(nn.Module):
    """Generic N-BEATS over flattened 3-D positions (module doc).

    ``forward(x)``: ``x`` ``(B, input_len, 3)`` positions (m, any frame) -> ``(B, output_len, 3)``
    forecast positions in the same frame.
    """

    def __init__(self, cfg: NBeatsConfig):
        super().__init__()
        self.cfg = cfg
        n_in, n_out = cfg.input_len * 3, cfg.output_len * 3
        self.blocks = nn.ModuleList(_Block(n_in, n_out, cfg.width, cfg.layers) for _ in range(cfg.stacks * cfg.blocks))

    def forward_normalised(self, z: torch.Tensor) -> torch.Tensor:
        res = z
        out = torch.zeros(z.shape[0], self.cfg.output_len * 3, dtype=z.dtype, device=z.device)
        for b in self.blocks:
            back, fore = b(res)
            res = res - back
            out = out + fore
        return out

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        if x.dim() != 3 or x.shape[1:] != (self.cfg.input_len, 3):
            raise ShapeError(f"NBeats: expected (B, {self.cfg.input_len}, 3), got {tuple(x.shape)}")
        last = x[:, -1:, :]
        z = ((x - last) / self.cfg.scale).reshape(x.shape[0], -1)
        y = self.forward_normalised(z).reshape(x.shape[0], self.cfg.output_len, 3)
        return y * self.cfg.scale + last


class NumpyNBeats:
    """The same forecaster evaluated with numpy float32 matmuls: ~10x less per-call overhead than
    torch for the one-window-per-frame online use (MIM's latency budget)."""

    def __init__(self, model: NBeats):
        self.cfg = model.cfg
        self.blocks = []
        for b in model.blocks:
            fc = [(m.weight.detach().numpy().T.astype(np.float32).copy(), m.bias.detach().numpy().astype(np.float32).copy())
                  for m in b.fc if isinstance(m, nn.Linear)]
            bw = (b.backcast.weight.detach().numpy().T.astype(np.float32).copy(), b.backcast.bias.detach().numpy().astype(np.float32).copy())
            fw = (b.forecast.weight.detach().numpy().T.astype(np.float32).copy(), b.forecast.bias.detach().numpy().astype(np.float32).copy())
            self.blocks.append((fc, bw, fw))

    def __call__(self, x: np.ndarray) -> np.ndarray:
        """``x`` ``(input_len, 3)`` m -> ``(output_len, 3)`` m (same frame)."""
        last = x[-1]
        res = ((x - last) / self.cfg.scale).astype(np.float32).reshape(-1)
        out = np.zeros(self.cfg.output_len * 3, dtype=np.float32)
        for fc, (bw, bb), (fw, fb) in self.blocks:
            h = res
            for w, b in fc:
                h = np.maximum(h @ w + b, 0.0)
            res = res - (h @ bw + bb)
            out += h @ fw + fb
        return out.reshape(self.cfg.output_len, 3).astype(np.float64) * self.cfg.scale + last


def save_forecaster(path: Path, model: NBeats, meta: dict[str, Any], train_state: dict[str, Any] | None = None) -> None:
    torch.save({"format": "wearpose.nbeats", "version": 1, "config": model.cfg.to_dict(),
                "weights": model.state_dict(), "meta": meta, "train_state": train_state}, path)


def load_forecaster(path: str | Path) -> tuple[NBeats, dict[str, Any]]:
    """Load a forecaster checkpoint -> ``(model in eval mode, checkpoint dict)``."""
    ck = torch.load(Path(path), map_location="cpu", weights_only=True)
    if ck.get("format") != "wearpose.nbeats":
        raise ConfigError(f"{path}: not an N-BEATS forecaster checkpoint (format {ck.get('format')!r})")
    model = NBeats(NBeatsConfig.from_dict(ck["config"]))
    model.load_state_dict(ck["weights"])
    model.eval()
    return model, ck


def kept_checkpoint(path: str | Path) -> tuple[dict[str, torch.Tensor], dict[str, Any], str]:
    """A kept forecaster checkpoint as ``(weights, meta, data_fingerprint)``, for comparing a
    recipe's rerun with the weights it made (:func:`wearpose.estimators.recipe.reproduction`);
    the fingerprint is the SHA-256 of the train data's description in ``meta`` (clips per
    source, windows, the mix's settings)."""
    _, ck = load_forecaster(path)
    meta = dict(ck.get("meta") or {})
    data = {k: meta.get(k) for k in ("train_clips", "train_windows", "clips_per_source")}
    data["mix"] = {k: v for k, v in (meta.get("mix") or {}).items() if k != "description"}
    return ck["weights"], meta, hashlib.sha256(json.dumps(data, sort_keys=True).encode()).hexdigest()


def clip_trajectories(motion: Any, body: Any, cfg: NBeatsConfig) -> list[np.ndarray]:
    """Wrist positions relative to the head-worn source at ``cfg.fps``: a list of ``(T, 3)`` float32."""
    tr = body_trajectories(motion, body, cfg.sites, source="head", fps=cfg.fps)
    _, p = tr.relative()
    return [p[:, s].numpy().astype(np.float32) for s in range(p.shape[1])]


def forecast_windows(trajs: list[np.ndarray], cfg: NBeatsConfig) -> np.ndarray:
    """Windows ``(N, input_len + output_len, 3)`` every ``cfg.stride`` samples."""
    L = cfg.input_len + cfg.output_len
    out = [np.lib.stride_tricks.sliding_window_view(t, L, axis=0)[::cfg.stride].transpose(0, 2, 1)
           for t in trajs if t.shape[0] >= L]
    return np.concatenate(out, 0).astype(np.float32) if out else np.zeros((0, L, 3), np.float32)


def spread(ids: Sequence[str], limit: int | None) -> list[str]:
    """At most ``limit`` of ``ids``, evenly spaced over them (all of them when ``limit`` is None)."""
    ids = list(ids)
    return ids if limit is None or len(ids) <= limit else ids[:: max(1, len(ids) // limit)][:limit]


def split_windows(split: str, cfg: NBeatsConfig, limit: int | None = None, store: Any = None,
                  ids: Sequence[str] | None = None,
                  progress: Callable[[int, int], None] | None = None) -> tuple[np.ndarray, list[str]]:
    """Windows of every clip of a corpus split (``limit`` clips at most, spread over the split).

    Args:
        store: what clips are loaded from (``load(id) -> MotionSequence``; default: the prepared
            corpus, :class:`~wearpose.motion.CorpusStore`).
        ids: the clips to window (default: ``store``'s clips of ``split``); ``limit`` applies to
            either.
        progress: ``progress(done, total)`` after each clip.
    """
    store = CorpusStore() if store is None else store
    clips = spread(sorted(store.clips(split=split)) if ids is None else list(ids), limit)
    body = BodyModel()
    trajs: list[np.ndarray] = []
    for i, cid in enumerate(clips):
        trajs += clip_trajectories(store.load(cid), body, cfg)
        if progress is not None:
            progress(i + 1, len(clips))
    return forecast_windows(trajs, cfg), clips


def _batches(w: np.ndarray, cfg: NBeatsConfig, rng: np.random.Generator, noise: bool):
    for i in range(0, len(w), cfg.batch_size):
        b = torch.from_numpy(w[i:i + cfg.batch_size])
        x, y = b[:, :cfg.input_len], b[:, cfg.input_len:]
        if noise and cfg.input_noise > 0:
            x = x + torch.from_numpy(rng.normal(0, cfg.input_noise, size=x.shape).astype(np.float32))
        yield x, y


def evaluate_forecaster(model: NBeats, windows: np.ndarray, batch: int = 1024) -> dict[str, float]:
    """Mean absolute error per coordinate (MI-Poser's figure, cm), mean 3-D error and at 0.5 s."""
    model.eval()
    mae, e3, e_end, n = 0.0, 0.0, 0.0, 0
    with torch.no_grad():
        for i in range(0, len(windows), batch):
            b = torch.from_numpy(windows[i:i + batch])
            x, y = b[:, :model.cfg.input_len], b[:, model.cfg.input_len:]
            d = model(x) - y
            mae += float(d.abs().mean(dim=(1, 2)).sum())
            e3 += float(d.norm(dim=-1).mean(dim=1).sum())
            e_end += float(d[:, -1].norm(dim=-1).sum())
            n += b.shape[0]
    n = max(n, 1)
    return {"mae_cm": 100 * mae / n, "mean_err_cm": 100 * e3 / n, "err_at_horizon_cm": 100 * e_end / n, "windows": n}


def evaluate_on_store(models: Mapping[str, NBeats], store: Any, split: str = "test",
                      group_by: str = "source") -> dict[str, Any]:
    """Every forecaster in ``models`` (all of one ``input_len`` / ``output_len`` / ``fps``) on the
    windows of ``store``'s ``split`` clips: overall and per group of clips (the clips' ``source``,
    or ``subject``: a procedural store's family), with the hold-last and constant-velocity
    forecasts (:func:`baseline_errors`) beside them. Metrics as :func:`evaluate_forecaster`
    (cm; ``windows``: how many).

    Returns:
        ``{"split", "clips", "group_by", "models": {name: {"all": metrics, "groups": {group:
        metrics}}}, "baselines": {"all": ..., "groups": ...}}``.

    Raises:
        ConfigError: the models disagree on the window, or the split has no clip long enough.
    """
    cfgs = {(m.cfg.input_len, m.cfg.output_len, m.cfg.fps, m.cfg.sites) for m in models.values()}
    if len(cfgs) != 1:
        raise ConfigError(f"evaluate_on_store: the forecasters' windows differ ({sorted(map(str, cfgs))}); "
                          "compare forecasters of one input_len, output_len, fps and sites")
    cfg = next(iter(models.values())).cfg
    ids = sorted(store.clips(split=split))
    groups: dict[str, list[str]] = {}
    for c in ids:
        groups.setdefault(str(store.entry(c).get(group_by, "?")), []).append(c)
    windows = {g: w for g, members in sorted(groups.items())
               if len(w := split_windows(split, cfg, store=store, ids=members)[0])}  # groups of short clips only: none
    if not windows:
        raise ConfigError(f"evaluate_on_store: no clip of split {split!r} is {cfg.input_len + cfg.output_len} "
                          f"samples long at {cfg.fps:g} Hz")
    every = np.concatenate(list(windows.values()), 0)
    models_out = {name: {"all": evaluate_forecaster(model, every),
                         "groups": {g: evaluate_forecaster(model, w) for g, w in windows.items()}}
                  for name, model in models.items()}
    baselines = {"all": baseline_errors(every, cfg), "groups": {g: baseline_errors(w, cfg) for g, w in windows.items()}}
    return {"split": split, "clips": len(ids), "group_by": group_by, "models": models_out, "baselines": baselines}


def baseline_errors(windows: np.ndarray, cfg: NBeatsConfig, vel_frames: int = 3) -> dict[str, dict[str, float]]:
    """The same errors for two naive forecasts: hold the last position, and constant velocity
    (differenced over ``vel_frames``), to put the forecaster's figures in context."""
    x, y = windows[:, :cfg.input_len], windows[:, cfg.input_len:]
    k = np.arange(1, cfg.output_len + 1, dtype=np.float32)[None, :, None]
    preds = {"hold": np.repeat(x[:, -1:], cfg.output_len, axis=1),
             "constant_velocity": x[:, -1:] + k * (x[:, -1:] - x[:, -1 - vel_frames:-vel_frames]) / vel_frames}
    out = {}
    for name, p in preds.items():
        d = p - y
        out[name] = {"mae_cm": float(100 * np.abs(d).mean()), "mean_err_cm": float(100 * np.linalg.norm(d, axis=-1).mean()),
                     "err_at_horizon_cm": float(100 * np.linalg.norm(d[:, -1], axis=-1).mean())}
    return out


def train(cfg: NBeatsConfig, out: Path, *, resume: bool = False, threads: int = 1, command: str = "",
          max_train_clips: int | None = None, checkpoint_every_s: float = 180.0, log=print, store: Any = None,
          train_source: tuple[Any, Sequence[str]] | None = None,
          provenance: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """Train on the corpus train split, select on the val split; writes ``last.pt`` and ``best.pt``.

    Args:
        store: the corpus store the splits come from (default: the prepared corpus; a lab's
            subset for ``--source``).
        train_source: ``(store, ids)`` of the train clips instead of ``store``'s train split (the
            training mix, module doc); ``max_train_clips`` applies to it.
        provenance: kept in every checkpoint's ``meta`` as given (the recipe, the mix's
            settings and card sentence).
    """
    torch.set_num_threads(threads)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.time()
    src_store, src_ids = train_source if train_source is not None else (store, None)
    every = lambda i, n: log(f"train windows: {i}/{n} clips ({time.time() - t0:.0f} s)") if i % 500 == 0 else None  # noqa: E731
    tr, train_clips = split_windows("train", cfg, max_train_clips, store=src_store, ids=src_ids, progress=every)
    va, _ = split_windows("val", cfg, cfg.val_clips, store=store)
    log(f"data: {len(tr)} train windows from {len(train_clips)} clips, {len(va)} val windows ({time.time() - t0:.0f} s)")
    torch.manual_seed(cfg.seed)
    model = NBeats(cfg)
    opt = torch.optim.Adam(model.parameters(), lr=cfg.lr)
    steps_per_epoch = math.ceil(len(tr) / cfg.batch_size)
    sched = torch.optim.lr_scheduler.OneCycleLR(opt, max_lr=cfg.lr, total_steps=max(1, cfg.epochs * steps_per_epoch),
                                                pct_start=0.05, final_div_factor=50)
    epoch, best = 0, float("inf")
    last = out / "last.pt"
    if resume and last.exists():
        ck = torch.load(last, map_location="cpu", weights_only=False)
        model.load_state_dict(ck["weights"])
        st = ck["train_state"]
        opt.load_state_dict(st["opt"])
        sched.load_state_dict(st["sched"])
        epoch, best = st["epoch"], st["best"]
        log(f"resumed at epoch {epoch} (best val MAE {best:.3f} cm)")
    meta_base = {"train_clips": len(train_clips), "train_windows": int(len(tr)), "val_windows": int(len(va)),
                 "train_command": command, "splits": {"train": "train", "select": "val"}, **(provenance or {})}
    history: list[dict[str, Any]] = []
    while epoch < cfg.epochs:
        model.train()
        rng = np.random.default_rng(cfg.seed * 1000 + epoch)
        perm = rng.permutation(len(tr))
        w = tr[perm]
        tl, nb, t_ep, t_ck = 0.0, 0, time.time(), time.time()
        for x, y in _batches(w, cfg, rng, noise=True):
            loss = (model(x) - y).abs().mean() / cfg.scale
            opt.zero_grad()
            loss.backward()
            opt.step()
            sched.step()
            tl += float(loss.detach())
            nb += 1
            if time.time() - t_ck > checkpoint_every_s:  # mid-epoch safety copy (resume restarts the epoch)
                save_forecaster(out / "partial.pt", model, {"epoch": epoch, "batch": nb})
                t_ck = time.time()
            if nb % 200 == 0:
                log(f"epoch {epoch + 1} batch {nb}/{steps_per_epoch} loss {tl / nb:.4f} ({time.time() - t_ep:.0f} s)")
        epoch += 1
        ev = evaluate_forecaster(model, va)
        row = {"epoch": epoch, "train_loss": tl / max(nb, 1), **{f"val_{k}": v for k, v in ev.items()},
               "seconds": time.time() - t_ep}
        history.append(row)
        log(json.dumps(row))
        meta = {**meta_base, **row}
        if ev["mae_cm"] < best:
            best = ev["mae_cm"]
            save_forecaster(out / "best.pt", model, meta)
        save_forecaster(last, model, meta, {"opt": opt.state_dict(), "sched": sched.state_dict(), "epoch": epoch, "best": best})
    (out / "history.json").write_text(json.dumps(history, indent=1))
    return {"best_val_mae_cm": best, "epochs": epoch}


def ship(checkpoint: Path, name: str, test: dict[str, Any] | None = None, notes: str | None = None) -> Path:
    """Copy a forecaster checkpoint into ``wearpose/weights/<name>.pt`` (no optimiser state) with its
    card; ``notes`` go first in the card's ``notes`` (what this version is, where it is worse)."""
    ck = torch.load(checkpoint, map_location="cpu", weights_only=False)
    ck["train_state"] = None
    out = weights.WEIGHTS_DIR / f"{name}.pt"
    torch.save(ck, out)
    store = CorpusStore()
    train = [store.entry(c) for c in store.clips(split="train")]
    licences = sorted({e["licence"] for e in train})
    meta = ck.get("meta", {})
    card = {
        "name": name, "method": "nbeats-forecaster (MI-Poser MIM, Sec. 3.3 / 4.3)",
        "config": ck["config"], "parameters": int(sum(v.numel() for v in ck["weights"].values())),
        "train_command": meta.get("train_command", ""),
        "training_data": {"split": "train", "clips": meta.get("train_clips"), "windows": meta.get("train_windows"),
                          "licences": licences,
                          "trajectories": "both wrists relative to a head-worn EM source (body model sites, 120 Hz), "
                                          "interference-free (ground-truth motion), input windows with "
                                          f"{1000 * float(ck['config'].get('input_noise', 0.0)):g} mm white noise",
                          **({"mix": meta["mix"]} if meta.get("mix") else {}),
                          "clips_per_source": meta.get("clips_per_source"), "corpus": store.provenance().get("corpus")},
        **({"recipe": meta["recipe"]} if meta.get("recipe") else {}),
        "licence": ("non-commercial use only: trained on CC BY-NC 4.0 motion (Bandai Namco) and CMU mocap "
                    "(research terms)") if "CC-BY-NC-4.0" in licences else "see training_data.licences",
        "validation": {k: v for k, v in meta.items() if k.startswith("val_") or k == "epoch"},
        "test": test or {},
        "size_bytes": out.stat().st_size,
        "shipped_with": f"wearpose train nbeats --ship {checkpoint} --name {name}",
        "notes": (f"{notes} " if notes else "") + "MI-Poser reports 1.26 cm validation MAE on its own ~40 min of "
                 "free sensor motion; ours is on corpus motion (dance, sports, walking included), a harder set.",
    }
    out.with_suffix(".json").write_text(json.dumps(card, indent=2))
    return out


def ship_tested(checkpoint: Path, name: str, notes: str | None = None) -> dict[str, Any]:
    """Measure ``checkpoint`` on the corpus test split's windows (MAE and the constant /
    constant-velocity baselines, :func:`evaluate_forecaster`, :func:`baseline_errors`), then
    :func:`ship` it as ``name`` with those figures on its card.

    Returns:
        ``{"shipped": path of the weights, "test": the figures}``.
    """
    model, _ = load_forecaster(checkpoint)
    windows, _ = split_windows("test", model.cfg)
    test = {"split": "test", **evaluate_forecaster(model, windows), "baselines": baseline_errors(windows, model.cfg)}
    return {"shipped": str(ship(checkpoint, name, test, notes)), "test": test}
