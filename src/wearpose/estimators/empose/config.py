"""``EmposeConfig``: LGD-RNN hyper-parameters (EM-POSE supp. Table 5) and data settings.

Presets (:meth:`EmposeConfig.preset`):

- ``paper``: Table 5 exactly, per sensor count (LSTM 2x512, MLP 512 x 5 layers, N = 4 / 2,
  alpha = 0.1, batch 12, sequence length 32, 50 epochs, lr 1e-4 (12) / 5e-4 (6), dropout 0.2 /
  0.0, lambdas (1, 1, 1, 0.01) for 12 and (10, 1, 0.1, 0.01) for 6), and the pose in
  axis-angle as Sec. 5.1 writes it (theta_t in R^{J*3}).
- ``cpu``: the same model at CPU scale: LSTM 2x256, MLP 256 x 5 layers, N = 3 (12) / 2 (6),
  pose in 6D (DESIGN's network convention: continuous, no wrap-around at pi for the additive
  update),
  batch 32 (more frames per optimiser step amortise Python overhead on CPU), lr 5e-4 with a
  cosine decay, 20 epochs. Loss weights and dropout as Table 5.
- ``tiny``: a few-second smoke-test model (CI).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

from wearpose.errors import ConfigError
from wearpose.estimators.trainconfig import SimulatedTrainConfig


#: Settings of the estimator at inference, not of the trained network: a checkpoint's values are
#: not restored when it is loaded (:meth:`~wearpose.estimators.empose.EmposeEstimator.from_checkpoint`), so every
#: checkpoint gets today's defaults and ``--set`` / ``set_*`` change them (a checkpoint trained
#: before a default changed kept the old one, e.g. the refinement's solver and weight).
INFERENCE_FIELDS = ("refine_steps", "refine_threshold", "refine_weight", "refine_solver", "refine_centre",
                    "refine_centre_frames", "refine_centre_every", "shape_fit_frames", "shape_fit_steps", "shape_fit_prior")


@dataclass(frozen=True, kw_only=True)
class EmposeConfig(SimulatedTrainConfig):
    """LGD-RNN and training settings.

    Model: ``hidden`` LSTM width (``rnn_layers`` layers), ``width`` / ``mlp_layers`` of the
    update network N, ``iterations`` = N LGD steps, ``alpha`` step size (Eq. 5), ``rep`` the pose
    parameterisation of Omega (``"rot6d"`` or ``"axis_angle"``; the paper writes theta in
    R^{J*3}, axis-angle).
    Losses (Sec. 5.3): ``lambda_pose``, ``lambda_shape``, ``lambda_joints``, ``lambda_rec``;
    ``supervise_initial`` adds the loss on Omega^(0) (the paper sums n = 1..N only).
    Data: ``sensors`` 12 / 6 (kits ``em12`` / ``em6``), ``rate`` Hz, ``seq_len`` frames per
    training window, ``window_stride`` frames between window starts, ``train_noise`` the EM error
    model of the training simulation (``"default"`` / ``"none"``, checked by
    :class:`~wearpose.estimators.trainconfig.SimulatedTrainConfig`), ``offsets`` subject offsets
    (``"random"`` synthetic subjects per sequence; ``"rot"`` = their rotations only, translations
    zero in the training data and in L_r, the "no t" ablation of Table 3; ``"none"`` = identity,
    the "no [R|t]" ablation).
    Ablations of Table 3 (defaults = the full model): ``inputs`` the measured modalities the
    network sees and L_r compares (``"both"``; ``"position"`` = "pos only", ``"orientation"`` =
    "ori only"), ``init`` the start of LGD (``"rnn"`` = Omega^(0) from the RNN; ``"mean"`` = "no
    RNN": one learned constant Omega^(0) for every frame, initialised at the mean training pose
    and mean shape, so LGD runs frame-wise like the original LGD).
    Optimisation: ``epochs``, and :class:`~wearpose.estimators.trainconfig.TrainConfig`'s
    ``seed``, ``val_clips``, ``lr``, ``lr_schedule`` (``constant`` / ``cosine``),
    ``lr_min_factor``, ``batch_size``, ``grad_clip``; EM-POSE's defaults: lr 1e-4, batch 12.
    Network: ``model`` = ``"lgd"`` (LGD-RNN, default) or a learned baseline of Table 2,
    ``"twostage"`` (:mod:`wearpose.estimators.empose.twostage`, supp. Sec. 9) or
    ``"resnet"`` / ``"birnn"`` (:mod:`wearpose.estimators.empose.baselines`; ``width`` /
    ``mlp_layers`` are the ResNet's width / residual blocks, ``hidden`` / ``rnn_layers`` the
    BiRNN's).
    Two-stage model only: ``ik`` its stage 2, ``"lgd"`` (the paper's LGD IK, default) or
    ``"closed"`` (closed-form pose from the mapped orientations, :mod:`.twostage`);
    ``mapper_input`` what its joint mapper sees per sensor, ``"raw"`` (the measurement, default)
    or ``"site"`` (the skin-site pose the measurement and the subject offsets imply).
    Measurement-consistency refinement at inference (:mod:`wearpose.estimators.empose.refine`;
    issue 24): ``refine_steps`` solver iterations on L_r plus the pose prior after the learned
    updates (0 = off, the trained model as it is), on the frames whose L_r exceeds
    ``refine_threshold`` (m^2 + squared Frobenius, summed over sensors; 0 = every frame, the
    default; a gate calibrated on validation clips,
    :func:`~wearpose.estimators.empose.refine.calibrate_threshold`; None = not calibrated, which
    refuses ``refine_steps > 0``); ``refine_weight`` the prior's weight (L_r per squared 6D unit;
    1e-3: docs/empose.md); ``refine_solver`` ``"gn"`` (Levenberg-Marquardt Gauss-Newton on the
    residuals, :func:`~wearpose.estimators.empose.refine.gauss_newton`, default) or ``"lbfgs"``;
    ``refine_centre`` where the prior is centred, ``"learned"`` (each frame's learned estimate,
    default) or ``"recording"`` (the learned estimate turned by one rotation per joint for the
    recording, :func:`~wearpose.estimators.empose.refine.recording_turn`), measured on
    ``refine_centre_frames`` frames with every sensor valid: 0 = the whole recording (offline
    only, the default), n > 0 = its first n, used from the n-th such frame on (online, and
    offline the same, so an offline figure is what a stream gets); ``refine_centre_every`` k > 0
    (with n > 0) adds every k-th valid frame after the n-th to the turn, which is then measured
    again on every frame so far that was measured (0 = the first n only, the default); n = 1 with
    k = 1 is the running turn, each frame turned by the turn over the valid frames up to it
    (the online form chosen on validation: docs/empose.md, "The running turn").
    Training ignores them, and a checkpoint does not restore them (:data:`INFERENCE_FIELDS`).
    Per-recording shape fit at inference (:mod:`wearpose.estimators.empose.shapefit`; issue
    24): ``shape_fit_frames`` frames with every sensor valid on which one body shape is fitted
    to L_r jointly with their poses (0 = off: the learned shape), ``shape_fit_steps`` L-BFGS
    iterations, ``shape_fit_prior`` the weight of ``||beta||^2`` (L_r units). Training ignores
    them.
    """

    sensors: int = 12
    hidden: int = 512
    rnn_layers: int = 2
    width: int = 512
    mlp_layers: int = 5
    iterations: int = 4
    alpha: float = 0.1
    rep: str = "rot6d"
    dropout_input: float = 0.2
    dropout_mlp: float = 0.2
    lambda_pose: float = 1.0
    lambda_shape: float = 1.0
    lambda_joints: float = 1.0
    lambda_rec: float = 0.01
    supervise_initial: bool = False
    rate: float = 30.0
    seq_len: int = 32
    window_stride: int = 16
    offsets: str = "random"
    lr: float = 1e-4
    batch_size: int = 12
    epochs: int = 50
    model: str = "lgd"
    inputs: str = "both"
    init: str = "rnn"
    ik: str = "lgd"
    mapper_input: str = "raw"
    refine_steps: int = 0
    refine_threshold: float | None = 0.0
    refine_weight: float = 1e-3
    refine_solver: str = "gn"
    refine_centre: str = "learned"
    refine_centre_frames: int = 0
    refine_centre_every: int = 0
    shape_fit_frames: int = 0
    shape_fit_steps: int = 80
    shape_fit_prior: float = 1e-3

    def __post_init__(self) -> None:
        super().__post_init__()  # the shared training fields (SimulatedTrainConfig)
        if self.sensors not in (6, 12):
            raise ConfigError(f"EmposeConfig.sensors: expected 6 or 12, got {self.sensors!r}")
        if self.rep not in ("rot6d", "axis_angle"):
            raise ConfigError(f"EmposeConfig.rep: expected 'rot6d' or 'axis_angle', got {self.rep!r}")
        if self.iterations < 0 or self.mlp_layers < 1 or self.rnn_layers < 1:
            raise ConfigError("EmposeConfig: iterations >= 0, mlp_layers >= 1 and rnn_layers >= 1 required")
        if self.offsets not in ("random", "rot", "none"):
            raise ConfigError(f"EmposeConfig.offsets: expected 'random', 'rot' or 'none', got {self.offsets!r}")
        if self.inputs not in ("both", "position", "orientation"):
            raise ConfigError(f"EmposeConfig.inputs: expected 'both', 'position' or 'orientation', got {self.inputs!r}")
        if self.init not in ("rnn", "mean"):
            raise ConfigError(f"EmposeConfig.init: expected 'rnn' or 'mean', got {self.init!r}")
        if self.ik not in ("lgd", "closed"):
            raise ConfigError(f"EmposeConfig.ik: expected 'lgd' or 'closed', got {self.ik!r}")
        if self.mapper_input not in ("raw", "site"):
            raise ConfigError(f"EmposeConfig.mapper_input: expected 'raw' or 'site', got {self.mapper_input!r}")
        if isinstance(self.refine_steps, bool) or not isinstance(self.refine_steps, int) or self.refine_steps < 0:
            raise ConfigError(f"EmposeConfig.refine_steps: expected a whole number >= 0, got {self.refine_steps!r}")
        if self.refine_threshold is not None and not self.refine_threshold >= 0.0:
            raise ConfigError(f"EmposeConfig.refine_threshold: expected an L_r level >= 0 or None, "
                              f"got {self.refine_threshold!r}")
        if not self.refine_weight >= 0.0:
            raise ConfigError(f"EmposeConfig.refine_weight: expected a weight >= 0, got {self.refine_weight!r}")
        if self.refine_centre not in ("learned", "recording"):
            raise ConfigError(f"EmposeConfig.refine_centre: expected 'learned' or 'recording', got {self.refine_centre!r}")
        for key, zero in (("refine_centre_frames", "the whole recording"), ("refine_centre_every", "the first frames only")):
            v = getattr(self, key)
            if isinstance(v, bool) or not isinstance(v, int) or v < 0:
                raise ConfigError(f"EmposeConfig.{key}: expected a whole number >= 0 (0 = {zero}), got {v!r}")
        if self.refine_solver not in ("lbfgs", "gn"):
            raise ConfigError(f"EmposeConfig.refine_solver: expected 'lbfgs' or 'gn', got {self.refine_solver!r}")
        for key in ("shape_fit_frames", "shape_fit_steps"):
            v = getattr(self, key)
            if isinstance(v, bool) or not isinstance(v, int) or v < 0:
                raise ConfigError(f"EmposeConfig.{key}: expected a whole number >= 0, got {v!r}")
        if not self.shape_fit_prior >= 0.0:
            raise ConfigError(f"EmposeConfig.shape_fit_prior: expected a weight >= 0, got {self.shape_fit_prior!r}")
        if self.model not in ("lgd", "resnet", "birnn", "twostage"):
            raise ConfigError(f"EmposeConfig.model: expected 'lgd', 'resnet', 'birnn' or 'twostage', got {self.model!r}")

    @property
    def kit(self) -> str:
        return f"em{self.sensors}"

    @classmethod
    def preset(cls, name: str, sensors: int = 12) -> EmposeConfig:
        """``paper`` (Table 5), ``cpu`` or ``tiny`` for ``sensors`` = 12 or 6."""
        if sensors == 12:
            paper = cls(sensors=12)
        elif sensors == 6:
            paper = cls(sensors=6, iterations=2, dropout_input=0.0, dropout_mlp=0.0, lambda_pose=10.0,
                        lambda_joints=0.1, lr=5e-4)
        else:
            raise ConfigError(f"sensors: expected 6 or 12, got {sensors!r}")
        if name == "paper":
            return replace(paper, rep="axis_angle")
        if name == "cpu":
            return replace(paper, hidden=256, width=256, iterations=3 if sensors == 12 else 2, batch_size=32,
                           lr=5e-4, lr_schedule="cosine", epochs=20, val_clips=60)
        if name == "tiny":
            return replace(paper, hidden=32, width=32, mlp_layers=2, iterations=1, batch_size=4, seq_len=8,
                           window_stride=8, lr=3e-3, epochs=2, dropout_input=0.0, dropout_mlp=0.0, val_clips=2)
        raise ConfigError(f"unknown EM-POSE config preset {name!r}; expected paper, cpu or tiny")


#: EM-POSE Table 3 rows: ablation key -> (label, :class:`EmposeConfig` overrides of the full model).
TABLE3_ABLATIONS: dict[str, tuple[str, dict[str, Any]]] = {
    "noRt": ("no [R,t]", {"offsets": "none"}),
    "no_t": ("no t", {"offsets": "rot"}),
    "ori_only": ("ori only", {"inputs": "orientation"}),
    "pos_only": ("pos only", {"inputs": "position"}),
    "no_rnn": ("no RNN", {"init": "mean"}),
    "full": ("full", {}),
}


def ablation_config(cfg: EmposeConfig, ablation: str) -> EmposeConfig:
    """``cfg`` with the overrides of the Table 3 row ``ablation`` (a key of :data:`TABLE3_ABLATIONS`)."""
    if ablation not in TABLE3_ABLATIONS:
        raise ConfigError(f"unknown EM-POSE ablation {ablation!r}; expected one of {sorted(TABLE3_ABLATIONS)}")
    return replace(cfg, **TABLE3_ABLATIONS[ablation][1])
