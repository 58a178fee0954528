"""SMPL's 24-joint skeleton: names, order, parents and the joint subsets metrics use.

Defined once here; every other module imports these.
"""

from __future__ import annotations

#: SMPL joint names in SMPL order.
JOINT_NAMES: tuple[str, ...] = (
    "pelvis", "left_hip", "right_hip", "spine1", "left_knee", "right_knee", "spine2",
    "left_ankle", "right_ankle", "spine3", "left_foot", "right_foot", "neck",
    "left_collar", "right_collar", "head", "left_shoulder", "right_shoulder",
    "left_elbow", "right_elbow", "left_wrist", "right_wrist", "left_hand", "right_hand",
)
NUM_JOINTS = 24
#: Parent index of each joint (-1 for the root), SMPL's kinematic tree.
PARENTS: tuple[int, ...] = (-1, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 9, 9, 12, 13, 14, 16, 17, 18, 19, 20, 21)
JOINT_INDEX: dict[str, int] = {n: i for i, n in enumerate(JOINT_NAMES)}

#: The joints DIP/SIP/EM-POSE ignore in their metrics: root, ankles, feet, wrists, hands
#: (their rotations are either the root or not observable from the sensors).
IGNORED_JOINTS: tuple[int, ...] = (0, 7, 8, 10, 11, 20, 21, 22, 23)
#: The 15 "major" joints of DIP/SIP/EM-POSE metrics (all others).
MAJOR_JOINTS: tuple[int, ...] = tuple(j for j in range(NUM_JOINTS) if j not in IGNORED_JOINTS)
#: Joints of the SIP error (global orientation of hips and shoulders), SMPL indices.
SIP_JOINTS: tuple[int, ...] = (1, 2, 16, 17)
#: Left/right mirror of each joint index.
MIRROR: tuple[int, ...] = (0, 2, 1, 3, 5, 4, 6, 8, 7, 9, 11, 10, 12, 14, 13, 15, 17, 16, 19, 18, 21, 20, 23, 22)

assert len(PARENTS) == NUM_JOINTS and len(MAJOR_JOINTS) == 15
