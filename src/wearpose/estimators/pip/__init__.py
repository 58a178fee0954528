"""PIP (Physical Inertial Poser, Yi et al. CVPR 2022): 6 IMUs -> pose, translation, joint
torques and ground reaction forces, online at 60 fps.

- :class:`PipConfig` (presets ``paper``, ``cpu``, ``tiny``);
- :mod:`.data`: training data synthesis (IMUs, contact labels, Eq. 14 joint velocities);
- :class:`PipNet`: the kinematics RNN chain P_L -> P_A -> R_A / V_A / C_F with learned
  initialisation I_PL / I_VA;
- :class:`PipEstimator`: the ``pip`` estimator (physics via :mod:`wearpose.physics`);
- :func:`train_pip`. See ``docs/pip.md``.
"""

from wearpose.estimators.pip.config import PipConfig
from wearpose.estimators.pip.data import imu_features, root_frame_targets
from wearpose.estimators.pip.estimator import PipEstimator
from wearpose.estimators.pip.model import PipNet, cumulative_velocity_loss, pip_loss
from wearpose.estimators.pip.train import train_pip

__all__ = ["PipConfig", "PipNet", "PipEstimator", "imu_features", "root_frame_targets", "pip_loss",
           "cumulative_velocity_loss", "train_pip"]
