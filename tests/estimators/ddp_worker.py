"""Worker for the DDP tests, started by ``torchrun`` (see ``test_ddp.py``); not collected by pytest.

Usage: ``torchrun --nproc_per_node N ddp_worker.py {synthetic,empose,empose-nobn} OUT_DIR [CACHE_DIR]``.
``empose-nobn`` makes the LGD update network's batch norms pass through: batch-norm
statistics are the one thing a rank computes on its slice only, so without them the N-process
run must equal the 1-process run to float precision.
Trains a tiny task with :func:`wearpose.estimators.train.train`, logging every step to
``OUT_DIR/log.jsonl`` (rank 0), so a 1-process and an N-process run can be compared step by step.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any, Iterable

import torch
from torch import nn

from wearpose.estimators.train import TrainSettings, train


class SyntheticTask:
    """Linear regression with a small MLP on fixed random data: 4 batches of 12 per epoch."""

    val_metric = "val_loss"

    def __init__(self) -> None:
        g = torch.Generator().manual_seed(0)
        self.x = torch.randn(48, 5, generator=g)
        self.y = self.x @ torch.randn(5, 2, generator=g) + 0.1 * torch.randn(48, 2, generator=g)
        torch.manual_seed(1)
        self.model = nn.Sequential(nn.Linear(5, 16), nn.Tanh(), nn.Linear(16, 2))

    def num_batches(self) -> int:
        return 4

    def batches(self, epoch: int, skip: int) -> Iterable[Any]:
        perm = torch.randperm(48, generator=torch.Generator().manual_seed(epoch))
        for k in range(skip, 4):
            i = perm[k * 12:(k + 1) * 12]
            yield {"x": self.x[i], "y": self.y[i]}

    def loss(self, batch: dict[str, torch.Tensor], device: torch.device) -> tuple[torch.Tensor, dict[str, float]]:
        return ((self.model(batch["x"]) - batch["y"]) ** 2).mean(), {}

    @torch.no_grad()
    def validate(self, device: torch.device) -> dict[str, float]:
        return {"val_loss": float(((self.model(self.x) - self.y) ** 2).mean())}

    def save(self, path: Path, meta: dict[str, Any], train_state: dict[str, Any] | None) -> None:
        torch.save({"weights": self.model.state_dict(), "meta": meta}, path)


def empose_task(cache: Path) -> Any:
    from wearpose.estimators.empose.config import EmposeConfig
    from wearpose.estimators.empose.data import build_split
    from wearpose.estimators.empose.estimator import EmposeEstimator
    from wearpose.estimators.empose.train import EmposeTask

    torch.manual_seed(0)
    est = EmposeEstimator(EmposeConfig.preset("tiny", 12))
    tr = build_split("train", est.config, est.body, limit=4, cache_root=cache)
    va = build_split("val", est.config, est.body, limit=1, cache_root=cache)
    return EmposeTask(est, tr, va), est.config


def main() -> None:
    kind, out = sys.argv[1], Path(sys.argv[2])
    torch.set_num_threads(1)
    if kind == "synthetic":
        task, lr, epochs, steps = SyntheticTask(), 0.05, 2, None
    else:
        task, cfg = empose_task(Path(sys.argv[3]))
        if kind == "empose-nobn":  # batch norms pass through (their parameters frozen at 1 / 0)
            for mod in task.model.modules():
                if isinstance(mod, nn.modules.batchnorm._BatchNorm):
                    mod.forward = lambda x: x  # type: ignore[method-assign]
                    for p in mod.parameters():
                        p.requires_grad_(False)
        lr, epochs, steps = cfg.lr, 3, None
    train(task, TrainSettings(out_dir=out, epochs=epochs, lr=lr, log_every=1, max_steps=steps, quiet=True,
                              device="cpu", checkpoint_every=1000))


if __name__ == "__main__":
    main()
