"""One training-config base for every method (wearpose.estimators.trainconfig.TrainConfig):
the methods' defaults as before, the shared lr_schedule check, shipped checkpoints' configs
loaded with the values they store."""

from __future__ import annotations

import dataclasses

import pytest

from wearpose.errors import ConfigError
from wearpose.estimators import get_estimator
from wearpose.estimators.birae.config import BiraeConfig
from wearpose.estimators.checkpoint import load_checkpoint
from wearpose.estimators.empose.config import EmposeConfig
from wearpose.estimators.miposer.config import MiposerConfig
from wearpose.estimators.pip.config import PipConfig
from wearpose.estimators.trainconfig import SimulatedTrainConfig, TrainConfig
from wearpose.weights import list_weights, weight_path

CONFIGS = (EmposeConfig, PipConfig, BiraeConfig, MiposerConfig)
SHARED = ("seed", "val_clips", "lr", "lr_schedule", "lr_min_factor", "batch_size", "grad_clip")


@pytest.mark.parametrize("cls", CONFIGS)
def test_method_configs_extend_the_base(cls: type) -> None:
    assert issubclass(cls, TrainConfig)
    names = [f.name for f in dataclasses.fields(cls)]
    assert all(names.count(n) == 1 for n in SHARED)
    with pytest.raises(TypeError):  # keyword-only: no reader depends on the field order
        cls(1)


def test_each_method_keeps_its_defaults() -> None:
    # The values each config declared before the base existed (commit 578713e).
    got = {c.__name__: {n: getattr(c(), n) for n in (*SHARED, "epochs")} for c in (EmposeConfig, PipConfig, MiposerConfig)}
    assert got["EmposeConfig"] == dict(seed=0, val_clips=0, lr=1e-4, lr_schedule="constant", lr_min_factor=0.1,
                                       batch_size=12, grad_clip=1.0, epochs=50)
    assert got["PipConfig"] == dict(seed=0, val_clips=0, lr=1e-3, lr_schedule="constant", lr_min_factor=0.1,
                                    batch_size=256, grad_clip=1.0, epochs=100)
    assert got["MiposerConfig"] == dict(seed=0, val_clips=0, lr=1e-3, lr_schedule="cosine", lr_min_factor=0.1,
                                        batch_size=32, grad_clip=1.0, epochs=100)
    b = BiraeConfig()
    assert {n: getattr(b, n) for n in SHARED} == dict(seed=0, val_clips=0, lr=1e-3, lr_schedule="exp",
                                                      lr_min_factor=0.1, batch_size=16, grad_clip=1.0)
    assert not hasattr(b, "epochs")  # BiRAE trains in two phases (epochs_clean, epochs_aug)


@pytest.mark.parametrize("cls", CONFIGS)
def test_lr_schedule_checked_once_for_all(cls: type) -> None:
    for s in ("constant", "cosine"):
        assert cls(lr_schedule=s).lr_schedule == s
    with pytest.raises(ConfigError, match=rf"{cls.__name__}\.lr_schedule: expected one of .*'cosine'.*got 'step'"):
        cls(lr_schedule="step")
    if cls is BiraeConfig:
        assert cls(lr_schedule="exp").lr_schedule == "exp"
    else:
        with pytest.raises(ConfigError, match="lr_schedule"):
            cls(lr_schedule="exp")


@pytest.mark.parametrize("name", [n for n in list_weights() if not n.startswith("nbeats")])
def test_shipped_checkpoints_load_with_their_stored_config(name: str) -> None:
    ck = load_checkpoint(weight_path(name))
    est = get_estimator(ck.method).load(weight_path(name))
    cfg = est.config.to_dict()
    assert isinstance(est.config, TrainConfig)
    assert {k: cfg[k] for k in ck.config} == ck.config  # every stored value, as stored
    assert type(est.config).from_dict(cfg) == est.config


@pytest.mark.parametrize("cls", (EmposeConfig, PipConfig, MiposerConfig))
def test_train_noise_declared_and_checked_once(cls: type) -> None:
    """EM-POSE, PIP and MI-Poser train on simulated sensors: ``train_noise`` comes from
    SimulatedTrainConfig (default ``"default"``, checked there); BiRAE has no error model."""
    assert issubclass(cls, SimulatedTrainConfig) and cls().train_noise == "default"
    assert cls(train_noise="none").train_noise == "none"
    with pytest.raises(ConfigError, match=rf"{cls.__name__}\.train_noise: expected one of 'default', 'none', got 'ximu3'"):
        cls(train_noise="ximu3")
    assert not issubclass(BiraeConfig, SimulatedTrainConfig) and not hasattr(BiraeConfig(), "train_noise")
