"""Motion data: ``MotionSequence``, BVH, ASF/AMC and AMASS readers, retargeting to SMPL-24, resampling,
and the prepared corpus store.

World frame everywhere: Y up, metres, at zero pose the body faces +Z with its left at +X.
"""

from wearpose.motion.amass import read_amass, save_amass
from wearpose.motion.augment import mirror, play_speed
from wearpose.motion.asf import AsfSkeleton, find_asf_for, parse_amc_text, parse_asf_text, read_asf, read_asf_amc
from wearpose.motion.bvh import (
    BvhMotion, BvhSkeleton, bvh_forward_kinematics, end_site_positions, parse_bvh_text, read_bvh,
)
from wearpose.motion.importer import ImportReport, Imported, collect_motion_files, import_motion, import_paths
from wearpose.motion.load import load_motion
from wearpose.motion.mapping import CMU_ASF, MIXAMO, NAMED_MAPS, RIGIFY, SMPL_NAMES, SkeletonMatch, match_skeleton
from wearpose.motion.paths import cache_dir, data_dir
from wearpose.motion.resample import resample
from wearpose.motion.retarget import (
    BANDAI, BUILTIN_MAPS, CMU_DAZ, LegMeasures, RetargetError, Retargeted, SkeletonMap, TPose, bone_direction_errors,
    detect_skeleton_map, estimate_hinge_axes, leg_measures, lowest_foot_height, refit_to_body, retarget_bvh, solve_tpose,
)
from wearpose.motion.sequence import FORMAT_VERSION, MotionSequence
from wearpose.motion.smpl_bvh import is_smpl_bvh, read_smpl_bvh
from wearpose.motion.store import CorpusStore, prepare_corpus
from wearpose.motion.template import default_rest_joints, template_rest_joints

__all__ = [
    "MotionSequence", "FORMAT_VERSION", "resample", "load_motion", "mirror", "play_speed",
    "read_bvh", "parse_bvh_text", "BvhMotion", "BvhSkeleton", "bvh_forward_kinematics", "end_site_positions",
    "retarget_bvh", "Retargeted", "SkeletonMap", "TPose", "solve_tpose", "detect_skeleton_map", "estimate_hinge_axes",
    "bone_direction_errors", "lowest_foot_height", "leg_measures", "LegMeasures", "refit_to_body", "RetargetError", "CMU_DAZ", "BANDAI", "BUILTIN_MAPS",
    "read_amass", "save_amass", "read_asf", "read_asf_amc", "parse_asf_text", "parse_amc_text", "find_asf_for",
    "AsfSkeleton", "read_smpl_bvh", "is_smpl_bvh",
    "import_motion", "import_paths", "collect_motion_files", "ImportReport", "Imported",
    "match_skeleton", "SkeletonMatch", "NAMED_MAPS", "CMU_ASF", "MIXAMO", "RIGIFY", "SMPL_NAMES",
    "prepare_corpus", "CorpusStore", "data_dir", "cache_dir",
    "default_rest_joints", "template_rest_joints",
]
