"""EM field, metal interference and its mitigation (MI-Poser's MIM) on a physically simulated field.

- :mod:`.field`: EM-POSE Eq. 1-2 dipole field and coil voltages; metal as induced eddy-current
  dipoles (:class:`MetalObject`), a conducting floor as an image source (:class:`Scene`).
- :mod:`.tracker`: :class:`EMTracker`, the 6-DoF pose from the 9 voltages by warm-started least
  squares, hemisphere by continuity.
- :mod:`.simulate`: condition presets (:data:`CONDITIONS`: "open-space", "standard", "extreme")
  and :func:`simulate_condition` (motion -> interfered EM poses + co-located IMU, 120 Hz).
- :mod:`.mim`: :class:`MIM` (:class:`MIMConfig`): gyro-vs-EM detection, gyro rotation correction,
  position correction by IMU odometry, N-BEATS forecasting or their fusion; "degraded" flag.
- :mod:`.nbeats`: the N-BEATS trajectory forecaster and its training on the corpus.
- :mod:`.metrics`: detection metrics (MCC, F1, precision, recall) and threshold sweeps.
- :mod:`.study`: MI-Poser's study on simulated sessions (Table 1 statistics, Table 3 / Fig. 8
  detection with val-chosen thresholds, Figs. 9-10 correction per method), what
  ``benchmarks/interference.py`` tabulates.

Docs: ``docs/interference.md``.
"""

from wearpose.interference.field import (
    MetalObject, Scene, coupling, dipole_field, ideal_voltages, measured_voltages, soft_coupling,
)
from wearpose.interference.metrics import binary_metrics, sweep_detection
from wearpose.interference.mim import MIM, POSITION_METHODS, MIMConfig, detect
from wearpose.interference.nbeats import NBeats, NBeatsConfig, NumpyNBeats, load_forecaster
from wearpose.interference.simulate import (
    CONDITIONS, ConditionPreset, ConditionSim, SensorStreams, draw_scene, get_condition, make_object, rotation_error,
    simulate_condition,
)
from wearpose.interference.tracker import EMTracker, TrackerConfig, closed_form_pose
from wearpose.interference.trajectories import EM_RATE, SiteTrajectories, body_trajectories

__all__ = [
    "MetalObject", "Scene", "coupling", "soft_coupling", "dipole_field", "ideal_voltages", "measured_voltages",
    "EMTracker", "TrackerConfig", "closed_form_pose",
    "CONDITIONS", "ConditionPreset", "ConditionSim", "SensorStreams", "simulate_condition", "draw_scene", "get_condition",
    "make_object", "rotation_error",
    "MIM", "MIMConfig", "POSITION_METHODS", "detect",
    "NBeats", "NBeatsConfig", "NumpyNBeats", "load_forecaster",
    "binary_metrics", "sweep_detection",
    "EM_RATE", "SiteTrajectories", "body_trajectories",
]
