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

from dataclasses import dataclass, replace
from typing import ClassVar, Self

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

    The training mix (:mod:`wearpose.estimators.trainmix`: what the *train* split holds beyond
    its corpus clips; validation and test never change): ``aug_mirror`` the left/right mirror
    image of every corpus clip; ``aug_speed_copies`` copies played at a speed drawn from
    ``aug_speed_range`` (log-uniform); ``aug_heading_copies`` copies turned to a random heading;
    ``aug_mix_copies`` copies whose upper body comes from another clip; ``aug_site_jitter_m``
    sensors strapped up to that far (m) off their sites, drawn per clip; ``aug_rest_offset_deg``
    every joint turned by a constant offset of up to that many degrees, drawn per clip (another
    capture chain's rest pose, :func:`wearpose.motion.augment.offset_rest`), on the SMPL joints
    named in ``aug_rest_offset_joints`` (``()``: all); ``procedural_per_family``
    procedural clips of each family of :mod:`wearpose.motion.procedural` (squat, kneel, ...);
    ``procedural_families`` the families drawn (``()``: all seven; names are checked against
    the generator's where the mix is built, :meth:`wearpose.estimators.trainmix.TrainingMix.from_config`);
    ``train_shapes`` the wearers, ``"corpus"`` (the clips' own body, beta = 0) or ``"random"``
    (one adult body drawn per clip, :func:`wearpose.body.shapes.sample_betas`).
    """

    #: The learning-rate schedules a method's training accepts.
    LR_SCHEDULES: ClassVar[tuple[str, ...]] = ("constant", "cosine")
    #: ``train_shapes`` values.
    TRAIN_SHAPES: ClassVar[tuple[str, ...]] = ("corpus", "random")
    TUPLE_FIELDS = {"aug_speed_range": float, "procedural_families": str, "aug_rest_offset_joints": str}

    seed: int = 0
    val_clips: int = 0
    lr: float = 1e-3
    lr_schedule: str = "constant"
    lr_min_factor: float = 0.1
    batch_size: int = 32
    grad_clip: float = 1.0
    aug_mirror: bool = False
    aug_speed_copies: int = 0
    aug_speed_range: tuple[float, float] = (0.8, 1.25)
    aug_heading_copies: int = 0
    aug_mix_copies: int = 0
    aug_site_jitter_m: float = 0.0
    aug_rest_offset_deg: float = 0.0
    aug_rest_offset_joints: tuple[str, ...] = ()
    procedural_per_family: int = 0
    procedural_families: tuple[str, ...] = ()
    train_shapes: str = "corpus"

    def __post_init__(self) -> None:
        name = type(self).__name__
        if self.lr_schedule not in self.LR_SCHEDULES:
            raise ConfigError(f"{name}.lr_schedule: expected one of "
                              f"{', '.join(repr(s) for s in self.LR_SCHEDULES)}, got {self.lr_schedule!r}")
        for field in ("aug_speed_copies", "aug_heading_copies", "aug_mix_copies", "procedural_per_family"):
            if int(getattr(self, field)) < 0:
                raise ConfigError(f"{name}.{field}: expected a count >= 0, got {getattr(self, field)!r}")
        lo_hi = tuple(self.aug_speed_range)
        if len(lo_hi) != 2 or not 0.0 < lo_hi[0] <= lo_hi[1]:
            raise ConfigError(f"{name}.aug_speed_range: expected (low, high) with 0 < low <= high, "
                              f"got {self.aug_speed_range!r}")
        if not 0.0 <= self.aug_site_jitter_m <= 0.1:
            raise ConfigError(f"{name}.aug_site_jitter_m: expected 0-0.1 m, got {self.aug_site_jitter_m!r}")
        if not 0.0 <= self.aug_rest_offset_deg <= 45.0:
            raise ConfigError(f"{name}.aug_rest_offset_deg: expected 0-45 deg, got {self.aug_rest_offset_deg!r}")
        fams = tuple(self.procedural_families)
        if len(set(fams)) != len(fams) or not all(isinstance(f, str) and f for f in fams):
            raise ConfigError(f"{name}.procedural_families: expected distinct family names, got {self.procedural_families!r}")
        if self.train_shapes not in self.TRAIN_SHAPES:
            raise ConfigError(f"{name}.train_shapes: expected one of "
                              f"{', '.join(repr(s) for s in self.TRAIN_SHAPES)}, got {self.train_shapes!r}")

    def without_mix(self) -> Self:
        """This config with the training mix off: the train split is its corpus clips as they
        are (no copies, procedural clips, wearers, site jitter or rest offsets)."""
        return replace(self, aug_mirror=False, aug_speed_copies=0, aug_heading_copies=0, aug_mix_copies=0,
                       aug_site_jitter_m=0.0, aug_rest_offset_deg=0.0, procedural_per_family=0, train_shapes="corpus")


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
