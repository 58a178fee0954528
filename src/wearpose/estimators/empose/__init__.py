"""EM-POSE (Kaufmann et al., ICCV 2021): SMPL pose and shape from 6 or 12 EM sensors by
learned gradient descent (LGD-RNN). See :mod:`.model` for the network, :mod:`.data` for the
training data, :mod:`.estimator` for the protocol implementation, :mod:`.train` for training
and evaluation, :mod:`.baselines` / :mod:`.twostage` / :mod:`.optimization` for the Table 2
baselines, the two-stage model and the L-BFGS optimiser.

This file is the method's declaration (:data:`METHOD`); the names below are imported on first use.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from wearpose.estimators.method import EstimatorEntry, MethodSpec, TrainOption, Training, lazy_exports

if TYPE_CHECKING:
    from wearpose.estimators.empose.config import EmposeConfig
    from wearpose.estimators.empose.estimator import EmposeEstimator
    from wearpose.estimators.empose.model import LGDRNN, PRED_JOINTS, UNOBSERVED_JOINTS, VirtualSensors, lgd_loss
    from wearpose.estimators.empose.train import evaluate_empose, train_empose

_P = "wearpose.estimators.empose"
#: Every EM-POSE network is compared with the others on the same simulations.
_COMPARE = f"{_P}.evaluate:evaluate_models"

METHOD = MethodSpec(
    name="empose",
    summary="EM-POSE (Kaufmann et al., ICCV 2021): pose and shape from 6 or 12 EM sensors, LGD-RNN",
    estimators=(
        EstimatorEntry("empose", f"{_P}.estimator:EmposeEstimator", compare=_COMPARE),
        EstimatorEntry("empose-resnet", f"{_P}.baselines:ResNetEstimator", compare=_COMPARE),
        EstimatorEntry("empose-birnn", f"{_P}.baselines:BiRNNEstimator", compare=_COMPARE),
        EstimatorEntry("empose-twostage", f"{_P}.twostage:TwoStageEstimator", compare=_COMPARE),
        EstimatorEntry("empose-lbfgs", f"{_P}.optimization:LbfgsEstimator",
                       evaluated_by="python benchmarks/empose_lbfgs.py"),
    ),
    config=f"{_P}.config:EmposeConfig",
    presets=("tiny", "cpu", "paper"),
    kits=("em12", "em6"),
    training=Training(
        entry=f"{_P}.entry:train_from_options",
        doc="""Train EM-POSE (LGD-RNN or a Table 2 baseline) on virtual EM sensors.

        Example: wearpose train empose --sensors 12 --config cpu --threads 1 --out runs/empose12_cpu
        Table 3 row: wearpose train empose --ablation no_t --epochs 3 --threads 1 --out runs/t3_no_t
        """,
        done="done: best val MPJPE {best:.1f} mm; checkpoints in {out_dir}",
        options=(
            TrainOption("sensors", 12, "Number of sensors: 12 (kit em12) or 6 (kit em6)."),
            TrainOption("model", "lgd", "empose network: lgd (LGD-RNN), a Table 2 baseline: resnet, birnn, or "
                                        "twostage (joint mapper + LGD IK for dropped sensors, supp. Sec. 9)."),
            TrainOption("hidden", None, "Override LSTM width.", int, min=1),
            TrainOption("width", None, "Override the update-MLP width.", int),
            TrainOption("iterations", None, "Override N, the LGD iterations.", int),
            TrainOption("batch_size", None, "Override the batch size.", int, min=1),
            TrainOption("offsets", None, "Subject offsets in training data: random (default) or none "
                                         "(EM-POSE's 'no [R|t]' ablation).", str),
            TrainOption("ablation", None, "An EM-POSE Table 3 ablation of the LGD-RNN: noRt, no_t, "
                                          "ori_only, pos_only, no_rnn (or full).", str),
        ),
        help={"config": "Preset: tiny (smoke test: 8 training clips unless --limit, under a minute), cpu "
                        "(CPU-sized), paper (supp. Table 5).",
              "out": "Run directory (default runs/<method><sensors>_<config>)."},
    ),
    demos={"em12": "wearpose.cli.demo:run_sensor_demo", "em6": "wearpose.cli.demo:run_sensor_demo_em6"},
)

__all__ = ["METHOD", "EmposeConfig", "EmposeEstimator", "LGDRNN", "PRED_JOINTS", "UNOBSERVED_JOINTS",
           "VirtualSensors", "lgd_loss", "evaluate_empose", "train_empose"]

__getattr__ = lazy_exports(__name__, {
    "EmposeConfig": "config", "EmposeEstimator": "estimator", "LGDRNN": "model", "PRED_JOINTS": "model",
    "UNOBSERVED_JOINTS": "model", "VirtualSensors": "model", "lgd_loss": "model", "evaluate_empose": "train",
    "train_empose": "train"})
