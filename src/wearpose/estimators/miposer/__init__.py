"""MI-Poser (Arakawa et al., IMWUT 2023): upper-body pose from AR-glasses VIO and two wrist EM
sensors, with metal-interference mitigation (MIM, :mod:`wearpose.interference`).

- :class:`MiposerConfig` (presets ``paper`` / ``cpu`` / ``tiny``), :data:`UPPER_BODY`;
- :class:`MiposerEstimator` (registry ``miposer``): T-pose calibration + AvatarPoser-style IK
  network over a 40-frame, 60 Hz window; MIM on or off; online :meth:`~MiposerEstimator.step`;
- :class:`~wearpose.estimators.miposer.baselines.ImuPoserEstimator` (registry ``imuposer``):
  the IMU-only head + wrists baseline (2-layer BiLSTM, IMUPoser) of Sec. 5.2.2;
- data synthesis (:mod:`.data`), training (:func:`train_miposer`), evaluation (:mod:`.evaluate`);
  the demo is :mod:`wearpose.viewer.demos.miposer`.

This file is the method's declaration (:data:`METHOD`); the names above are imported on first use.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from wearpose.estimators.method import EstimatorEntry, MethodSpec, TrainOption, Training, lazy_exports

if TYPE_CHECKING:
    from wearpose.estimators.miposer.config import UPPER_BODY, MiposerConfig
    from wearpose.estimators.miposer.estimator import MiposerEstimator, frames
    from wearpose.estimators.miposer.train import train_miposer

_P = "wearpose.estimators.miposer"

METHOD = MethodSpec(
    name="miposer",
    summary="MI-Poser (Arakawa et al., IMWUT 2023): upper body from headset VIO + wrist EM, interference-robust",
    estimators=(EstimatorEntry("miposer", f"{_P}.estimator:MiposerEstimator", protocol=f"{_P}.entry:protocol"),
                EstimatorEntry("imuposer", f"{_P}.baselines:ImuPoserEstimator",
                               protocol=f"{_P}.entry:imuposer_protocol")),
    config=f"{_P}.config:MiposerConfig",
    presets=("tiny", "cpu", "paper"),
    kits=("miposer", "miposer1"),
    training=Training(
        mix=True,
        entry=f"{_P}.entry:train_from_options",
        doc="""Train MI-Poser (AvatarPoser-style IK from head + wrist 6-DoF) or the IMUPoser baseline.

        Example: wearpose train miposer --config cpu --threads 1 --out runs/miposer2_cpu
        """,
        done="done: best val upper-body MPJPE {best:.1f} mm; checkpoints in {out_dir}",
        options=(
            TrainOption("model", "avatarposer", "avatarposer (MI-Poser IK network) or imuposer (IMU-only BiLSTM "
                                                "baseline)."),
            TrainOption("wrists", 2, "Wrist sensors: 2 (kit miposer) or 1 (left wrist, smartwatch variant, kit "
                                     "miposer1)."),
            TrainOption("batch_size", None, "Override the batch size.", int, min=1),
            TrainOption("lr", None, "Override the learning rate.", float),
        ),
        help={"config": "Preset: tiny (smoke test: 8 training clips unless --limit, under a minute), cpu "
                        "(CPU-sized), paper (AvatarPoser / MI-Poser Sec. 4.2).",
              "out": "Run directory (default runs/miposer<wrists>_<config> or runs/imuposer_<config>)."},
    ),
    trainings={"nbeats": Training(
        entry=f"{_P}.entry:train_nbeats_from_options",
        doc="""Train MIM's N-BEATS trajectory forecaster (MI-Poser Sec. 3.3 / 4.3) on the corpus train split, or ship a trained one.

        Wrist trajectories relative to the head-worn source at 120 Hz, 1 s in, 0.5 s out (wearpose.interference.nbeats).

        Example: wearpose train nbeats --config cpu --threads 1 --out runs/nbeats_cpu
        The shipped nbeats_cpu: wearpose train --recipe nbeats_cpu_v2 --out runs/nbeats_cpu
        Ship it: wearpose train nbeats --ship runs/nbeats_cpu/best.pt --name nbeats_cpu
        """,
        done="done: {summary}",
        options=(
            TrainOption("ship", None, "Ship this checkpoint as package weights (measured on the test split) instead "
                                      "of training.", Path),
            TrainOption("name", "nbeats_cpu", "Name of the shipped weights (with --ship)."),
            TrainOption("notes", None, "With --ship: the card's notes (what this version is, where it is worse).",
                        str),
            TrainOption("max_train_clips", None, "Use only the first N training clips.", int, min=1),
        ),
        defaults={"out": Path("runs/nbeats_cpu"), "threads": 1},
        help={"config": "Preset: tiny (smoke test), cpu (2 x 2 x 256, shipped as nbeats_cpu), paper (2 x 2 x 512).",
              "out": "Run directory.", "threads": "torch CPU threads."},
        # the mix applies to the motion: no simulated sensors to jitter, no estimator to start from
        omit=frozenset({"device", "limit", "checkpoint_every", "init_from", "site_jitter"}),
        mix=True,
        val_metric="val_mae_cm",
        reader="wearpose.interference.nbeats:kept_checkpoint",
    )},
    demos={"miposer": "wearpose.viewer.demos.miposer:run_demo"},
)

__all__ = ["METHOD", "MiposerConfig", "MiposerEstimator", "UPPER_BODY", "frames", "train_miposer"]

__getattr__ = lazy_exports(__name__, {
    "MiposerConfig": "config", "UPPER_BODY": "config", "MiposerEstimator": "estimator", "frames": "estimator",
    "train_miposer": "train"})
