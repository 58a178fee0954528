"""PIP (Physical Inertial Poser, Yi et al. CVPR 2022): 6 IMUs -> pose, translation, joint
torques and ground reaction forces, online at 60 fps.

- :class:`PipConfig` (presets ``paper``, ``cpu``, ``tiny``);
- :mod:`.data`: training data synthesis (IMUs, contact labels, Eq. 14 joint velocities);
- :class:`PipNet`: the kinematics RNN chain P_L -> P_A -> R_A / V_A / C_F with learned
  initialisation I_PL / I_VA;
- :class:`PipEstimator`: the ``pip`` estimator (physics via :mod:`wearpose.physics`);
- :func:`train_pip`. See ``docs/pip.md``.

This file is the method's declaration (:data:`METHOD`); the names above are imported on first use.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from wearpose.estimators.method import EstimatorEntry, MethodSpec, TrainOption, Training, lazy_exports

if TYPE_CHECKING:
    from wearpose.estimators.pip.config import PipConfig
    from wearpose.estimators.pip.data import imu_features, root_frame_targets
    from wearpose.estimators.pip.estimator import PipEstimator
    from wearpose.estimators.pip.model import PipNet, cumulative_velocity_loss, pip_loss
    from wearpose.estimators.pip.train import train_pip

METHOD = MethodSpec(
    name="pip",
    summary="PIP (Yi et al., CVPR 2022): 6 IMUs -> pose, translation, torques and contact forces, online",
    estimators=(EstimatorEntry("pip", "wearpose.estimators.pip.estimator:PipEstimator",
                               protocol="wearpose.estimators.pip.entry:protocol"),),
    config="wearpose.estimators.pip.config:PipConfig",
    presets=("tiny", "cpu", "paper"),
    kits=("imu6",),
    training=Training(
        mix=True,
        entry="wearpose.estimators.pip.entry:train_from_options",
        doc="""Train PIP's kinematics RNNs (P_L, P_A, R_A, V_A, C_F, I_PL, I_VA) on virtual IMUs (kit imu6).

        Example: wearpose train pip --config cpu --threads 1 --out runs/pip_cpu

        Fine-tune with synthetic sitting: wearpose train pip --config cpu --threads 1 --init-from
        runs/pip_cpu/best.pt --sitting-clips 150 --epochs 2 --lr 3e-4 --out runs/pip_cpu_sit

        Augmented data (3x the corpus: mirrored copies and one speed-changed copy of every clip):
        wearpose train pip --config cpu --threads 1 --mirror --speed-copies 1 --out runs/pip_aug

        The shipped pip_cpu (20 s windows, short clips padded; 200 frames for the sitting clips;
        sit-downs with trunk lean):
        wearpose train pip --config cpu --threads 1 --mirror --speed-copies 1 --sitting-clips 150 --balanced-sitting --sitting-transitions lean --seq-len 1200
        --window-stride 600 --min-window 60 --sitting-window 200 --out runs/pip_lean
        """,
        done="done: best val joint error {best:.1f} mm; checkpoints in {out_dir}",
        options=(
            TrainOption("hidden", None, "Override LSTM width.", int, min=1),
            TrainOption("batch_size", None, "Override the batch size.", int, min=1),
            TrainOption("learned_init", True, "Learned RNN initialisation I_PL / I_VA (off: Table 2 ablation).",
                        flags=("--learned-init/--no-learned-init",)),
            TrainOption("sitting_clips", None, "Add N synthetic sitting clips to train (N/10 to val).", int),
            TrainOption("balanced_sitting", False, "Synthetic sitting clips stand as long as they sit (3-20 s holds).",
                        flags=("--balanced-sitting",)),
            TrainOption("sitting_transitions", None, "How the synthetic sitting clips sit down / stand up: slerp "
                                                     "(no lean) or lean (trunk lean, knees forward).", str),
            TrainOption("sitting_hanging_arms", None, "Fraction of the synthetic sitting clips whose arms hang "
                                                      "nearly straight.", float, min=0.0, max=1.0),
            TrainOption("seq_len", None, "Override the training window length, frames.", int, min=2),
            TrainOption("window_stride", None, "Override the stride between windows, frames.", int, min=1),
            TrainOption("min_window", None, "Clips of at least N frames but shorter than the window train as one "
                                            "padded window (0: left out).", int, min=0),
            TrainOption("sitting_window", None, "Windows of N frames (every N/2) for the synthetic sitting clips "
                                                "(0: as the corpus clips).", int, min=0),
            TrainOption("lr", None, "Override the learning rate.", float),
        ),
        help={"config": "Preset: tiny (smoke test: 8 training clips unless --limit, under a minute), cpu "
                        "(CPU-sized), paper (PIP appendix).",
              "out": "Run directory (default runs/pip_<config>[_noinit]).",
              "limit": "Use only N training clips spread over the split (quick runs)."},
    ),
    demos={"imu6": "wearpose.viewer.demos.pip:run_demo"},
)

__all__ = ["METHOD", "PipConfig", "PipNet", "PipEstimator", "imu_features", "root_frame_targets", "pip_loss",
           "cumulative_velocity_loss", "train_pip"]

__getattr__ = lazy_exports(__name__, {
    "PipConfig": "config", "imu_features": "data", "root_frame_targets": "data", "PipEstimator": "estimator",
    "PipNet": "model", "cumulative_velocity_loss": "model", "pip_loss": "model", "train_pip": "train"})
