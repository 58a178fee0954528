"""``PipConfig``: PIP kinematics-module hyper-parameters (PIP Sec. 3.1, appendix) and data settings.

Presets (:meth:`PipConfig.preset`):

- ``paper``: the appendix exactly: five RNNs (P_L, P_A, R_A, V_A, C_F), each a linear+ReLU input
  layer, two LSTM layers of width 256 and a linear output, 40 % dropout; initialisation FCNs
  I_PL / I_VA with FC widths 256-512-1024 (1024 = hidden + cell state of the two LSTM layers);
  60 fps input, training windows of 200 frames, batch 256, Adam. The paper trains each RNN
  separately (and fine-tunes on DIP-IMU, which we do not have); we train the chain jointly
  (each stage fed the previous stage's prediction), see ``docs/pip.md``.
- ``cpu``: the same chain sized to train in about an hour on one CPU thread: LSTM width 128
  (FCN widths 128-256-512 so the last layer is again 2 layers x (h, c) x width; 7 MB of
  weights instead of 22), batch 16 of the paper's 200-frame windows (half-overlapping), lr 1e-3
  with a cosine decay, 12 epochs.
- ``tiny``: a few-second smoke-test model (tests).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from wearpose.errors import ConfigError
from wearpose.estimators.trainconfig import SimulatedTrainConfig
from wearpose.estimators.pip.sitting import STAND_HOLD_S, TRANSITIONS


@dataclass(frozen=True, kw_only=True)
class PipConfig(SimulatedTrainConfig):
    """PIP kinematics settings.

    Model: ``hidden`` LSTM width (``rnn_layers`` layers) of every RNN, ``dropout`` on each RNN's
    input, ``init_widths`` the two hidden FC widths of I_PL / I_VA (their output is
    ``2 * rnn_layers * hidden``), ``learned_init`` (False = zero initial LSTM states: the
    "w/o learned init" ablation of Table 2).
    Scales (TransPose/PIP code): accelerations divided by ``acc_scale`` (m/s^2), joint
    velocities by ``vel_scale`` (m/s) before entering / leaving the network.
    Losses: ``w_leaf``, ``w_joints``, ``w_rot`` (L2), ``w_vel`` (cumulative velocity loss over
    windows ``vel_windows`` frames, TransPose Eq. 5), ``w_contact`` (binary cross-entropy).
    Contact labels (TransPose): a foot (SMPL joints 10/11) is in contact when it moves less than
    ``contact_speed`` m/s; additionally it must be within ``contact_height`` m of the clip's
    lowest foot height (rules out the slow apex of a jump).
    Data: ``rate`` Hz, ``seq_len`` frames per window, ``window_stride``, ``min_window`` (0: only
    windows of exactly ``seq_len`` frames, clips shorter than that are not trained on; N > 0: a
    clip of N to ``seq_len`` - 1 frames is one padded, masked window, and a long clip's tail the
    stride leaves out gets a window of its own -- what lets long windows, the LSTM's memory
    of a sit-down over many seconds, coexist with the corpus's short clips), ``sitting_window``
    (0: the synthetic sitting clips are windowed like the corpus; N > 0: windows of N frames
    every N // 2 for them, e.g. long windows for motion and short ones for sitting),
    ``train_noise`` IMU error model (``default`` / ``none``; :class:`~wearpose.estimators.trainconfig.SimulatedTrainConfig`), ``max_train_clips`` (0 = whole
    train split), ``sitting_clips`` synthetic sitting clips
    (:mod:`~wearpose.estimators.pip.sitting`; the corpus has none) added to the
    train split (and a tenth as many, at least 4, to val); 0 = corpus only; ``sitting_stand_s``
    the range of their standing holds, s (seated holds: 3-20 s; ``(3, 20)`` = balanced);
    ``sitting_transitions`` how they sit down and stand up (``slerp``: pelvis fixed, no lean, the
    sitting clips every model up to session 7 saw; ``lean``: trunk lean and knees forward, see
    :mod:`~wearpose.estimators.pip.sitting`); ``sitting_hanging_arms`` the fraction of them whose
    arms hang nearly straight (0: the random arm posture only).
    Augmentation, procedural clips and wearers of the *train* split: the training mix every
    method shares (``aug_*``, ``procedural_per_family``, ``train_shapes``,
    :class:`~wearpose.estimators.trainconfig.TrainConfig`, :mod:`wearpose.estimators.trainmix`).
    Optimisation: ``epochs``, and :class:`~wearpose.estimators.trainconfig.TrainConfig`'s
    ``seed``, ``val_clips``, ``lr``, ``lr_schedule``, ``lr_min_factor``, ``batch_size``,
    ``grad_clip``; PIP's default batch: 256.
    """

    TUPLE_FIELDS = {**SimulatedTrainConfig.TUPLE_FIELDS, "init_widths": int, "vel_windows": int, "sitting_stand_s": float}

    hidden: int = 256
    rnn_layers: int = 2
    dropout: float = 0.4
    init_widths: tuple[int, int] = (256, 512)
    learned_init: bool = True
    acc_scale: float = 30.0
    vel_scale: float = 3.0
    w_leaf: float = 1.0
    w_joints: float = 1.0
    w_rot: float = 1.0
    w_vel: float = 1.0
    w_contact: float = 1.0
    vel_windows: tuple[int, ...] = (1, 3, 9, 27)
    contact_speed: float = 0.48
    contact_height: float = 0.10
    rate: float = 60.0
    seq_len: int = 200
    window_stride: int = 200
    min_window: int = 0
    sitting_window: int = 0
    max_train_clips: int = 0
    sitting_clips: int = 0
    sitting_stand_s: tuple[float, float] = STAND_HOLD_S
    sitting_transitions: str = "slerp"
    sitting_hanging_arms: float = 0.0
    batch_size: int = 256
    epochs: int = 100

    def __post_init__(self) -> None:
        super().__post_init__()  # the shared training fields (SimulatedTrainConfig)
        if self.hidden < 1 or self.rnn_layers < 1:
            raise ConfigError("PipConfig: hidden >= 1 and rnn_layers >= 1 required")
        if not 0.0 <= self.dropout < 1.0:
            raise ConfigError(f"PipConfig.dropout: expected 0 <= p < 1, got {self.dropout!r}")
        if self.seq_len < 2 or self.window_stride < 1:
            raise ConfigError("PipConfig: seq_len >= 2 and window_stride >= 1 required")
        if self.sitting_window < 0 or self.sitting_window == 1:
            raise ConfigError(f"PipConfig.sitting_window: expected 0 or >= 2 frames, got {self.sitting_window!r}")
        if not 0 <= self.min_window <= self.seq_len:
            raise ConfigError(f"PipConfig.min_window: expected 0 <= min_window <= seq_len ({self.seq_len}), "
                              f"got {self.min_window!r}")
        if len(self.sitting_stand_s) != 2 or not 0.0 < self.sitting_stand_s[0] <= self.sitting_stand_s[1]:
            raise ConfigError(f"PipConfig.sitting_stand_s: expected (low, high) seconds with 0 < low <= high, "
                              f"got {self.sitting_stand_s!r}")
        if self.sitting_transitions not in TRANSITIONS:
            raise ConfigError(f"PipConfig.sitting_transitions: expected one of {', '.join(TRANSITIONS)}, "
                              f"got {self.sitting_transitions!r}")
        if not 0.0 <= self.sitting_hanging_arms <= 1.0:
            raise ConfigError(f"PipConfig.sitting_hanging_arms: expected a fraction in [0, 1], "
                              f"got {self.sitting_hanging_arms!r}")
        if len(self.init_widths) != 2:
            raise ConfigError(f"PipConfig.init_widths: expected two widths, got {self.init_widths!r}")

    @property
    def kit(self) -> str:
        return "imu6"

    @classmethod
    def preset(cls, name: str) -> PipConfig:
        """``paper``, ``cpu`` or ``tiny`` (module doc)."""
        if name == "paper":
            return cls()
        if name == "cpu":
            return cls(hidden=128, init_widths=(128, 256), batch_size=16, seq_len=200, window_stride=100, lr=1e-3,
                       lr_schedule="cosine", epochs=12, val_clips=40)
        if name == "tiny":
            return cls(hidden=16, init_widths=(16, 32), dropout=0.0, batch_size=4, seq_len=12, window_stride=6, lr=3e-3,
                       epochs=2, val_clips=2, vel_windows=(1, 3))
        raise ConfigError(f"unknown PIP config preset {name!r}; expected paper, cpu or tiny")
