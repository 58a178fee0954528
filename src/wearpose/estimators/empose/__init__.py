"""EM-POSE (Kaufmann et al., ICCV 2021): SMPL pose and shape from 6 or 12 EM sensors by
learned gradient descent (LGD-RNN). See :mod:`.model` for the network, :mod:`.data` for the
training data, :mod:`.estimator` for the protocol implementation, :mod:`.train` for training
and evaluation."""

from wearpose.estimators.empose.config import EmposeConfig
from wearpose.estimators.empose.estimator import EmposeEstimator
from wearpose.estimators.empose.model import LGDRNN, PRED_JOINTS, UNOBSERVED_JOINTS, VirtualSensors, lgd_loss

__all__ = ["EmposeConfig", "EmposeEstimator", "LGDRNN", "PRED_JOINTS", "UNOBSERVED_JOINTS", "VirtualSensors",
           "lgd_loss", "evaluate_empose", "train_empose"]


def __getattr__(name: str):  # lazy: training/evaluation pull in the corpus and rich
    if name in ("evaluate_empose", "train_empose"):
        from wearpose.estimators.empose import train

        return getattr(train, name)
    raise AttributeError(name)
