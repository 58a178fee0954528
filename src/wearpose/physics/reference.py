"""Kinematic references for the optimizer from a ground-truth motion (tests, benchmarks, plots).

The optimizer normally tracks PIP's network outputs; driving it with a ground-truth motion
instead checks the physics alone: with perfect kinematics the output should stay close to the
motion, carry the body weight on the feet and alternate the load between the feet in walking.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from wearpose.body import JOINT_INDEX, BodyModel
from wearpose.motion import MotionSequence, resample

#: Foot joints (left, right) whose contact the optimizer takes as probabilities.
FOOT_JOINTS = (JOINT_INDEX["left_foot"], JOINT_INDEX["right_foot"])


@dataclass
class KinematicReference:
    """Reference inputs of :meth:`PhysicsOptimizer.run` from a motion, at ``fps``.

    Attributes:
        pose: ``(T, 24, 3, 3)`` local rotations; trans: ``(T, 3)`` m; joints: ``(T, 24, 3)`` m, world.
        joint_vel: ``(T, 24, 3)`` world joint velocities, m/s (central differences, one-sided
            at the ends).
        contact: ``(T, 2)`` left/right foot contact labels in {0, 1}: foot joint slower than
            ``contact_speed`` and within ``contact_height`` of its lowest height in the clip.
        fps: Hz.
    """

    pose: torch.Tensor
    trans: torch.Tensor
    joints: torch.Tensor
    joint_vel: torch.Tensor
    contact: torch.Tensor
    fps: float


def kinematic_reference(seq: MotionSequence, body: BodyModel, fps: float = 60.0, contact_speed: float = 0.48,
                        contact_height: float = 0.10) -> KinematicReference:
    """References from ``seq`` (resampled to ``fps``) posed on ``body`` with the clip's betas.

    Contact thresholds default to the ones of PIP's training labels in this project
    (0.48 m/s = 8 mm per frame at 60 fps, TransPose's threshold; 10 cm above the clip's lowest).
    """
    if abs(seq.fps - fps) > 1e-9:
        seq = resample(seq, fps)
    pose, trans = seq.pose.float(), seq.trans.float()
    with torch.no_grad():
        joints = body(pose, seq.betas.float(), trans, return_vertices=False).joints
    vel = torch.gradient(joints, spacing=1.0 / fps, dim=0)[0] if len(joints) > 1 else torch.zeros_like(joints)
    feet = joints[:, list(FOOT_JOINTS)]
    speed = vel[:, list(FOOT_JOINTS)].norm(dim=-1)
    height = feet[..., 1] - feet[..., 1].min()
    contact = ((speed < contact_speed) & (height < contact_height)).float()
    return KinematicReference(pose=pose, trans=trans, joints=joints, joint_vel=vel, contact=contact, fps=fps)
