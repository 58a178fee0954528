"""Physics of PIP (Sec. 3.2): an articulated character from the body asset, dynamics via
Pinocchio, the dual PD controller and the contact QP solved with proxsuite.

Public entry: :class:`PhysicsCharacter`, :class:`PhysicsConfig`, :class:`PhysicsOptimizer`,
:class:`PhysicsState`; :func:`zmp_distance` (PIP's ZMP metric). See ``docs/physics.md``.
"""

from wearpose.physics.reference import FOOT_JOINTS, KinematicReference, kinematic_reference
from wearpose.physics.optimizer import PhysicsConfig, PhysicsOptimizer, PhysicsState
from wearpose.physics.zmp import ZMP_FEET, ZmpResult, convex_hull_2d, distance_to_polygon, zmp_distance
from wearpose.physics.character import (
    BODY_DENSITY, DEFAULT_MASS_KG, SEGMENT_MASS_FRACTION, PhysicsCharacter, mesh_volume,
)

__all__ = [
    "PhysicsConfig", "PhysicsOptimizer", "PhysicsState",
    "KinematicReference", "kinematic_reference", "FOOT_JOINTS",
    "zmp_distance", "ZmpResult", "ZMP_FEET", "convex_hull_2d", "distance_to_polygon",
    "PhysicsCharacter", "BODY_DENSITY", "DEFAULT_MASS_KG", "SEGMENT_MASS_FRACTION", "mesh_volume",
]
