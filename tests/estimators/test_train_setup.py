"""Run setup shared by the estimators' ``train_*`` functions (:mod:`wearpose.estimators.train`):
:class:`WindowTask`, :func:`loop_settings`, :func:`resume_provenance`, :func:`train_estimator`.

A toy estimator (one linear layer on random windows, no body model) keeps these fast; the
methods' own tests train their tiny configs through the same code."""

from __future__ import annotations

import io
import json
from pathlib import Path
from typing import Any

import pytest
import torch
from rich.console import Console

from wearpose.estimators.birae.config import BiraeConfig
from wearpose.estimators.checkpoint import Checkpoint, CheckpointMismatchError, load_checkpoint, save_checkpoint
from wearpose.estimators.miposer.config import MiposerConfig
from wearpose.estimators.train import TrainSettings, WindowTask, loop_settings, resume_provenance, train_estimator


#: a real method config (the fields train_estimator reads), with a toy's sizes
TOY = MiposerConfig.preset("tiny").override(window=4, stride=2, batch_size=2, epochs=2, val_clips=0, lr=1e-2,
                                            lr_schedule="constant")


class ToyData:
    """``frames`` random 3-vectors with a linear target, cut into windows."""

    def __init__(self, clip_ids: list[str], frames: int, seed: int) -> None:
        g = torch.Generator().manual_seed(seed)
        self.clip_ids, self.num_frames = clip_ids, frames
        self.fingerprint = f"toy-{seed:02d}" + "0" * 20
        self.x = torch.randn(frames, 3, generator=g)
        self.y = self.x @ torch.tensor([[1.0], [-2.0], [0.5]])

    def windows(self, length: int, stride: int) -> list[int]:
        return list(range(0, self.num_frames - length + 1, stride))

    def iter_batches(self, length: int, stride: int, batch_size: int, g: torch.Generator | None = None, *,
                     skip: int = 0, shuffle: bool = True):
        starts = torch.tensor(self.windows(length, stride))
        if shuffle:
            starts = starts[torch.randperm(len(starts), generator=g)]
        for k in range(skip, len(starts) // batch_size):
            idx = starts[k * batch_size:(k + 1) * batch_size, None] + torch.arange(length)
            yield {"x": self.x[idx], "y": self.y[idx], "starts": starts[k * batch_size:(k + 1) * batch_size]}


class ToyTask(WindowTask):
    val_metric = "val_mse"

    def window(self) -> tuple[int, int]:
        return self.cfg.window, self.cfg.stride

    def loss(self, batch: dict[str, torch.Tensor], device: torch.device):
        loss = torch.mean((self.model(batch["x"].to(device)) - batch["y"].to(device)) ** 2)
        return loss, {"mse": float(loss.detach())}

    @torch.no_grad()
    def validate(self, device: torch.device) -> dict[str, float]:
        b = self.val_data
        return {"val_mse": float(torch.mean((self.model(b.x.to(device)) - b.y.to(device)) ** 2))}


class ToyEstimator:
    name = "toy"
    body_asset_id = "none"

    def __init__(self, config: MiposerConfig = TOY) -> None:
        torch.manual_seed(0)
        self.config, self.kit_name = config, config.kit
        self.model = torch.nn.Linear(3, 1)
        self.data_fingerprint, self.train_command, self.meta = "", "", {}
        self.device = torch.device("cpu")

    def to(self, device: torch.device) -> ToyEstimator:
        self.device = device
        self.model.to(device)
        return self

    def checkpoint(self, meta: dict[str, Any] | None = None, train_state: dict[str, Any] | None = None) -> Checkpoint:
        return Checkpoint(method=self.name, config=self.config.to_dict(), kit=self.kit_name, sensors=["s"],
                          body_asset=self.body_asset_id, weights={k: v.detach().cpu() for k, v in self.model.state_dict().items()},
                          data_fingerprint=self.data_fingerprint, train_command=self.train_command,
                          meta={**self.meta, **(meta or {})}, train_state=train_state)


def toy_build(calls: list[tuple[str, Any]] | None = None):
    def build(split: str, *, store: Any, limit: int | None, cache_root: Any, progress: Any) -> ToyData:
        if calls is not None:
            calls.append((split, limit))
        n = limit or 3
        progress(n, n)
        return ToyData([f"{split}/{i}" for i in range(n)], 24 if split == "train" else 12, seed=1 if split == "train" else 2)
    return build


def run(est: ToyEstimator, out: Path, **kw: Any) -> tuple[dict[str, Any], str]:
    buf = io.StringIO()
    res = train_estimator(est, out, toy_build(kw.pop("calls", None)), lambda tr, va: ToyTask(est, tr, va), label="Toy",
                          console=Console(file=buf, width=200), device="cpu", **kw)
    return res, buf.getvalue()


# --------------------------------------------------------------------------- WindowTask
def test_window_task_batches_are_seeded_by_epoch_and_skip_done_ones(tmp_path: Path) -> None:
    est = ToyEstimator()
    task = ToyTask(est, ToyData(["a"], 24, 1), None)
    assert task.num_batches() == 5  # 11 windows of 4 frames every 2, batches of 2, last partial batch dropped
    order = lambda ep, skip=0: [b["starts"].tolist() for b in task.batches(ep, skip)]  # noqa: E731
    assert order(0) == order(0) and order(0) != order(1)
    assert order(1, skip=2) == order(1)[2:]
    task.save(tmp_path / "c.pt", {"epoch": 1}, {"global_step": 3})
    ck = load_checkpoint(tmp_path / "c.pt")
    assert ck.meta == {"epoch": 1} and ck.train_state == {"global_step": 3} and ck.method == "toy"
    with pytest.raises(NotImplementedError):
        WindowTask(est, ToyData(["a"], 24, 1), None)


# --------------------------------------------------------------------------- loop_settings
def test_loop_settings_take_the_config_optimisation_fields(tmp_path: Path) -> None:
    cfg = TOY.override(lr=3e-3, lr_schedule="cosine", lr_min_factor=0.2, grad_clip=0.5)
    s = loop_settings(cfg, str(tmp_path), 7, resume=True, threads=1, max_steps=4)
    assert s == TrainSettings(out_dir=tmp_path, epochs=7, lr=3e-3, lr_schedule="cosine", lr_min_factor=0.2, grad_clip=0.5,
                              resume=True, threads=1, max_steps=4, seed=cfg.seed)
    assert loop_settings(cfg.override(seed=5), tmp_path, 1).seed == 5  # dropout draws follow the config's seed
    assert loop_settings(cfg, tmp_path, 1, lr=1e-5).lr == 1e-5
    s = loop_settings(BiraeConfig.preset("tiny").override(lr_schedule="exp", lr_decay=0.5, lr_decay_steps=10), tmp_path, 1)
    assert (s.lr_schedule, s.lr_decay, s.lr_decay_steps) == ("exp", 0.5, 10)  # configs without them: TrainSettings' defaults
    assert (loop_settings(cfg, tmp_path, 1).lr_decay, loop_settings(cfg, tmp_path, 1).lr_decay_steps) == (0.9, 5000)


# --------------------------------------------------------------------------- resume_provenance
def test_resume_provenance(tmp_path: Path) -> None:
    buf = io.StringIO()
    con = Console(file=buf, width=200)
    last = tmp_path / "last.pt"
    est = ToyEstimator()
    resume_provenance(est, last, resume=True, train_command="first", console=con)  # nothing to resume: a new run
    assert est.train_command == "first" and "resumed_with" not in est.meta
    resume_provenance(est, last, resume=False, train_command="", console=con)
    assert est.train_command == "first"  # an empty command keeps the estimator's
    save_checkpoint(est.checkpoint(), last)

    again = ToyEstimator()
    resume_provenance(again, last, resume=True, train_command="second", console=con)
    assert again.train_command == "first" and again.meta["resumed_with"] == "second" and buf.getvalue() == ""
    resume_provenance(ToyEstimator(), last, resume=False, train_command="third", console=con)  # not resuming: not read
    other = ToyEstimator(TOY.override(lr=1.0))
    resume_provenance(other, last, resume=True, train_command="x", console=con)
    assert "warning" in buf.getvalue() and "different config" in buf.getvalue()
    wrong = ToyEstimator()
    wrong.kit_name = "miposer1"
    with pytest.raises(CheckpointMismatchError, match="kit"):
        resume_provenance(wrong, last, resume=True, train_command="x", console=con)


# --------------------------------------------------------------------------- train_estimator
def test_train_estimator_run_directory_logs_and_resume(tmp_path: Path) -> None:
    out = tmp_path / "run"
    est = ToyEstimator()
    calls: list[tuple[str, Any]] = []
    res, text = run(est, out, max_steps=3, train_command="cmd1", calls=calls, limit_train=2)
    assert calls == [("train", 2), ("val", None)]  # val_clips 0 = the whole split
    assert res["steps"] == 3 and sorted(p.name for p in out.iterdir()) == ["last.pt", "log.jsonl"]
    lines = text.splitlines()
    assert lines[:4] == ["Toy data: simulating/loading train split (miposer, 60 Hz)", "  simulated 2/2 clips",
                         "  simulated 3/3 clips", "train: 2 clips, 24 frames; val: 3 clips, 12 frames; fingerprint toy-010000000000"]
    assert est.data_fingerprint.startswith("toy-01") and est.train_command == "cmd1"
    assert est.meta == {"train_clips": 2, "train_frames": 24, "val_clips": 3}
    ck = load_checkpoint(out / "last.pt")
    assert ck.train_command == "cmd1" and ck.meta["train_clips"] == 2 and ck.train_state["global_step"] == 3

    est2 = ToyEstimator()
    res2, text2 = run(est2, out, resume=True, train_command="cmd2", epochs=1, val_frames=False)
    assert res2["steps"] == 5 and sorted(p.name for p in out.iterdir()) == ["best.pt", "last.pt", "log.jsonl"]
    assert "val: 3 clips; fingerprint" in text2 and f"resumed from {out / 'last.pt'}: epoch 1, batch 3/5, step 3" in text2
    best = load_checkpoint(out / "best.pt")
    assert best.train_command == "cmd1" and best.meta["resumed_with"] == "cmd2" and best.meta["epoch"] == 1
    rows = [json.loads(line) for line in (out / "log.jsonl").read_text().splitlines()]
    assert [r["type"] for r in rows] == ["start", "start", "epoch"] and rows[1]["resume_step"] == 3
    # a wrong estimator cannot resume this run
    wrong = ToyEstimator()
    wrong.name = "other"
    with pytest.raises(CheckpointMismatchError, match="method"):
        run(wrong, out, resume=True)
