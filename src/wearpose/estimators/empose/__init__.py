"""EM-POSE (Kaufmann et al., ICCV 2021): SMPL pose and shape from 6 or 12 EM sensors by
learned gradient descent (LGD-RNN). See :mod:`.model` for the network, :mod:`.data` for the
training data, :mod:`.estimator` for the protocol implementation, :mod:`.train` for training
and evaluation, :mod:`.baselines` / :mod:`.twostage` / :mod:`.optimization` for the Table 2
baselines, the two-stage model and the L-BFGS optimiser.

This file is the method's declaration (:data:`METHOD`); the names below are imported on first use.
"""

from __future__ import annotations

from pathlib import Path
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
        mix=True,
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
            TrainOption("lr", None, "Override the learning rate.", float),
            TrainOption("lambda_shape", None, "Override the shape loss weight (default 1: betas' squared error, "
                                              "which outweighs the pose loss tenfold when wearers vary).", float,
                        min=0.0),
            TrainOption("offsets", None, "Subject offsets in training data: random (default) or none "
                                         "(EM-POSE's 'no [R|t]' ablation).", str),
            TrainOption("ablation", None, "An EM-POSE Table 3 ablation of the LGD-RNN: noRt, no_t, "
                                          "ori_only, pos_only, no_rnn (or full).", str),
        ),
        help={"config": "Preset: tiny (smoke test: 8 training clips unless --limit, under a minute), cpu "
                        "(CPU-sized), paper (supp. Table 5).",
              "out": "Run directory (default runs/<method><sensors>_<config>)."},
    ),
    trainings={
        "empose-twostage": Training(
            entry=f"{_P}.twostage:train_from_options",
            doc="""Train the EM-POSE two-stage model (supp. Sec. 9), optionally warm-started from another two-stage checkpoint.

            Trains the empose-twostage weights; wearpose train empose --model twostage trains the default (LGD IK) from scratch.

            Example: wearpose train empose-twostage --ik closed --init runs/twostage12_long/best.pt --epochs 8 --lr 2e-4 --threads 1 --out runs/twostage12_closed
            The shipped empose12_twostage_cpu: wearpose train --recipe empose12_twostage_cpu_v3
            """,
            done="done: best val MPJPE {best:.1f} mm; checkpoints in {out_dir}",
            options=(
                TrainOption("sensors", 12, "Number of sensors: 12 (kit em12) or 6 (kit em6)."),
                TrainOption("ik", "lgd", "Stage 2 (EmposeConfig.ik): lgd or closed."),
                TrainOption("mapper_input", "raw", "EmposeConfig.mapper_input: raw or site."),
                TrainOption("init", None, "Two-stage checkpoint to warm-start from (matching tensors).", Path),
                TrainOption("lr", None, "Override the learning rate.", float),
                TrainOption("limit_val", None, "Use only the first N validation clips.", int, min=1),
                TrainOption("max_steps", None, "Stop after N optimiser steps.", int, min=1),
                TrainOption("fk_weight", None, "ik=closed: FK_JOINT_WEIGHT (default 100).", float),
            ),
            help={"out": "Run directory (required).", "resume": "Continue <out>/last.pt (--init is then ignored)."},
            # the training mix and the seed as for EM-POSE (the same data path); its own --init
            # warm-starts mapper and Adam moments, so the shared --init-from is left out
            omit=frozenset({"init_from"}),
            mix=True,
        ),
        "poseprior": Training(
            entry=f"{_P}.optimization:train_from_options",
            doc="""Train the pose-prior VAE of the L-BFGS baseline (empose-lbfgs): <out>/prior.pt.

            Example: wearpose train poseprior --out runs/poseprior_cpu --epochs 4
            """,
            done="done: best val reconstruction {best_val_rec:.5f}; prior in {out_dir}/prior.pt",
            defaults={"epochs": 4, "threads": 1, "out": Path("runs/poseprior_cpu")},
            help={"epochs": "Number of epochs.", "threads": "torch CPU threads."},
            omit=frozenset({"config", "resume", "device", "checkpoint_every"}),
        ),
    },
    demos={"em12": "wearpose.cli.demo:run_sensor_demo", "em6": "wearpose.cli.demo:run_sensor_demo_em6"},
)

__all__ = ["METHOD", "EmposeConfig", "EmposeEstimator", "LGDRNN", "PRED_JOINTS", "UNOBSERVED_JOINTS",
           "VirtualSensors", "lgd_loss", "evaluate_empose", "train_empose"]

__getattr__ = lazy_exports(__name__, {
    "EmposeConfig": "config", "EmposeEstimator": "estimator", "LGDRNN": "model", "PRED_JOINTS": "model",
    "UNOBSERVED_JOINTS": "model", "VirtualSensors": "model", "lgd_loss": "model", "evaluate_empose": "train",
    "train_empose": "train"})
