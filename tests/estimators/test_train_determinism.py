"""A training run is a function of its seed (issue 24: a shipped weight's recipe must reproduce
its validation figure when rerun).

Before the fix the networks' initial weights came from torch's global generator, whose state
depends on whatever ran before in the process, and dropout masks likewise: two EM-POSE runs of
the same command gave val MPJPE 480 / 511 / 504 mm. Here the global generator is deliberately
put in different states before each run, as different processes would leave it.
"""

from __future__ import annotations

import zlib
from pathlib import Path
from typing import Any, Callable

import pytest
import torch

from tests.estimators.test_empose import synthetic_motion
from wearpose.estimators.seeding import init_seed, seeded, step_seed


def _weights(model: torch.nn.Module) -> dict[str, torch.Tensor]:
    return {k: v.detach().clone() for k, v in model.state_dict().items()}


def _same(a: dict[str, torch.Tensor], b: dict[str, torch.Tensor]) -> bool:
    return a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in a)


def _estimators(body: Any) -> dict[str, Callable[[int], Any]]:
    """Every network estimator, built with config seed ``s``."""
    from wearpose.estimators.birae import BiraeConfig, BiraeEstimator
    from wearpose.estimators.empose import EmposeConfig, EmposeEstimator
    from wearpose.estimators.empose.baselines import baseline_config, estimator_class
    from wearpose.estimators.miposer.baselines import ImuPoserEstimator
    from wearpose.estimators.miposer.config import MiposerConfig
    from wearpose.estimators.miposer.estimator import MiposerEstimator
    from wearpose.estimators.pip.config import PipConfig
    from wearpose.estimators.pip.estimator import PipEstimator

    em = EmposeConfig.preset("tiny")
    out: dict[str, Callable[[int], Any]] = {
        "empose": lambda s: EmposeEstimator(em.override(seed=s), body=body),
        "pip": lambda s: PipEstimator(PipConfig.preset("tiny").override(seed=s), body=body, physics=False),
        "miposer": lambda s: MiposerEstimator(MiposerConfig.preset("tiny").override(seed=s), body=body),
        "imuposer": lambda s: ImuPoserEstimator(MiposerConfig.preset("tiny", model="imuposer").override(seed=s), body=body),
        "birae": lambda s: BiraeEstimator(BiraeConfig.preset("tiny").override(seed=s)),
    }
    for model in ("resnet", "birnn", "twostage"):
        cfg = baseline_config("tiny", 12, model)
        out[model] = lambda s, cfg=cfg, model=model: estimator_class(model)(cfg.override(seed=s), body=body)
    return out


def test_seeded_restores_the_callers_generator() -> None:
    torch.manual_seed(7)
    before = torch.get_rng_state()
    with seeded(init_seed(0)):
        a = torch.randn(4)
    assert torch.equal(torch.get_rng_state(), before)
    with seeded(init_seed(0)):
        assert torch.equal(torch.randn(4), a)
    assert init_seed(0) != init_seed(1) and step_seed(0, 0) != step_seed(0, 1) != step_seed(1, 1)


def test_every_estimator_draws_its_initial_weights_from_the_config_seed(body: Any) -> None:
    # ~2 s for the eight networks
    for name, make in _estimators(body).items():
        torch.manual_seed(1)
        a = _weights(make(0).model)
        torch.manual_seed(2)  # another process state: must not matter
        state = torch.get_rng_state()
        b = _weights(make(0).model)
        assert torch.equal(torch.get_rng_state(), state), f"{name}: building the network moved the caller's generator"
        assert _same(a, b), f"{name}: same seed, different initial weights"
        assert not _same(a, _weights(make(1).model)), f"{name}: seed 1 gave seed 0's initial weights"


class _SyntheticStore:
    """Duck-typed :class:`~wearpose.motion.CorpusStore` of short synthetic clips, seeded by a
    crc32 of the clip id (not ``hash``, which changes with ``PYTHONHASHSEED``)."""

    def __init__(self, root: Path) -> None:
        self.root = root
        self._ids = {"train": ["synthetic/train_00", "synthetic/train_01"], "val": ["synthetic/val_00"]}

    def clips(self, split: str | None = None) -> list[str]:
        return list(self._ids.get(split, []))

    def load(self, clip_id: str) -> Any:
        return synthetic_motion(zlib.crc32(clip_id.encode()) % 10_000, T=40)


@pytest.mark.budget(20)
def test_two_trainings_with_one_seed_give_identical_weights(tmp_path: Path, body: Any) -> None:
    """EM-POSE tiny with dropout on, 2 epochs of 2 steps: the data simulated twice (separate
    caches), the global generator in different states; then seed 1; then a run stopped after
    3 steps and resumed to 4."""
    from wearpose.estimators.empose import EmposeConfig, EmposeEstimator
    from wearpose.estimators.empose.train import train_empose

    store = _SyntheticStore(tmp_path / "store")
    cfg = EmposeConfig.preset("tiny").override(dropout_input=0.2, dropout_mlp=0.2)

    def run(name: str, seed: int, rng: int, cache: str | None = None, resume: bool = False) -> Any:
        torch.manual_seed(rng)
        est = EmposeEstimator(cfg.override(seed=seed), body=body)
        kw = dict(epochs=2, store=store, quiet=True, cache_root=tmp_path / f"cache-{cache or name}")
        if resume:  # stop inside epoch 2 (2 batches per epoch), then continue from last.pt
            train_empose(est, tmp_path / name, max_steps=3, **kw)
        train_empose(est, tmp_path / name, max_steps=4, resume=resume, **kw)
        return _weights(est.model)

    a, b = run("a", 0, rng=1), run("b", 0, rng=2)
    assert _same(a, b), "same seed, different weights after 4 steps"
    files = sorted((tmp_path / "cache-a").glob("*.pt"))
    assert len(files) == 2  # train and val, simulated again for run b
    for f in files:
        da, db = torch.load(f, weights_only=True), torch.load(tmp_path / "cache-b" / f.name, weights_only=True)
        assert all(torch.equal(da[k], db[k]) for k in da if isinstance(da[k], torch.Tensor)), f.name
    assert not _same(a, run("c", 1, rng=1)), "seed 1 gave seed 0's weights"
    # max_steps counts the steps of the whole run: the resumed part continues from step 3
    assert _same(a, run("d", 0, rng=3, cache="a", resume=True)), "a resumed run drew other dropout masks"
