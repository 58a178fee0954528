"""``MiposerConfig``: the AvatarPoser-style IK network of MI-Poser (Sec. 4.2) and its data settings.

Presets (:meth:`MiposerConfig.preset`):

- ``paper``: AvatarPoser's network as MI-Poser adopts it (transformer encoder, 3 layers, width
  256, 8 heads) with MI-Poser's training settings: 40-frame windows at 60 Hz with a stride of
  0.1 s (6 frames), Adam, batch 32, learning rate 1e-3 decayed by 0.8 every 20 epochs (we use a
  step schedule approximated by the generic loop's cosine decay to 0.1x over the run, see
  ``lr_schedule``), 100 epochs.
- ``cpu``: the same network (3 layers, d = 256, 8 heads) with a smaller feed-forward width
  (512), trained ``dense`` (causal mask, every frame of a window supervised, windows every 20
  frames): on one shared CPU thread the encoder costs ~20 ms per window, so supervising only
  the last frame would see each training frame about twice in an hour. Batch 32, cosine decay
  from 1e-3, sized to train in about an hour on one CPU thread.
- ``tiny``: a seconds-long smoke-test model (tests, CI).

``model`` selects the network: ``"avatarposer"`` (MI-Poser, 6-DoF head + wrist inputs) or
``"imuposer"`` (the IMU-only 2-layer BiLSTM baseline of Sec. 5.2.2, head + wrist IMUs).
``wrists`` = 2 (kit ``miposer``) or 1 (kit ``miposer1``, the smartwatch variant, left wrist).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

from wearpose.errors import ConfigError
from wearpose.estimators.trainconfig import SimulatedTrainConfig

#: SMPL joints MI-Poser reports (Fig. 5 "upper body"): pelvis (the alignment root), the spine,
#: neck, collars, head, shoulders, elbows and wrists.
UPPER_BODY: tuple[int, ...] = (0, 3, 6, 9, 12, 13, 14, 15, 16, 17, 18, 19, 20, 21)
#: Joints the network predicts rotations for: root (0) + 21 body joints (SMPL 0..21; the hands
#: 22/23 stay at identity as in AvatarPoser).
PREDICTED_JOINTS = 22

#: The rotation loss of the ``cpu`` and ``tiny`` presets (issue 22): geodesic per joint, the spine
#: (SMPL 3, 6, 9) 5x, their twist about the bone hinged beyond 40 deg (the training targets' range).
FIXED_LOSS: dict[str, Any] = {"rot_loss": "geodesic", "spine_rot_weight": 5.0, "lambda_twist": 1.0}
#: The loss fields' defaults (the v1 weights' loss), which :meth:`MiposerConfig.to_dict` leaves out.
LATER_LOSS: dict[str, Any] = {"rot_loss": "l1_6d", "spine_rot_weight": 1.0, "lambda_twist": 0.0, "twist_limit_deg": 40.0}


@dataclass(frozen=True, kw_only=True)
class MiposerConfig(SimulatedTrainConfig):
    """Network, data and optimisation settings (see module doc).

    Network (``avatarposer``): ``d_model`` width, ``layers`` encoder layers, ``heads`` attention
    heads, ``ff`` feed-forward width, ``dropout``; ``dense``: causal attention mask and a pose
    decoded at every frame of the window, all frames from the ``window // 4``-th supervised (the
    ``cpu`` preset: 30 targets per window instead of 1 for the same encoder cost; at run time
    only the last frame is used, as AvatarPoser) -- ``False`` is AvatarPoser's unmasked encoder
    supervised at the last frame; (``imuposer``): ``hidden`` LSTM width per
    direction, ``layers`` LSTM layers.
    Loss: ``lambda_rot`` (L1 on the 21 local 6D rotations), ``lambda_root`` (L1 on the root 6D in
    the heading frame), ``lambda_pos`` (L1 on head-relative joint positions, m), ``lambda_hand``
    (extra weight on the two wrist joints' positions, AvatarPoser's hand alignment term);
    ``rot_loss`` the rotation term: ``"l1_6d"`` (the default, what the v1 weights were trained
    with: L1 on the raw 6D numbers) or ``"geodesic"`` (per-joint angle of the Gram-Schmidt rotation,
    rad, issue 22's waist-tear fix), ``spine_rot_weight`` (geodesic only: the spine joints' weight
    in it), ``lambda_twist`` / ``twist_limit_deg`` (a hinge on the spine joints' twist about the
    bone beyond the limit, rad; 0 = off). The defaults keep a stored config's old loss.
    Data: ``rate`` Hz, ``window`` frames, ``stride`` frames between training windows,
    ``train_noise`` the simulated sensors' error model (``default`` / ``none``;
    :class:`~wearpose.estimators.trainconfig.SimulatedTrainConfig`), ``tpose_s`` /
    ``blend_s`` the calibration T-pose held before each clip and the blend into the clip.
    Optimisation: ``epochs``, and :class:`~wearpose.estimators.trainconfig.TrainConfig`'s
    ``seed``, ``val_clips``, ``lr``, ``lr_schedule``, ``lr_min_factor``, ``batch_size``,
    ``grad_clip``; MI-Poser's default schedule: cosine.
    """

    model: str = "avatarposer"
    wrists: int = 2
    d_model: int = 256
    layers: int = 3
    heads: int = 8
    ff: int = 1024
    dropout: float = 0.1
    dense: bool = False
    hidden: int = 256
    lambda_rot: float = 1.0
    lambda_root: float = 1.0
    lambda_pos: float = 5.0
    lambda_hand: float = 5.0
    rot_loss: str = "l1_6d"
    spine_rot_weight: float = 1.0
    lambda_twist: float = 0.0
    twist_limit_deg: float = 40.0
    rate: float = 60.0
    window: int = 40
    stride: int = 6
    tpose_s: float = 1.0
    blend_s: float = 0.5
    lr_schedule: str = "cosine"
    epochs: int = 100

    def __post_init__(self) -> None:
        super().__post_init__()  # the shared training fields (SimulatedTrainConfig)
        if self.model not in ("avatarposer", "imuposer"):
            raise ConfigError(f"MiposerConfig.model: expected 'avatarposer' or 'imuposer', got {self.model!r}")
        if self.wrists not in (1, 2):
            raise ConfigError(f"MiposerConfig.wrists: expected 1 or 2, got {self.wrists!r}")
        if self.model == "avatarposer" and self.d_model % self.heads:
            raise ConfigError(f"MiposerConfig: d_model {self.d_model} must be divisible by heads {self.heads}")
        if self.window < 2 or self.stride < 1 or self.layers < 1:
            raise ConfigError("MiposerConfig: window >= 2, stride >= 1 and layers >= 1 required")
        if self.rot_loss not in ("l1_6d", "geodesic"):
            raise ConfigError(f"MiposerConfig.rot_loss: expected 'l1_6d' or 'geodesic', got {self.rot_loss!r}")

    def to_dict(self) -> dict[str, Any]:
        """The config as a dict; the loss fields added after the v1 weights (:data:`LATER_LOSS`)
        are left out when all are at those defaults (the v1 loss), so a checkpoint stored before
        them re-saves identically (``from_dict`` fills them in again: the same config)."""
        d = super().to_dict()
        if all(d[k] == v for k, v in LATER_LOSS.items()):
            for k in LATER_LOSS:
                del d[k]
        return d

    @property
    def kit(self) -> str:
        """Sensor kit the data are simulated with (the IMU baseline uses its own head+wrist IMU kit)."""
        if self.model == "imuposer":
            return "imu3-head-wrists"
        return "miposer" if self.wrists == 2 else "miposer1"

    @property
    def roles(self) -> tuple[str, ...]:
        """Input roles, head first: the calibration's target joints (SMPL 15, 20, 21)."""
        return ("head", "left_wrist", "right_wrist")[: 1 + self.wrists]

    @classmethod
    def preset(cls, name: str, wrists: int = 2, model: str = "avatarposer") -> MiposerConfig:
        """``paper``, ``cpu`` or ``tiny`` for ``wrists`` = 2 / 1 and ``model``."""
        base = cls(model=model, wrists=wrists)
        if model == "imuposer":
            # IMUPoser: 2-layer bidirectional LSTM (Mollyn et al. 2023), 256 units per direction;
            # trained on 1.5 s windows (the BiLSTM sees the whole window, offline; most corpus
            # clips are 2-5 s long).
            base = replace(base, layers=2, hidden=256, window=90, stride=30)
        if name == "paper":
            return base
        if name == "cpu":
            if model == "imuposer":
                return replace(base, batch_size=32, epochs=10, val_clips=60)
            return replace(base, ff=512, dense=True, stride=20, batch_size=32, epochs=3, val_clips=60, **FIXED_LOSS)
        if name == "tiny":
            return replace(base, d_model=32, layers=1, heads=4, ff=64, hidden=32, batch_size=8, epochs=1, dense=True,
                           window=12 if model == "avatarposer" else 24, stride=6, lr=3e-3, val_clips=2, dropout=0.0,
                           tpose_s=0.5, blend_s=0.25, **(FIXED_LOSS if model == "avatarposer" else {}))
        raise ConfigError(f"unknown MI-Poser config preset {name!r}; expected paper, cpu or tiny")
