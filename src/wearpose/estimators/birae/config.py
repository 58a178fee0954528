"""``BiraeConfig``: BiRAE (Butt et al., IEEE Access 2021) hyper-parameters and data settings.

Presets (:meth:`BiraeConfig.preset`):

- ``paper``: Sec. IV-A / IV-E exactly: input FC 512 + ReLU + dropout 0.2, two stacked Bi-LSTM
  layers of 512, linear mean / log-variance heads; 300-frame subsequences (truncated BPTT),
  batch 16, Adam lr 1e-3 decayed x0.9 every 5000 steps (``lr_schedule="exp"``), gradient-norm
  clipping 1, best-validation checkpoint (early stopping), max 2000 epochs split between the
  clean phase and the augmented fine-tuning phase, 60 Hz.
- ``cpu``: the same network at CPU scale for a ~30 min single-thread run per model on one
  idle core (~0.7 s/step): width and hidden 128 (256 measured ~3x slower per step),
  240-frame subsequences, batch 16, lr 1e-3 with the paper's exponential decay shape at CPU
  scale (x0.9 every 100 steps instead of every 5000, restarting per phase), 8 clean + 12
  augmented epochs over all training clips, the whole validation split (all 174 clips: the
  first 60 sorted ids are one subject raising its hands), 10 MC-dropout samples, the
  ``decoupled`` loss (see ``loss``). Everything else as ``paper``.
- ``tiny``: a seconds-long smoke-test model (tests).

Input representations (``rep``; :mod:`.representations`): ``"6param"`` (Appendix A),
``"3param"`` (its yaw-free subset r31, r32, r33), ``"3param_rate"`` (3-param plus the
root-relative angular rate, with an auxiliary reconstruction loss on the rate, Sec. IV-D) and
``"zhou6d"`` (Zhou et al.'s first two columns, Table 1's comparison row; we keep the
exponential-map output for it).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

from wearpose.errors import ConfigError
from wearpose.estimators.trainconfig import TrainConfig

REPS: tuple[str, ...] = ("6param", "3param", "3param_rate", "zhou6d")


@dataclass(frozen=True, kw_only=True)
class BiraeConfig(TrainConfig):
    """Network, data and optimisation settings (see the module doc for the presets).

    Network: ``rep`` input representation; ``width`` input FC size; ``hidden`` Bi-LSTM size per
    direction; ``layers`` stacked Bi-LSTM layers; ``dropout`` after the input FC (also the
    MC-dropout rate at inference); ``logvar_min`` / ``logvar_max`` clamp of the predicted
    log-variance (rad^2, numerical safety only); ``aux_weight`` weight of the angular-rate
    reconstruction loss (``3param_rate`` only); ``rate_scale`` factor applied to angular rates
    (rad/s) before they enter the network (keeps them in the range of the orientation
    parameters).
    Data: ``rate`` Hz of the training data; ``seq_len`` subsequence length (truncated BPTT);
    ``min_len`` shortest clip kept (frames); ``aug_*`` augmentation of the second phase (white
    orientation noise std, impulse probability per frame and std, yaw-rate bias std in deg/s);
    ``train_clips`` / ``val_clips`` first N clips of the split (0 = all).
    Optimisation: ``epochs_clean`` then ``epochs_aug``, then ``epochs_sigma`` (0: no third phase;
    the log-variance head alone refitted on the corpus's own clips, the mix left out:
    :func:`~wearpose.estimators.birae.train.train_birae`) at ``lr_sigma`` (one linear layer refitted
    on frozen features takes a larger step than the whole network's fine-tuning),
    ``lr_decay`` / ``lr_decay_steps``, and
    :class:`~wearpose.estimators.trainconfig.TrainConfig`'s ``seed``, ``val_clips``, ``lr``,
    ``lr_schedule`` (``exp`` = x``lr_decay`` every ``lr_decay_steps``; ``cosine``;
    ``constant``), ``lr_min_factor``, ``batch_size``, ``grad_clip``.
    Inference: ``mc_samples`` M of Eq. 7-8; ``window`` (past, future) frames of the online mode
    at ``rate`` (Sec. V-D: [130, 30] at 60 Hz).
    """

    TUPLE_FIELDS = {**TrainConfig.TUPLE_FIELDS, "window": None}
    LR_SCHEDULES = ("exp", "cosine", "constant")

    rep: str = "6param"
    width: int = 512
    hidden: int = 512
    layers: int = 2
    dropout: float = 0.2
    logvar_min: float = -14.0
    logvar_max: float = 4.0
    aux_weight: float = 1.0
    loss: str = "nll"
    rate_scale: float = 0.1
    rate: float = 60.0
    seq_len: int = 300
    min_len: int = 200
    aug_white_deg: float = 1.0
    aug_impulse_prob: float = 0.002
    aug_impulse_deg: float = 5.0
    aug_yaw_bias_dps: float = 0.5
    train_clips: int = 0
    lr_schedule: str = "exp"
    lr_decay: float = 0.9
    lr_decay_steps: int = 5000
    batch_size: int = 16
    epochs_clean: int = 1000
    epochs_aug: int = 1000
    epochs_sigma: int = 0
    lr_sigma: float = 1e-3
    mc_samples: int = 20
    window: tuple[int, int] = (130, 30)

    def __post_init__(self) -> None:
        super().__post_init__()  # the shared training fields (TrainConfig)
        if self.rep not in REPS:
            raise ConfigError(f"BiraeConfig.rep: expected one of {REPS}, got {self.rep!r}")
        if self.loss not in ("nll", "decoupled"):
            raise ConfigError(f"BiraeConfig.loss: expected nll or decoupled, got {self.loss!r}")
        if not self.lr_sigma > 0:
            raise ConfigError(f"BiraeConfig.lr_sigma: expected a learning rate > 0, got {self.lr_sigma!r}")
        if self.epochs_sigma < 0:
            raise ConfigError(f"BiraeConfig.epochs_sigma: expected a whole number >= 0, got {self.epochs_sigma!r}")
        if min(self.width, self.hidden, self.layers, self.seq_len, self.batch_size, self.mc_samples) < 1:
            raise ConfigError("BiraeConfig: width, hidden, layers, seq_len, batch_size and mc_samples must be >= 1")
        if not 0.0 <= self.dropout < 1.0:
            raise ConfigError(f"BiraeConfig.dropout: expected a probability in [0, 1), got {self.dropout!r}")
        w = tuple(self.window)
        if len(w) != 2 or min(w) < 0:
            raise ConfigError(f"BiraeConfig.window: expected (past, future) frames >= 0, got {self.window!r}")
        object.__setattr__(self, "window", (int(w[0]), int(w[1])))
        if not (self.rate > 0 and math.isfinite(self.rate)):
            raise ConfigError(f"BiraeConfig.rate: expected a positive rate in Hz, got {self.rate!r}")

    @property
    def kit(self) -> str:
        return "mimu6"

    @property
    def uses_rate(self) -> bool:
        """True when the input carries the root-relative angular rate (``3param_rate``)."""
        return self.rep == "3param_rate"

    @classmethod
    def preset(cls, name: str, rep: str = "6param") -> BiraeConfig:
        """``paper``, ``cpu`` or ``tiny`` for input representation ``rep``."""
        paper = cls(rep=rep)
        if name == "paper":
            return paper
        if name == "cpu":
            return replace(paper, width=128, hidden=128, seq_len=240, min_len=60, lr_schedule="exp", lr_decay_steps=100,
                           loss="decoupled", epochs_clean=8, epochs_aug=12, val_clips=0, mc_samples=10)
        if name == "tiny":
            return replace(paper, width=16, hidden=16, seq_len=32, min_len=8, batch_size=4, lr=3e-3,
                           lr_schedule="constant", epochs_clean=1, epochs_aug=1, train_clips=4, val_clips=2,
                           mc_samples=3)
        raise ConfigError(f"unknown BiRAE config preset {name!r}; expected paper, cpu or tiny")
