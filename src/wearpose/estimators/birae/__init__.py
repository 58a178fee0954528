"""BiRAE (Butt et al., IEEE Access 2021): magnetometer-robust 3D pose with calibrated per-joint
uncertainty from six MIMUs (kit ``mimu6``), offline bidirectional and sliding-window online.

Modules: :mod:`.config` (presets), :mod:`.representations` (Eq. 1, Appendix A inputs, exp-map
outputs), :mod:`.model` (Bi-LSTM autoencoder, Eq. 6), :mod:`.data` (synthesis, augmentation,
evaluation scenarios), :mod:`.train` (two-phase training, fine-tuning), :mod:`.uncertainty`
(Eq. 7-8, sigma-scaling calibration), :mod:`.estimator` (the protocol), :mod:`.evaluate`
(Tables 1-4, calibration, window grid); the demo is :mod:`wearpose.viewer.demos.birae`.

This file is the method's declaration (:data:`METHOD`); the names below are imported on first use.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from wearpose.estimators.method import EstimatorEntry, MethodSpec, TrainOption, Training, lazy_exports

if TYPE_CHECKING:
    from wearpose.estimators.birae.config import REPS, BiraeConfig
    from wearpose.estimators.birae.estimator import BiraeEstimator
    from wearpose.estimators.birae.model import BiRAE, nll_loss
    from wearpose.estimators.birae.train import finetune, train_birae

METHOD = MethodSpec(
    name="birae",
    summary="BiRAE (Butt et al., IEEE Access 2021): 6 MIMUs -> pose with calibrated per-joint uncertainty",
    estimators=(EstimatorEntry("birae", "wearpose.estimators.birae.estimator:BiraeEstimator",
                               protocol="wearpose.estimators.birae.entry:protocol"),),
    config="wearpose.estimators.birae.config:BiraeConfig",
    presets=("tiny", "cpu", "paper"),
    kits=("mimu6",),
    training=Training(
        mix=True,
        entry="wearpose.estimators.birae.entry:train_from_options",
        val_metric="val_mpjae_deg",  # the sigma phase keeps by val_nll; the mean's figure is the headline
        doc="""Train BiRAE: clean synthetic orientations first, then noise/impulse/yaw-drift augmented.

        Example: wearpose train birae --rep 3param --config cpu --threads 1 --out runs/birae3_cpu
        """,
        done="done: best val MPJAE {best:.2f} deg; checkpoint {best_checkpoint}",
        options=(
            TrainOption("rep", "6param", "Input representation: 6param, 3param, 3param_rate, zhou6d."),
            TrainOption("epochs_clean", None, "Override the clean-phase epochs.", int),
            TrainOption("epochs_aug", None, "Override the augmented-phase epochs.", int),
            TrainOption("epochs_sigma", None, "Epochs of a third phase: the log-variance head alone on the "
                        "corpus's own clips, the training mix left out (default 0: none).", int, min=0),
            TrainOption("hidden", None, "Override the Bi-LSTM width.", int, min=1),
            TrainOption("width", None, "Override the input FC width.", int),
            TrainOption("batch_size", None, "Override the batch size.", int, min=1),
            TrainOption("train_clips", None, "Use only the first N training clips (quick runs).", int, min=1),
            TrainOption("lr", None, "Override the initial learning rate.", float),
        ),
        omit=frozenset({"epochs", "limit"}),  # two phases, each with its epochs; --train-clips
        defaults={"device": "cpu", "checkpoint_every": 50},
        help={"config": "Preset: tiny (smoke test), cpu (CPU-sized), paper (Sec. IV-A/E).",
              "init_from": "Start from this BiRAE checkpoint's weights (same --rep); with --epochs-clean 0 it "
                           "continues in the augmented phase.",
              "out": "Run directory (default runs/birae_<rep>_<config>).",
              "resume": "Continue each phase from its last.pt.", "device": "cpu, cuda[:i] or auto."},
    ),
    demos={"mimu6": "wearpose.viewer.demos.birae:run_demo"},
)

__all__ = ["METHOD", "REPS", "BiraeConfig", "BiraeEstimator", "BiRAE", "nll_loss", "train_birae", "finetune"]

__getattr__ = lazy_exports(__name__, {
    "REPS": "config", "BiraeConfig": "config", "BiraeEstimator": "estimator", "BiRAE": "model", "nll_loss": "model",
    "train_birae": "train", "finetune": "train"})
