"""The body model: SMPL-format linear blend skinning on a free embedded asset or a user's SMPL file.

Public entry: :class:`BodyModel` (forward returns :class:`BodyOutput`), skeleton constants,
:func:`forward_kinematics`, the calibration poses (:func:`calibration_pose`), asset loaders.
"""

from wearpose.body.asset import BodyAsset, load_asset_npz, load_default_asset, load_smpl_file
from wearpose.body.model import BodyModel, BodyOutput, LowestPoint, SiteOutput
from wearpose.body.kinematics import forward_kinematics, global_to_local
from wearpose.body.poses import IPOSE_ANGLE, POSES, calibration_pose
from wearpose.body.skeleton import (
    IGNORED_JOINTS, JOINT_INDEX, JOINT_NAMES, MAJOR_JOINTS, MIRROR, NUM_JOINTS, PARENTS, SIP_JOINTS,
)

__all__ = [
    "BodyModel", "BodyOutput", "LowestPoint", "SiteOutput",
    "BodyAsset", "load_asset_npz", "load_default_asset", "load_smpl_file",
    "forward_kinematics", "global_to_local", "calibration_pose", "POSES", "IPOSE_ANGLE",
    "JOINT_NAMES", "JOINT_INDEX", "NUM_JOINTS", "PARENTS", "MAJOR_JOINTS", "IGNORED_JOINTS", "SIP_JOINTS", "MIRROR",
]
