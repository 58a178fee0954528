"""MI-Poser (Arakawa et al., IMWUT 2023): upper-body pose from AR-glasses VIO and two wrist EM
sensors, with metal-interference mitigation (MIM, :mod:`wearpose.interference`).

- :class:`MiposerConfig` (presets ``paper`` / ``cpu`` / ``tiny``), :data:`UPPER_BODY`;
- :class:`MiposerEstimator` (registry ``miposer``): T-pose calibration + AvatarPoser-style IK
  network over a 40-frame, 60 Hz window; MIM on or off; online :meth:`~MiposerEstimator.step`;
- :class:`~wearpose.estimators.miposer.baselines.ImuPoserEstimator` (registry ``imuposer``):
  the IMU-only head + wrists baseline (2-layer BiLSTM, IMUPoser) of Sec. 5.2.2;
- data synthesis (:mod:`.data`), training (:func:`train_miposer`), evaluation (:mod:`.evaluate`),
  demo (:mod:`.demo`).
"""

from wearpose.estimators.miposer.config import UPPER_BODY, MiposerConfig
from wearpose.estimators.miposer.estimator import MiposerEstimator, frames
from wearpose.estimators.miposer.train import train_miposer

__all__ = ["MiposerConfig", "MiposerEstimator", "UPPER_BODY", "frames", "train_miposer"]
