"""Segment estimator for dense kits: what commercial inertial suits do, with no learned part.

After a static calibration pose (T-pose; for a lower-body kit standing upright is the same),
every body segment with a sensor on it takes that sensor's orientation composed with the
sensor-to-segment rotation from calibration (:func:`wearpose.calibration.calibrate`,
``"tpose"``; BiRAE Eq. 2a-2b): ``R^{WB}(t) = R^{WM} R^{MS}(t) (R^{BS})^T``. A joint with no sensor
keeps its calibration pose relative to its parent (local rotation identity), so a lower-body kit
gives a rigid, upright upper body that turns and leans with the pelvis. No translation is
estimated (``trans=None``; the export puts the feet on the floor, :mod:`wearpose.estimators.run`).

Sensors are matched to SMPL joints by their ``site`` (:data:`SEGMENT_JOINTS`); the pelvis must be
one of them (it carries the root). Sensors that stamp their own samples are put on one grid by
nearest sample (:func:`wearpose.estimators.inputs.nearest_sample_grid`), never interpolated.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import torch

from wearpose.body.skeleton import JOINT_INDEX, NUM_JOINTS, PARENTS
from wearpose.errors import ShapeError
from wearpose.estimators.base import Estimator, PoseFrame, PoseTrack, SensorFrame
from wearpose.estimators.inputs import InputSpec, nearest_sample_grid, prepare
from wearpose.estimators.registry import register_estimator
from wearpose.recording import Recording, calibration_window

#: Body site of a sensor -> the SMPL joint whose segment (the bone from that joint to its child)
#: it is strapped to.
SEGMENT_JOINTS: dict[str, str] = {
    "pelvis": "pelvis", "back_upper": "spine3", "sternum": "spine3", "head": "head",
    "left_thigh": "left_hip", "right_thigh": "right_hip", "left_shin": "left_knee", "right_shin": "right_knee",
    "left_foot": "left_ankle", "right_foot": "right_ankle",
    "left_upper_arm": "left_shoulder", "right_upper_arm": "right_shoulder",
    "left_forearm": "left_elbow", "right_forearm": "right_elbow", "left_wrist": "left_wrist", "right_wrist": "right_wrist",
}
#: Calibration pose window when the recording marks none: the first half second (s).
DEFAULT_WINDOW_S = (0.0, 0.5)


@register_estimator("segments")
class SegmentsEstimator(Estimator):
    """Segment orientations from calibrated sensors (module doc). Offline only.

    Args:
        calibration_window: ``(start_s, stop_s)`` of the static calibration pose; default the
            recording's marked T-pose (``meta["calibration_window"]``), else :data:`DEFAULT_WINDOW_S`.
    """

    name = "segments"
    has_weights = False
    causal = False

    def __init__(self, calibration_window: tuple[float, float] | None = None) -> None:
        self.calibration_window = calibration_window
        self.kit_name = "any"
        self.sensor_names: tuple[str, ...] = ()
        self.body_asset_id = "any"
        self.fps = 0.0  # any rate: the recording's
        self.meta: dict[str, Any] = {}

    def fit(self, *args: Any, **kwargs: Any) -> Any:
        raise ShapeError("the segment estimator has nothing to train")

    def save(self, path: str | Path) -> Path:
        raise ShapeError("the segment estimator has no weights to save")

    @classmethod
    def load(cls, path: str | Path, *, kit: str | None = None, body: Any = None, **kwargs: Any) -> SegmentsEstimator:
        return cls()

    def reset(self) -> None:
        pass

    def step(self, frame: SensorFrame) -> PoseFrame:
        raise ShapeError("the segment estimator is offline only (it calibrates on the recording); use estimate()")

    def estimate(self, recording: Recording) -> PoseTrack:
        """Local rotations ``(T, 24, 3, 3)`` on the sensors' shared grid (module doc);
        ``valid`` where every used sensor had a sample; ``extras``: ``frame="world"``,
        ``segments`` (sensor -> joint), ``grid``, ``calibration``."""
        # start-up: wearpose.calibration adds ~370 ms to importing this module
        from wearpose.calibration import calibrate
        # start-up: wearpose.calibration.segment adds ~470 ms to importing this module
        from wearpose.calibration.segment import bone_orientations

        names, joints = self._segments(recording)
        grid = nearest_sample_grid(recording.to_canonical(), names)
        spec = InputSpec("segments", None, names, ("orientation",), kinds={"any": ("imu", "mimu")})
        window = self.calibration_window or calibration_window(recording) or DEFAULT_WINDOW_S
        t0 = float(grid.sensor(names[0]).timestamps[0])
        window = (max(window[0], t0), max(window[1], t0 + 0.1))
        res = calibrate(grid, "tpose", window=window, sensors=names)
        x = prepare(grid, spec)
        B = bone_orientations(x.channels["orientation"].double(), res).float()  # (T, S, 3, 3) bone -> world
        G = torch.eye(3).expand(B.shape[0], NUM_JOINTS, 3, 3).clone()
        have = {JOINT_INDEX[j]: k for k, j in enumerate(joints)}
        for j in range(NUM_JOINTS):  # parents precede children
            G[:, j] = B[:, have[j]] if j in have else (G[:, PARENTS[j]] if j else G[:, j])
        local = G.clone()
        for j in range(1, NUM_JOINTS):
            local[:, j] = G[:, PARENTS[j]].transpose(-1, -2) @ G[:, j]
        fps = float(grid.sensor(names[0]).info.rate)
        extras = {"frame": "world", "method": self.name, "segments": dict(zip(names, joints)),
                  "grid": grid.meta["grid"], "calibration_window_s": list(window)}
        return PoseTrack(local, torch.zeros(10), None, x.valid.all(1), fps, extras=extras)

    @staticmethod
    def _segments(recording: Recording) -> tuple[tuple[str, ...], tuple[str, ...]]:
        """The inertial sensors on known segments (one per joint) and their SMPL joints."""
        pairs: dict[str, str] = {}
        for s in recording.sensors:
            joint = SEGMENT_JOINTS.get(s.info.site or "")
            if s.kind in ("imu", "mimu") and s.orientation is not None and joint and joint not in pairs.values():
                pairs[s.info.name] = joint
        if "pelvis" not in pairs.values():
            raise ShapeError(f"the segment estimator needs a sensor on the pelvis (site 'pelvis'); the recording has "
                             f"sites {[s.info.site for s in recording.sensors]}; known sites: {sorted(SEGMENT_JOINTS)}")
        return tuple(pairs), tuple(pairs.values())
