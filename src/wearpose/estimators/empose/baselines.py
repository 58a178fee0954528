"""The learned baselines of EM-POSE Table 2 (main paper Sec. 6.2, supp. Sec. 4): direct regression
of SMPL pose and shape from the EM measurements, no body model in the loop.

- :class:`ResNetBaseline` (``model="resnet"``): frame-wise. The frame's sensor features
  ``x_t`` (:func:`~wearpose.estimators.empose.model.sensor_features`) go through a dense layer
  to ``cfg.width``, then ``cfg.mlp_layers`` (5) residual blocks ``h <- ReLU(h + W h)`` (supp. 4:
  "a dense layer that maps to the same size as its input, followed by a skip connection and a
  ReLU"), and a dense layer to ``Omega_t``. Causal (one frame), so it also runs online.
- :class:`BiRNNBaseline` (``model="birnn"``): ``cfg.rnn_layers`` (2) bidirectional LSTM layers of
  ``cfg.hidden`` (256 in the paper) units per direction; the forward and backward states of the
  last layer are mapped to ``Omega_t`` by a dense layer. Offline only (``causal=False``).

Both see exactly what the LGD-RNN sees: the same simulated training data (:func:`build_split`:
per-sequence random subject offsets applied to the virtual sensors, the "offsets analogous to
Sec. 5.3" of the paper, the same EM noise, the same source-relative normalisation and the same
input dropout ``cfg.dropout_input``), the same ``Omega`` parameterisation (20 rotations in
``cfg.rep`` + 10 betas, predicted around the rest pose) and the same loss,
:func:`~wearpose.estimators.empose.model.lgd_loss` on the single estimate with ``lambda_rec =
0``: pose MSE, shape MSE of the per-window mean betas, 3D joint MSE (the paper uses an L1 shape
loss for the baselines; we keep one loss for all three models). They do **not** receive the
subject offsets ``O_p`` as input, and there is no L_r and no LGD: that is the difference Table 2
measures.

Hyper-parameters (:func:`baseline_config`): supp. Table 6 where it differs from the LGD-RNN
preset (joint loss weight 10), the rest from the ``EmposeConfig`` preset (``cpu``: 6D pose,
32-frame windows, batch 32, lr 5e-4 cosine). ResNet width is 1024 in the paper
(``paper`` preset) and 512 in the ``cpu`` preset.

Estimators: :class:`ResNetEstimator` (registry ``empose-resnet``) and :class:`BiRNNEstimator`
(``empose-birnn``), subclasses of :class:`~wearpose.estimators.empose.EmposeEstimator` that
reuse its checkpoints (kit / body / site checks), input checks and dropped-sample policy
(held at the last valid value; frames with any dropped sensor are ``valid=False``). Output frame
as the LGD-RNN: root orientation relative to the EM source, no translation.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np
import torch
from torch import nn

from wearpose.errors import ConfigError
from wearpose.estimators.base import OfflineOnlyError, PoseFrame, PoseTrack, SensorFrame
from wearpose.estimators.empose.config import EmposeConfig
from wearpose.estimators.empose.data import EmposeData
from wearpose.estimators.empose.estimator import EmposeEstimator
from wearpose.body.skeleton import NUM_JOINTS
from wearpose.estimators.empose.model import (
    NUM_BETAS, SENSOR_FEATURES, decode_omega, encode_pose, omega_dim, sensor_features,
)
from wearpose.estimators.registry import register_estimator
from wearpose.estimators.seeding import init_seed, seeded
from wearpose.estimators.checkpoint import load_checkpoint
from wearpose.estimators.empose.train import EmposeTask
from wearpose.estimators.empose.twostage import TwoStageEstimator
from wearpose.estimators.empose.twostage import twostage_config

#: Config model name -> registry name of the estimator.
ESTIMATOR_NAMES: dict[str, str] = {"lgd": "empose", "resnet": "empose-resnet", "birnn": "empose-birnn",
                                   "twostage": "empose-twostage"}


def baseline_config(preset: str, sensors: int, model: str) -> EmposeConfig:
    """The config of a Table 2 baseline: ``EmposeConfig.preset(preset, sensors)`` with
    ``model`` set and supp. Table 6's joint loss weight 10 (no L_r); ResNet width 1024 for
    ``paper``, 512 for ``cpu``; BiRNN 2 x 256 per direction. Windows, batch size and learning
    rate stay the preset's: Table 6's 128-frame training sequences would drop every validation
    clip of our corpus (all shorter than 128 frames at 30 Hz) and a quarter of the training
    frames, so the baselines train on the LGD-RNN's 32-frame windows. The ``tiny`` preset keeps
    its tiny sizes. ``model="lgd"`` returns the preset unchanged."""
    base = EmposeConfig.preset(preset, sensors)
    if model == "lgd":
        return base
    if model == "twostage":

        return twostage_config(preset, sensors)
    if model not in ("resnet", "birnn"):
        raise ConfigError(f"model: expected lgd, resnet or birnn, got {model!r}")
    kw: dict[str, Any] = {"model": model, "lambda_joints": 10.0, "lambda_rec": 0.0, "iterations": 0,
                          "supervise_initial": True}
    if preset == "paper":
        kw.update(width=1024, hidden=256, lr=5e-4)
    elif preset == "cpu":
        kw.update(width=512, hidden=256)
    return replace(base, **kw)


class _OmegaHead(nn.Module):
    """Shared output layer: features ``(..., H)`` -> ``Omega`` ``(..., D)`` around the rest pose."""

    def __init__(self, in_dim: int, rep: str) -> None:
        super().__init__()
        self.rep = rep
        self.head = nn.Linear(in_dim, omega_dim(rep))
        ident = torch.eye(3).expand(NUM_JOINTS, 3, 3)
        self.register_buffer("omega_rest", torch.cat([encode_pose(ident, rep), torch.zeros(NUM_BETAS)]))

    def forward(self, h: torch.Tensor) -> torch.Tensor:
        return self.head(h) + self.omega_rest


class _BaselineNet(nn.Module):
    """What both learned baselines share: ``cfg``, ``rep``, ``num_sensors`` (S), ``in_dim`` (the
    per-frame features, S * 12), ``omega_dim`` (D of ``rep``) and the input dropout."""

    def __init__(self, cfg: EmposeConfig, num_sensors: int) -> None:
        super().__init__()
        self.cfg, self.rep, self.num_sensors = cfg, cfg.rep, num_sensors
        self.in_dim, self.omega_dim = num_sensors * SENSOR_FEATURES, omega_dim(cfg.rep)
        self.input_dropout = nn.Dropout(cfg.dropout_input)


class ResNetBaseline(_BaselineNet):
    """Frame-wise residual MLP (see module doc).

    Args:
        cfg: ``width`` (block width), ``mlp_layers`` (residual blocks, 5), ``rep``,
            ``dropout_input``.
        num_sensors: S.
    """

    def __init__(self, cfg: EmposeConfig, num_sensors: int) -> None:
        super().__init__(cfg, num_sensors)
        F = self.in_dim
        self.inp = nn.Linear(F, cfg.width)
        self.blocks = nn.ModuleList(nn.Linear(cfg.width, cfg.width) for _ in range(cfg.mlp_layers))
        self.out = _OmegaHead(cfg.width, cfg.rep)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """``x`` ``(..., S * 12)`` sensor features (any leading shape, frames independent) ->
        ``Omega`` ``(..., D)``."""
        h = torch.relu(self.inp(self.input_dropout(x)))
        for blk in self.blocks:
            h = torch.relu(h + blk(h))
        return self.out(h)


class BiRNNBaseline(_BaselineNet):
    """Bidirectional LSTM over the sequence (see module doc).

    Args:
        cfg: ``hidden`` (units per direction), ``rnn_layers`` (2), ``rep``, ``dropout_input``.
        num_sensors: S.
    """

    def __init__(self, cfg: EmposeConfig, num_sensors: int) -> None:
        super().__init__(cfg, num_sensors)
        F = self.in_dim
        self.rnn = nn.LSTM(F, cfg.hidden, cfg.rnn_layers, batch_first=True, bidirectional=True)
        self.out = _OmegaHead(2 * cfg.hidden, cfg.rep)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """``x`` ``(B, T, S * 12)`` -> ``Omega`` ``(B, T, D)`` (every frame sees the whole window)."""
        h, _ = self.rnn(self.input_dropout(x))
        return self.out(h)


def build_baseline(cfg: EmposeConfig, num_sensors: int) -> nn.Module:
    """The network of ``cfg.model`` (``resnet`` / ``birnn``)."""
    if cfg.model == "resnet":
        return ResNetBaseline(cfg, num_sensors)
    if cfg.model == "birnn":
        return BiRNNBaseline(cfg, num_sensors)
    raise ConfigError(f"EmposeConfig.model={cfg.model!r} is not a baseline (resnet, birnn)")


def baseline_outputs(model: nn.Module, body: Any, x: torch.Tensor) -> dict[str, torch.Tensor]:
    """Run a baseline on a batch and pose the body.

    Args:
        model: :class:`ResNetBaseline` / :class:`BiRNNBaseline`.
        body: the :class:`~wearpose.body.BodyModel` (joints for the joint loss / metrics).
        x: ``(B, T, S * 12)`` features.

    Returns:
        ``omega`` ``(B, T, D)``, ``local_rot`` ``(B, T, 24, 3, 3)`` (unobserved joints = I, root
        in the source frame), ``betas`` ``(B, T, 10)``, ``joints`` ``(B, T, 24, 3)`` m (zero
        translation) and ``rec`` ``(B, T)`` zeros (no L_r): the keys of one
        :meth:`LGDRNN.forward` iteration, so :func:`lgd_loss` and the LGD validation apply.
    """
    B, T = x.shape[:2]
    omega = model(x)
    R, b = decode_omega(omega, model.rep)
    joints = body(R.reshape(B * T, NUM_JOINTS, 3, 3), b.reshape(B * T, NUM_BETAS), None,
                  return_vertices=False).joints.reshape(B, T, NUM_JOINTS, 3)
    return {"omega": omega, "local_rot": R, "betas": b, "joints": joints, "rec": x.new_zeros(B, T)}


def _make_task(est: BaselineEstimator, train_data: EmposeData, val_data: EmposeData | None) -> Any:

    class BaselineTask(EmposeTask):
        """:class:`EmposeTask` (same batches, loss and validation) with the baseline's forward."""

        def _forward(self, b: dict[str, torch.Tensor], device: torch.device, train: bool):
            b = {k: v.to(device) for k, v in b.items()}
            x = sensor_features(b["position"], b["orientation"])
            return [baseline_outputs(self.model, self.est.body, x)], b

        def validate(self, device: torch.device) -> dict[str, float]:
            out = super().validate(device)
            out.pop("val_mpjpe_rnn_mm", None)  # = val_mpjpe_mm: there is no LGD stage
            return out

    return BaselineTask(est, train_data, val_data)


class BaselineEstimator(EmposeEstimator):
    """Common part of the two baseline estimators (module doc). ``config.model`` picks the
    network; everything else (checkpoints, input checks, training data) is the LGD-RNN's."""

    model_name = "?"

    def __init__(self, config: EmposeConfig | None = None, body: Any = None, device: str | torch.device = "cpu") -> None:
        config = config or baseline_config("cpu", 12, self.model_name)
        if config.model != self.model_name:
            raise ConfigError(f"{type(self).__name__} needs EmposeConfig.model={self.model_name!r}, got {config.model!r}")
        super().__init__(config, body=body, device=device)
        with seeded(init_seed(self.config.seed)):  # initial weights: a function of the seed (issue 24)
            self.model = build_baseline(self.config, len(self.sensor_names)).to(self.device)

    def make_task(self, train_data: EmposeData, val_data: EmposeData | None) -> Any:
        """The training task for :func:`~wearpose.estimators.empose.train.train_empose`."""
        return _make_task(self, train_data, val_data)

    def _inputs(self, recording: Any) -> tuple[torch.Tensor, torch.Tensor]:
        """Features ``(T, S * 12)`` of a recording (dropped samples held) and ``valid`` ``(T,)``."""
        p, R, valid = self._measurements(recording)
        return sensor_features(p, R), valid.all(1)

    def _omega(self, x: torch.Tensor) -> torch.Tensor:
        """``(T, F)`` -> ``(T, D)`` for a whole sequence."""
        raise NotImplementedError

    @torch.no_grad()
    def estimate(self, recording: Any) -> PoseTrack:
        """Offline estimate of a whole recording (the subject offsets are not used).

        Returns a :class:`PoseTrack`: ``local_rot`` ``(T, 24, 3, 3)`` (root in the EM source
        frame), ``betas`` ``(10,)`` the mean over frames with all sensors valid, ``trans=None``,
        ``valid`` ``(T,)`` all sensors valid; ``extras``: ``frame="em_source"``, ``method``,
        ``betas_per_frame`` ``(T, 10)``.
        """
        x, ok = self._inputs(recording)
        self.model.eval()
        omega = self._omega(x.to(self.device)).cpu()
        local_rot, b_all = decode_omega(omega, self.model.rep)
        beta = (b_all[ok] if bool(ok.any()) else b_all).mean(0)
        return PoseTrack(local_rot, beta, None, ok, self.fps,
                         extras={"frame": "em_source", "method": self.name, "betas_per_frame": b_all})


@register_estimator("empose-resnet")
class ResNetEstimator(BaselineEstimator):
    """EM-POSE's frame-wise ResNet baseline behind the Estimator protocol (causal, online)."""

    name = "empose-resnet"
    model_name = "resnet"
    causal = True
    lookahead = 0

    def _omega(self, x: torch.Tensor, chunk: int = 8192) -> torch.Tensor:
        return torch.cat([self.model(x[a:a + chunk]) for a in range(0, x.shape[0], chunk)]) if x.shape[0] else \
            self.model(x)

    @torch.no_grad()
    def step(self, frame: SensorFrame) -> PoseFrame:
        """One frame, independent of the past except for holding dropped samples at the last
        valid value (neutral values before any). Returns a :class:`PoseFrame` (root in the EM
        source frame, the frame's own betas)."""
        (p, R), v = self._input(frame)
        self.model.eval()
        omega = self.model(sensor_features(p, R)[None].to(self.device)).cpu()
        rot, b = decode_omega(omega, self.model.rep)
        return PoseFrame(rot[0], b[0], None, bool(v.all()), frame.timestamp, extras={"frame": "em_source"})


@register_estimator("empose-birnn")
class BiRNNEstimator(BaselineEstimator):
    """EM-POSE's bidirectional-LSTM baseline behind the Estimator protocol (offline only:
    :meth:`step` raises :class:`OfflineOnlyError`)."""

    name = "empose-birnn"
    model_name = "birnn"
    causal = False
    lookahead = 0  # not windowed: the whole sequence

    def _omega(self, x: torch.Tensor) -> torch.Tensor:
        return self.model(x[None])[0]

    def step(self, frame: SensorFrame) -> PoseFrame:
        raise OfflineOnlyError("empose-birnn is a bidirectional (non-causal) model: use estimate(recording) on a "
                               "whole sequence; for streaming use empose (LGD-RNN) or empose-resnet")


def estimator_class(model: str) -> type[EmposeEstimator]:
    """``lgd`` / ``resnet`` / ``birnn`` / ``twostage`` -> the estimator class (ConfigError otherwise)."""

    classes: dict[str, type[EmposeEstimator]] = {"lgd": EmposeEstimator, "resnet": ResNetEstimator,
                                                 "birnn": BiRNNEstimator, "twostage": TwoStageEstimator}
    if model not in classes:
        raise ConfigError(f"model: expected lgd, resnet, birnn or twostage, got {model!r}")
    return classes[model]


def load_any(path: Any, **kw: Any) -> EmposeEstimator:
    """Load an EM-POSE-family checkpoint (LGD-RNN or a baseline) by its ``method`` field."""

    ck = load_checkpoint(path)
    cls = {v: estimator_class(k) for k, v in ESTIMATOR_NAMES.items()}.get(ck.method)
    if cls is None:
        raise ConfigError(f"{path}: checkpoint method {ck.method!r} is not an EM-POSE model "
                          f"({', '.join(ESTIMATOR_NAMES.values())})")
    return cls.from_checkpoint(ck, kit=kw.get("kit"), body=kw.get("body"), device=kw.get("map_location", "cpu"), path=path)
