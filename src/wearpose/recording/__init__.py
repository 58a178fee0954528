"""Recordings: one type for every sensor modality, its versioned file format, and converters
from public dataset layouts.

Public API:

- :class:`Recording`, :class:`SensorStream`, :class:`SensorInfo`, :class:`CommonGrid`
- :func:`load_recording` / :func:`save_recording` (also ``Recording.save``), format
  ``wearpose.recording`` v1 (``docs/formats.md``)
- :func:`check_stream` / :func:`check_recording`: does the data look like its declared units?
- converters: :func:`from_dip_imu`, :func:`from_totalcapture`, :func:`from_empose`, :func:`from_ximu3`,
  :func:`amass_ground_truth`; device files: :func:`from_mvnx` (Xsens MVNX), :func:`from_movella_dot`
  (Movella DOT CSV exports), :func:`from_csv` (any CSV with a YAML column map, :func:`load_column_map`)
- :func:`recording_from_simulation` (also ``Recording.from_simulation``): a
  :func:`wearpose.sensors.simulate` result as a recording
- :func:`prepend_tpose` / :func:`calibration_window`: a calibration T-pose before a (simulated)
  motion, marked in ``meta["calibration_window"]`` (estimators use the mark through
  :func:`wearpose.estimators.run.use_calibration_window`)
- :func:`decimate` / :func:`decimation_factor`: integer-factor decimation (e.g. 120 -> 30 Hz),
  validity mask kept per kept sample, non-integer ratios refused
- :class:`RecordingError` for operations a recording cannot do (file problems are
  :class:`wearpose.errors.InputFileError`).
"""

from wearpose.recording.types import (
    CHANNELS,
    KINDS,
    OPTIONAL_CHANNELS,
    REQUIRED_CHANNELS,
    CommonGrid,
    Recording,
    RecordingError,
    SensorInfo,
    SensorStream,
)
from wearpose.recording.checks import ConventionIssue, check_recording, check_stream
from wearpose.recording.fileformat import FORMAT_NAME, FORMAT_VERSION, load_recording, recording_arrays, save_recording
from wearpose.recording.simulated import recording_from_simulation, simulate_recording
from wearpose.recording.resample import decimate, decimation_factor
from wearpose.recording.tpose import CALIBRATION_WINDOW_KEY, calibration_window, prepend_tpose
from wearpose.recording.converters import (
    DIP_IMU_SENSORS,
    DIP_IMU_SIX,
    EMPOSE_SENSORS,
    EMPOSE_SITES,
    EMPOSE_SIX,
    TOTALCAPTURE_SITES,
    amass_ground_truth,
    from_dip_imu,
    from_empose,
    from_totalcapture,
    from_ximu3,
)
from wearpose.recording.mvnx import from_mvnx
from wearpose.recording.movella import from_movella_dot
from wearpose.recording.csvmap import from_csv, load_column_map

__all__ = [
    "Recording", "SensorStream", "SensorInfo", "CommonGrid", "RecordingError",
    "KINDS", "CHANNELS", "REQUIRED_CHANNELS", "OPTIONAL_CHANNELS",
    "ConventionIssue", "check_stream", "check_recording",
    "FORMAT_NAME", "FORMAT_VERSION", "load_recording", "save_recording", "recording_arrays",
    "recording_from_simulation", "simulate_recording",
    "decimate", "decimation_factor",
    "CALIBRATION_WINDOW_KEY", "prepend_tpose", "calibration_window",
    "from_dip_imu", "from_totalcapture", "from_empose", "from_ximu3", "amass_ground_truth",
    "from_mvnx", "from_movella_dot", "from_csv", "load_column_map",
    "DIP_IMU_SENSORS", "DIP_IMU_SIX", "EMPOSE_SENSORS", "EMPOSE_SITES", "EMPOSE_SIX", "TOTALCAPTURE_SITES",
]
