"""BiRAE (Butt et al., IEEE Access 2021): magnetometer-robust 3D pose with calibrated per-joint
uncertainty from six MIMUs (kit ``mimu6``), offline bidirectional and sliding-window online.

Modules: :mod:`.config` (presets), :mod:`.representations` (Eq. 1, Appendix A inputs, exp-map
outputs), :mod:`.model` (Bi-LSTM autoencoder, Eq. 6), :mod:`.data` (synthesis, augmentation,
evaluation scenarios), :mod:`.train` (two-phase training, fine-tuning), :mod:`.uncertainty`
(Eq. 7-8, sigma-scaling calibration), :mod:`.estimator` (the protocol), :mod:`.evaluate`
(Tables 1-4, calibration, window grid), :mod:`.demo`.
"""

from wearpose.estimators.birae.config import REPS, BiraeConfig
from wearpose.estimators.birae.estimator import BiraeEstimator
from wearpose.estimators.birae.model import BiRAE, nll_loss

__all__ = ["REPS", "BiraeConfig", "BiraeEstimator", "BiRAE", "nll_loss", "train_birae", "finetune"]


def __getattr__(name: str):  # lazy: training pulls in the corpus and rich
    if name in ("train_birae", "finetune"):
        from wearpose.estimators.birae import train

        return getattr(train, name)
    raise AttributeError(name)
