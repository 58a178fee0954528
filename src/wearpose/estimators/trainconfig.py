"""``TrainConfig``: the training fields every method's config shares, declared once;
``SimulatedTrainConfig``: with the sensor error model of methods trained on simulated sensors.

A method's config (``EmposeConfig``, ``PipConfig``, ``BiraeConfig``, ``MiposerConfig``, a new
method's) is a frozen, keyword-only dataclass extending :class:`TrainConfig`; it adds its model
and data fields and states its own defaults by declaring a shared field again (the field keeps
its place). The training loop (:func:`wearpose.estimators.train.loop_settings`) reads these
fields, and checkpoints store them with the rest of the config (``to_dict``; readers match
fields by name, never by position).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from wearpose.errors import ConfigError
from wearpose.estimators.configio import ConfigIO


@dataclass(frozen=True, kw_only=True)
class TrainConfig(ConfigIO):
    """Optimisation and data-draw settings of a method's training run.

    ``seed`` base seed of the simulated data (:func:`wearpose.estimators.seeding.clip_seed`)
    and of the batch order; ``val_clips`` validation clips used each epoch (0 = all); ``lr``
    Adam learning rate; ``lr_schedule`` one of the class's :attr:`LR_SCHEDULES` (``constant``,
    ``cosine`` decay to ``lr_min_factor * lr`` over the run, and where a method allows it
    ``exp``, see :class:`wearpose.estimators.train.TrainSettings`); ``lr_min_factor``;
    ``batch_size`` windows per optimiser step; ``grad_clip`` max global gradient norm (0 = off).
    """

    #: The learning-rate schedules a method's training accepts.
    LR_SCHEDULES: ClassVar[tuple[str, ...]] = ("constant", "cosine")

    seed: int = 0
    val_clips: int = 0
    lr: float = 1e-3
    lr_schedule: str = "constant"
    lr_min_factor: float = 0.1
    batch_size: int = 32
    grad_clip: float = 1.0

    def __post_init__(self) -> None:
        if self.lr_schedule not in self.LR_SCHEDULES:
            raise ConfigError(f"{type(self).__name__}.lr_schedule: expected one of "
                              f"{', '.join(repr(s) for s in self.LR_SCHEDULES)}, got {self.lr_schedule!r}")


@dataclass(frozen=True, kw_only=True)
class SimulatedTrainConfig(TrainConfig):
    """:class:`TrainConfig` of a method whose training data are sensors simulated with an error
    model (:func:`wearpose.sensors.simulate`; EM-POSE, PIP, MI-Poser): ``train_noise`` one of
    :attr:`TRAIN_NOISES`, ``default`` (the documented error models) or ``none`` (ideal sensors).
    """

    TRAIN_NOISES: ClassVar[tuple[str, ...]] = ("default", "none")

    train_noise: str = "default"

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.train_noise not in self.TRAIN_NOISES:
            raise ConfigError(f"{type(self).__name__}.train_noise: expected one of "
                              f"{', '.join(repr(s) for s in self.TRAIN_NOISES)}, got {self.train_noise!r}")
