"""Sensor kits and simulators: EM 6-DoF (EM-POSE), IMU (TransPose/PIP synthesis), MIMU (BiRAE
yaw drift and magnetic disturbance), headset VIO (MI-Poser), and root-relative normalisation.

Entry point: :func:`simulate` (motion + kit + body -> :class:`SimulationResult`). Kits:
:func:`get_kit` / :func:`list_kits`. Each simulator module documents its model and sources.
"""

from wearpose.sensors.em import EMNoise, EMOffsets, apply_offsets, random_subject_offsets, relative_to_source, simulate_em
from wearpose.sensors.imu import (
    ImuNoise, angular_velocity, free_acceleration, integrate_gyro, simulate_imu, specific_force, synthetic_acceleration,
)
from wearpose.sensors.kits import SENSOR_KINDS, SITE_SEGMENT, KitError, SensorKit, SensorSpec, get_kit, list_kits, register_kit, resolve_sites
from wearpose.sensors.mimu import (
    EARTH_FIELD, MimuNoise, ahrs_fusion, birae_3param, birae_6param, birae_6param_to_matrix, simulate_mimu, zhou_6d,
)
from wearpose.sensors.normalize import empose_normalize, root_relative_orientations
from wearpose.sensors.simulate import SHAPE_STREAMS, NoiseConfig, SensorData, SimulationResult, random_body_shape, simulate
from wearpose.sensors.vio import VioNoise, simulate_vio

__all__ = [
    "simulate", "SimulationResult", "SensorData", "NoiseConfig", "random_body_shape", "SHAPE_STREAMS",
    "SensorKit", "SensorSpec", "SENSOR_KINDS", "SITE_SEGMENT", "KitError", "get_kit", "list_kits", "register_kit", "resolve_sites",
    "ImuNoise", "synthetic_acceleration", "angular_velocity", "integrate_gyro", "specific_force", "free_acceleration",
    "simulate_imu",
    "EMNoise", "EMOffsets", "random_subject_offsets", "apply_offsets", "relative_to_source", "simulate_em",
    "MimuNoise", "EARTH_FIELD", "simulate_mimu", "ahrs_fusion", "birae_6param", "birae_3param", "birae_6param_to_matrix", "zhou_6d",
    "root_relative_orientations", "empose_normalize",
    "VioNoise", "simulate_vio",
]
