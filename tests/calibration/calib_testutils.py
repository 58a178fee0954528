"""Helpers for calibration tests: motions that start (and optionally end) in a static pose."""

from __future__ import annotations

import math

import torch

from wearpose.calibration.segment import calibration_pose
from wearpose.geometry import axis_angle_to_matrix
from wearpose.motion.sequence import MotionSequence


def _smoothstep(x: torch.Tensor) -> torch.Tensor:
    x = x.clamp(0, 1)
    return x * x * x * (10 - 15 * x + 6 * x * x)


def posed_motion(T: int, fps: float, *, seed: int = 0, amp: float = 0.5, hold: float = 1.0, hold_end: float = 0.0,
                 pose: str = "tpose", turn: float = 1.0, mid_holds: tuple[float, ...] = ()) -> MotionSequence:
    """``hold`` s of a static calibration pose, a smooth blend into sum-of-sinusoids motion (root
    turning by up to ``turn`` rad, walking), optionally static holds of the pose (facing +Z, at
    the same spot) centred at ``mid_holds`` s and for the last ``hold_end`` s. float64."""
    g = torch.Generator().manual_seed(seed)
    t = torch.arange(T, dtype=torch.float64) / fps
    a = amp * torch.rand(24, 3, generator=g, dtype=torch.float64)
    f = 0.2 + 0.8 * torch.rand(24, 3, generator=g, dtype=torch.float64)
    ph = 2 * math.pi * torch.rand(24, 3, generator=g, dtype=torch.float64)
    aa = a * torch.sin(2 * math.pi * f * t[:, None, None] + ph)
    aa[:, 0] = 0.0
    aa[:, 0, 1] = turn * torch.sin(0.4 * t)  # root yaw: the subject turns around
    aa[:, 0, 0] = 0.15 * torch.sin(1.1 * t)
    w = _smoothstep((t - hold) / 0.5)  # 0 during the hold, 1 after 0.5 s of blending
    end = t[-1]
    if hold_end > 0:
        w = w * _smoothstep((end - hold_end - t) / 0.5)
    for c in mid_holds:
        w = w * _smoothstep((torch.abs(t - c) - 0.5) / 0.5)
    base = calibration_pose(pose)
    pose_rot = base[None] @ axis_angle_to_matrix(aa * w[:, None, None])
    trans = torch.stack([0.3 * torch.sin(0.3 * t), 0.02 * torch.sin(2 * math.pi * t), 0.2 * torch.sin(0.5 * t)], -1) * w[:, None]
    return MotionSequence(pose_rot, torch.zeros(10, dtype=torch.float64), trans, fps)


def tilt_yaw(yaw: float, tilt: float, tilt_axis: tuple[float, float, float] = (1.0, 0.0, 0.3)) -> torch.Tensor:
    """A world rotation ``(3, 3)``: yaw about +Y then a tilt about a horizontal-ish axis."""
    ax = torch.tensor(tilt_axis, dtype=torch.float64)
    ax = ax / ax.norm()
    return axis_angle_to_matrix(ax * tilt) @ axis_angle_to_matrix(torch.tensor([0.0, yaw, 0.0], dtype=torch.float64))


def sim_to_recording(sim, *, ground_truth=None, world: torch.Tensor | None = None, raw_imu: bool = False,
                     yaw_drift: dict[str, float] | None = None):
    """A :class:`wearpose.recording.Recording` from a :class:`wearpose.sensors.SimulationResult`.

    ``world``: ``(3, 3)`` rotation C taking wearpose-world coordinates to the devices' world M
    (inertial and VIO streams are re-expressed in M: ``R_MS = C R_WS``, ``p_M = C p``).
    ``raw_imu``: store IMU acceleration as the raw accelerometer reading (sensor frame, gravity
    included: ``acc_frame="sensor"``, ``acc_gravity="included"``), as a device would, so
    ``Recording.to_canonical`` forms ``R_MS f + g`` in M. ``yaw_drift``: sensor -> rad/s of
    linear heading drift about M's vertical.
    """
    from wearpose.calibration._common import rotation_y
    from wearpose.recording import Recording, SensorInfo, SensorStream

    C = torch.eye(3, dtype=torch.float64) if world is None else world.to(torch.float64)
    streams = []
    src = sim.kit.em_source_site
    for name, d in sim.sensors.items():
        ch = {}
        if d.kind == "em6dof":
            info = SensorInfo(name, d.kind, d.site, d.rate, source_site=src)
            ch["position"], ch["orientation"] = d.position.double().numpy(), d.orientation.double().numpy()
        else:
            R = d.orientation.double()
            if yaw_drift and name in yaw_drift:
                R = rotation_y(d.timestamps.double() * yaw_drift[name]) @ R
            RM = C @ R
            ch["orientation"] = RM.numpy()
            if d.kind == "vio":
                info = SensorInfo(name, d.kind, d.site, d.rate)
                ch["position"] = (d.position.double() @ C.T).numpy()
            else:
                if raw_imu:
                    info = SensorInfo(name, d.kind, d.site, d.rate, acc_frame="sensor", acc_gravity="included")
                    ch["acceleration"] = d.specific_force.double().numpy()
                else:
                    info = SensorInfo(name, d.kind, d.site, d.rate)
                    ch["acceleration"] = (d.acceleration.double() @ C.T).numpy()
                if d.angular_velocity is not None:
                    ch["angular_velocity"] = d.angular_velocity.double().numpy()
                if d.kind == "mimu":
                    ch["magnetic_field"] = d.magnetic_field.double().numpy()
        streams.append(SensorStream(info, d.timestamps.double().numpy(), d.valid.numpy(), **ch))
    return Recording(streams, ground_truth=ground_truth, meta={"source": "simulate", "seed": sim.seed})


def tpose_then(motion: MotionSequence, hold: float = 1.0, blend: float = 0.5, pose: str = "tpose") -> MotionSequence:
    """``hold`` s of the calibration pose (facing +Z at the clip's first position), a ``blend`` s
    slerp into the clip's first frame (root orientation included), then the clip. float64."""
    from wearpose.geometry import slerp_matrix

    fps = motion.fps
    m = motion.to(torch.float64)
    nh, nb = int(round(hold * fps)), int(round(blend * fps))
    base = calibration_pose(pose)
    first = m.pose[0]
    w = _smoothstep(torch.arange(1, nb + 1, dtype=torch.float64) / (nb + 1))
    blend_pose = slerp_matrix(base.expand(nb, 24, 3, 3), first.expand(nb, 24, 3, 3), w[:, None].expand(nb, 24))
    pose_all = torch.cat([base.expand(nh, 24, 3, 3), blend_pose, m.pose])
    trans = torch.cat([m.trans[:1].expand(nh + nb, 3), m.trans])
    return MotionSequence(pose_all, m.betas, trans, fps, dict(m.meta))
