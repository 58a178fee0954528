"""The floating-base articulated character of PIP (Sec. 3.2.1), built on Pinocchio.

Skeleton: SMPL's 24 joints on the body asset's rest joints for the subject's betas. Joint 0
(pelvis) is a free-flyer (6 DoF), the other 23 are spherical joints (3 DoF each), so the model has
``nq = 7 + 23 * 4 = 99`` configuration and ``nv = 6 + 23 * 3 = 75`` velocity coordinates.
Joint frames are aligned with the world at zero pose (SMPL convention), so each spherical joint's
rotation *is* the SMPL local rotation of that joint and the free-flyer's rotation is the root
orientation. The free-flyer's placement is the rest pelvis position, so its translation
coordinate equals SMPL's ``trans`` (metres, world, Y up).

Configuration / velocity layout (Pinocchio's). Pinocchio's algorithms (CRBA in particular)
need every joint's subtree to follow it contiguously, i.e. joints in depth-first order, which
SMPL's order is not; so the joints are added in :data:`DFS_ORDER` and
``PhysicsCharacter.pin_id[j]`` is the Pinocchio joint id of SMPL joint ``j``.
- ``q[0:3]`` = trans; ``q[3:]`` reshaped ``(24, 4)`` = joint quaternions ``(x, y, z, w)`` in
  ``DFS_ORDER``.
- ``v[0:3]`` = root linear velocity *in the root frame*; ``v[3:]`` reshaped ``(24, 3)`` = angular
  velocity of each joint relative to its parent, in the joint's own frame (root: w.r.t. world),
  in ``DFS_ORDER``.

Mass distribution (documented, deterministic):
- **Total mass**: ``density * volume`` of the rest mesh for these betas (closed-mesh divergence
  theorem) with ``density`` = :data:`BODY_DENSITY` (1010 kg/m^3, whole-body density of a
  living adult with normal breathing, cf. Winter, *Biomechanics and Motor Control of Human
  Movement*, Table 4.1 ~1.01-1.07 g/cm^3 by segment). Override with ``mass_kg``. If the mesh
  gives an implausible volume (open mesh, tiny test asset) :data:`DEFAULT_MASS_KG` is used.
- **Segment masses**: fractions of the total mass from de Leva (1996, J. Biomech. 29(9),
  adjustments to Zatsiorsky-Seluyanov, male column) mapped onto the SMPL bodies
  (:data:`SEGMENT_MASS_FRACTION`); de Leva's segments that SMPL splits in two (trunk, head+neck,
  foot, hand) are shared as stated there. Sums to 1.
- **Segment COM and inertia**: each body is a solid cylinder fitted to the rest-mesh vertices
  whose dominant skinning weight is that joint: centre = their centroid, axis = their principal
  direction, length ``sqrt(12 var)`` along it, radius = mean distance from the axis. Inertia:
  ``m r^2 / 2`` about the axis, ``m (3 r^2 + l^2) / 12`` across it.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin
import torch

from wearpose.body import JOINT_NAMES, NUM_JOINTS, PARENTS, BodyModel
from wearpose.errors import ShapeError, WearposeError
from wearpose.geometry import GRAVITY, matrix_to_quat, quat_to_matrix

def _dfs_order() -> tuple[int, ...]:
    children: dict[int, list[int]] = {j: [] for j in range(NUM_JOINTS)}
    for j, p in enumerate(PARENTS):
        if p >= 0:
            children[p].append(j)
    out: list[int] = []
    stack = [0]
    while stack:
        j = stack.pop()
        out.append(j)
        stack.extend(reversed(children[j]))
    return tuple(out)


#: SMPL joint indices in the order they are added to the Pinocchio model (depth-first).
DFS_ORDER: tuple[int, ...] = _dfs_order()
#: Pinocchio joint id of each SMPL joint.
PIN_ID: np.ndarray = np.argsort(np.array(DFS_ORDER)) + 1

#: Whole-body density, kg/m^3 (see module docstring).
BODY_DENSITY = 1010.0
#: Mass used when the mesh volume is not usable (kg).
DEFAULT_MASS_KG = 70.0
#: Plausible mesh-derived mass range (kg); outside it the default is used.
_PLAUSIBLE_MASS = (25.0, 250.0)

#: Fraction of total body mass per SMPL body (body j spans joint j to its children).
#: de Leva 1996, male: head+neck 6.94 (neck 1.2 + head 5.74), trunk 43.46 = upper 15.96
#: (spine3 11.96 + collars 2 x 2.0) + middle 16.33 (spine1, spine2 half each) + lower/pelvis
#: 11.17; upper arm 2.71; forearm 1.62; hand 0.61 (palm 0.42 on the wrist body, fingers 0.19 on
#: the hand body); thigh 14.16; shank 4.33; foot 1.37 (rear/mid foot 1.17 on the ankle body,
#: toes 0.20 on the foot body).
SEGMENT_MASS_FRACTION: dict[str, float] = {
    "pelvis": 0.1117, "spine1": 0.08165, "spine2": 0.08165, "spine3": 0.1196,
    "left_collar": 0.020, "right_collar": 0.020, "neck": 0.012, "head": 0.0574,
    "left_hip": 0.1416, "right_hip": 0.1416, "left_knee": 0.0433, "right_knee": 0.0433,
    "left_ankle": 0.0117, "right_ankle": 0.0117, "left_foot": 0.0020, "right_foot": 0.0020,
    "left_shoulder": 0.0271, "right_shoulder": 0.0271, "left_elbow": 0.0162, "right_elbow": 0.0162,
    "left_wrist": 0.0042, "right_wrist": 0.0042, "left_hand": 0.0019, "right_hand": 0.0019,
}
assert abs(sum(SEGMENT_MASS_FRACTION.values()) - 1.0) < 1e-9


def mesh_volume(vertices: np.ndarray, faces: np.ndarray) -> float:
    """Signed volume (m^3) of a closed, outward-oriented triangle mesh (divergence theorem)."""
    v0, v1, v2 = vertices[faces[:, 0]], vertices[faces[:, 1]], vertices[faces[:, 2]]
    return float(np.einsum("ij,ij->i", v0, np.cross(v1, v2)).sum() / 6.0)


def _cylinder_fit(points: np.ndarray, mass: float) -> tuple[np.ndarray, np.ndarray]:
    """COM ``(3,)`` and inertia about the COM ``(3, 3)`` of a solid cylinder fitted to ``points``."""
    if len(points) < 4:  # degenerate asset: a small sphere of radius 3 cm at the points' mean
        com = points.mean(0) if len(points) else np.zeros(3)
        return com, np.eye(3) * 0.4 * mass * 0.03 ** 2
    com = points.mean(0)
    d = points - com
    evals, evecs = np.linalg.eigh(d.T @ d / len(d))
    axis = evecs[:, -1]
    length = float(np.sqrt(12.0 * max(evals[-1], 1e-8)))
    radial = d - np.outer(d @ axis, axis)
    r = max(float(np.linalg.norm(radial, axis=1).mean()), 0.01)
    i_ax = 0.5 * mass * r * r
    i_perp = mass * (3 * r * r + length * length) / 12.0
    inertia = i_perp * np.eye(3) + (i_ax - i_perp) * np.outer(axis, axis)
    return com, inertia


@dataclass
class PhysicsCharacter:
    """Pinocchio model of one subject. Build with :meth:`from_body`.

    Attributes:
        model: ``pinocchio.Model`` (free-flyer root + 23 spherical joints in :data:`DFS_ORDER`;
            Pinocchio joint id of SMPL joint ``j`` is ``pin_id[j]``), gravity ``(0, -9.81, 0)``.
        rest_joints: ``(24, 3)`` rest joint positions, m (model frame, zero trans).
        segment_mass: ``(24,)`` kg per SMPL body.
        mass_kg: total mass, kg.
        mass_source: ``"mesh"`` (density x volume), ``"given"`` or ``"default"``.
    """

    model: pin.Model
    rest_joints: np.ndarray
    segment_mass: np.ndarray
    mass_kg: float
    mass_source: str
    betas: np.ndarray = field(default_factory=lambda: np.zeros(10))

    @property
    def pin_id(self) -> np.ndarray:
        """``(24,)`` Pinocchio joint id of each SMPL joint."""
        return PIN_ID

    @property
    def nq(self) -> int:
        return int(self.model.nq)

    @property
    def nv(self) -> int:
        return int(self.model.nv)

    @classmethod
    def from_body(cls, body: BodyModel, betas: torch.Tensor | None = None, mass_kg: float | None = None,
                  density: float = BODY_DENSITY) -> PhysicsCharacter:
        """Build the character of ``body`` with shape ``betas`` ``(num_betas,)`` (None = mean shape).

        Args:
            body: the body model (any asset: embedded or SMPL file).
            betas: ``(S,)`` shape coefficients.
            mass_kg: total mass in kg; ``None`` = ``density`` x rest-mesh volume.
            density: kg/m^3 used when ``mass_kg`` is None.
        """
        if betas is None:
            betas = torch.zeros(body.num_betas)
        betas = torch.as_tensor(betas).reshape(-1)
        if betas.shape[0] != body.num_betas:
            raise ShapeError(f"betas: expected ({body.num_betas},), got {tuple(betas.shape)}")
        if mass_kg is not None and not (mass_kg > 0):
            raise WearposeError(f"mass_kg: expected a positive mass in kg, got {mass_kg}")
        with torch.no_grad():
            out = body(None, betas.to(body.dtype), None, return_normals=False)
        verts = out.vertices.double().cpu().numpy()
        rest = out.rest_joints.double().cpu().numpy()
        faces = body.faces.cpu().numpy()
        if mass_kg is not None:
            total, source = float(mass_kg), "given"
        else:
            total, source = density * abs(mesh_volume(verts, faces)), "mesh"
            if not (_PLAUSIBLE_MASS[0] <= total <= _PLAUSIBLE_MASS[1]):
                total, source = DEFAULT_MASS_KG, "default"
        seg_mass = np.array([SEGMENT_MASS_FRACTION[n] * total for n in JOINT_NAMES])
        owner = body.weights.argmax(dim=1).cpu().numpy()

        model = pin.Model()
        model.name = "wearpose-pip-character"
        model.gravity.linear = np.array(GRAVITY, dtype=np.float64)
        for j in DFS_ORDER:
            p = PARENTS[j]
            if p < 0:
                jid = model.addJoint(0, pin.JointModelFreeFlyer(), pin.SE3(np.eye(3), rest[0].copy()), JOINT_NAMES[0])
            else:
                jid = model.addJoint(int(PIN_ID[p]), pin.JointModelSpherical(), pin.SE3(np.eye(3), rest[j] - rest[p]),
                                     JOINT_NAMES[j])
            assert jid == PIN_ID[j]
            com, inertia = _cylinder_fit(verts[owner == j] - rest[j], seg_mass[j])
            model.appendBodyToJoint(jid, pin.Inertia(float(seg_mass[j]), com, inertia), pin.SE3.Identity())
        return cls(model=model, rest_joints=rest, segment_mass=seg_mass, mass_kg=total, mass_source=source,
                   betas=betas.double().cpu().numpy())

    # ------------------------------------------------------------------ conversions
    def q_from_pose(self, pose_local: torch.Tensor | np.ndarray, trans: torch.Tensor | np.ndarray) -> np.ndarray:
        """Pinocchio configuration ``(99,)`` float64 from local rotations ``(24, 3, 3)`` and trans ``(3,)`` m."""
        R = torch.as_tensor(pose_local, dtype=torch.float64)
        if R.shape != (NUM_JOINTS, 3, 3):
            raise ShapeError(f"pose_local: expected (24, 3, 3) local rotation matrices, got {tuple(R.shape)}")
        t = torch.as_tensor(trans, dtype=torch.float64).reshape(-1)
        if t.shape != (3,):
            raise ShapeError(f"trans: expected (3,) metres, got {tuple(t.shape)}")
        return self.q_from_motion(R[None], t[None])[0]

    def q_from_motion(self, pose_local: torch.Tensor | np.ndarray, trans: torch.Tensor | np.ndarray) -> np.ndarray:
        """Pinocchio configurations ``(T, 99)`` float64 of a motion: local rotations ``(T, 24, 3, 3)``
        and root translation ``(T, 3)`` m (the batched :meth:`q_from_pose`)."""
        R = torch.as_tensor(pose_local, dtype=torch.float64)
        t = torch.as_tensor(trans, dtype=torch.float64)
        if R.dim() != 4 or R.shape[1:] != (NUM_JOINTS, 3, 3):
            raise ShapeError(f"pose_local: expected (T, 24, 3, 3) local rotation matrices, got {tuple(R.shape)}")
        if t.shape != (R.shape[0], 3):
            raise ShapeError(f"trans: expected ({R.shape[0]}, 3) metres, got {tuple(t.shape)}")
        quat = matrix_to_quat(R[:, list(DFS_ORDER)]).numpy()  # (T, 24, 4) w, x, y, z in Pinocchio order
        return np.concatenate([t.numpy(), quat[..., [1, 2, 3, 0]].reshape(len(quat), -1)], axis=1)

    def pose_from_q(self, q: np.ndarray) -> tuple[torch.Tensor, torch.Tensor]:
        """Local rotations ``(24, 3, 3)`` and trans ``(3,)`` (float32 tensors) from a configuration."""
        quat = torch.from_numpy(np.ascontiguousarray(q[3:].reshape(NUM_JOINTS, 4)[PIN_ID - 1][:, [3, 0, 1, 2]]))
        return quat_to_matrix(quat).float(), torch.from_numpy(q[:3].copy()).float()

    def center_of_mass(self, q: np.ndarray) -> np.ndarray:
        """Whole-body centre of mass ``(3,)`` m, world frame, at configuration ``q``."""
        data = self.model.createData()
        return np.array(pin.centerOfMass(self.model, data, q))
