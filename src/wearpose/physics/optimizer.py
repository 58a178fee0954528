"""PIP's physics-aware motion optimizer (Sec. 3.2.2-3.2.4): dual PD controller + contact QP.

Per frame (:meth:`PhysicsOptimizer.step`):

1. Dynamics at the current state ``(q, v)`` from Pinocchio: mass matrix ``M`` (CRBA), non-linear
   effects ``h`` (RNEA with zero acceleration), joint Jacobians ``J`` and their time variation
   ``dJ`` (``computeJointJacobiansTimeVariation``), in the ``LOCAL_WORLD_ALIGNED`` frame.
2. Dual PD controller. Rotation controller (Eq. 3) on every rotational DoF (root orientation and
   the 23 joints): ``qdd_rot_des = kp_theta * log(R^T R_ref) - kd_theta * v_rot`` (the Lie-group
   difference stands in for the paper's Euler-angle difference ``E(phi) - theta``).
   Position controller (Eqs. 4-6) on the world positions of the joints in
   ``PhysicsConfig.position_joints``: ``r_ref = r + v_ref dt``,
   ``rdd_des = kp_r (r_ref - r) - kd_r J v``. With ``dual_pd=False`` (the paper's single-PD
   ablation, "a single PD controller that only watches q") only the root joint's position is
   controlled, i.e. a PD on the translation part of ``q`` with reference ``trans + v_root dt``.
3. QP (Eq. 7-12) solved by proxsuite (dense):
   ``min k_theta |qdd_rot - qdd_rot_des|^2 + k_r |J qdd + dJ v - rdd_des|^2
   + k_lambda sum_c d_c |lambda_c|^2 + k_res |tau_root|^2 + k_tau |tau_joints|^2``
   s.t. ``M qdd + h = tau + J_c^T lambda`` (equation of motion), ``lambda_c`` in the 4-sided
   friction pyramid (``mu``), and for every contact joint
   ``J_j (v + qdd dt)`` in ``{y >= 0, |x| <= sigma, |z| <= sigma}`` (no sliding, Eq. 11-12).
   By default the torques are eliminated through the equation of motion
   (``tau = M qdd + h - J_c^T lambda``), which gives the same minimiser with half the
   variables and no equality constraints; ``eliminate_torques=False`` solves the paper's
   three-block form (tests check both agree).
4. State update (Eq. 13), semi-implicit Euler: ``v += qdd dt``, ``q = q (+) v dt`` (Pinocchio's
   ``integrate`` on the Lie group). The original PIP implementation updates in this order too.

Contacts (Sec. 3.2.3): a foot joint (``foot_joints``, SMPL ``left_foot``/``right_foot``) is in
contact if its height above the ground is below ``contact_height`` (0.5 cm), or below
``foot_contact_height`` (3 cm) with contact probability above 0.5; any other joint of
``contact_candidates`` only below 0.5 cm. Each contact joint contributes the 4 corners of an
``L x L`` horizontal, world-aligned square (L = 20 cm) at its height as contact points, centred
on the joint, except that a foot's square is moved half-way towards its ankle
(``foot_square_shift``, why: see :class:`PhysicsConfig`).

Ground: the plane ``y = ground_y``. ``PhysicsConfig.ground_y=None`` places it at the lowest
joint of ``contact_candidates`` at :meth:`PhysicsOptimizer.reset` (the subject starts on the
ground, as PIP assumes); the motion corpus floor is at the height of the lowest *foot joint*,
which is 0-4 cm above ``y = 0`` depending on the source.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pinocchio as pin
import proxsuite
import torch

from wearpose.body import JOINT_INDEX, NUM_JOINTS, PARENTS
from wearpose.errors import ConfigError, ShapeError
from wearpose.physics._blas import limit_blas_threads
from wearpose.physics.character import DFS_ORDER, PhysicsCharacter

_LWA = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
_SOLVED = proxsuite.proxqp.QPSolverOutput.PROXQP_SOLVED
_NO_CONTACT = ("left_ankle", "right_ankle", "neck", "left_wrist", "right_wrist", "left_collar", "right_collar", "pelvis")


@dataclass
class PhysicsConfig:
    """Gains and weights of the physics module; defaults are PIP's (Sec. 3.2, appendix A).

    Attributes:
        fps: frame rate (Hz); ``dt = 1 / fps`` is the simulation step (PIP: 60).
        dual_pd: dual PD controller (rotation + joint position); False = single PD ablation.
        kp_theta, kd_theta: rotation controller gains (PIP: 2400, 60; appendix A derives 3600
            and lowers kp for smoother angular accelerations).
        kp_r, kd_r: joint position controller gains (PIP: 3600, 60 = 1/dt^2, 1/dt for 60 fps).
        k_theta, k_r: weights of the two PD energies (PIP: 1, 1).
        k_lambda, k_res, k_tau: regulariser weights (PIP: 10, 0.1, 0.01).
        mu: friction coefficient of the linearised (4-sided pyramid) cone (PIP: 0.6).
        sigma: allowed horizontal speed of a contact joint, m/s (PIP: 0.01).
        square_size: side L of the contact square per contact joint, m (PIP: 0.2).
        contact_height: any candidate joint closer than this to the ground is in contact, m
            (PIP: 0.5 cm).
        foot_contact_height: a foot joint closer than this with contact probability above
            ``contact_prob_threshold`` is in contact, m (PIP: 3 cm, 0.5).
        min_contact_weight: floor on the point height ``d_c`` in the Signorini term, m: with
            ``d_c = 0`` a point at (or below) the ground would have no force regulariser at
            all. 1 mm; PIP's released code uses 5 mm, which puts less weight on the feet
            (standing T-pose 96.8 % vs 99.8 % of m g; val walking clip 93.0 % vs 94.9 %).
        ground_bound: lower bound of a contact joint's vertical velocity (Eq. 11). True:
            ``(ground_y - y) / dt``, i.e. the joint may not be below the ground after the step
            (it may settle onto the ground from up to ``foot_contact_height`` above, and is pushed
            back out if below), as PIP's released code does for the feet. False: the paper's
            literal ``>= 0``, under which a foot that enters contact above the ground can never
            come down, its Signorini weight ``d_c`` stays high and the residual root force
            carries the body (val walking clip: 77.6 % of body weight on the feet vs 94.9 %).
        foot_contact_requires_prob: a foot joint is in contact only by the probability rule
            (within ``foot_contact_height`` and probability above the threshold); the paper
            also takes a foot below ``contact_height`` (0.5 cm) regardless of its probability.
            Why: under that rule a foot still on the ground when the reference lifts it
            (c -> 0) stays held by the no-sliding constraint (1 cm/s), can only leave
            vertically, and the gait falls out of step with the reference (val walking clip
            driven by ground truth: 78 % of body weight on the feet, root-relative joints
            6.9 cm off, translation 0.76 m off on average; 95 %, 1.0 cm, 0.17 m with this
            rule). PIP's released code likewise frees a foot whose probability is low.
        contact_no_lift: a foot the network calls planted (probability above the threshold) may
            not rise faster than ``sigma`` -- in contact its vertical velocity joins the no-sliding
            bound (unless pushed out of the ground), above the ground (not yet in contact) it may
            only come down; other contact joints (knees, hands) are not bound this way. The
            paper bounds only ``ydot >= 0``; PIP's released code bounds a foot's upward speed by
            ``-log(min(p, 0.85) / 0.85)`` (0 for a confident contact) whatever its height. Why:
            without it a planted foot drifts up a few mm, its Signorini weight ``d_c`` (its
            height) makes ground forces expensive, and the residual root force carries the
            body: with the networks on the 13 val walking clips the feet carried 77 % of the
            body weight (96 % with it), on the test clips 83 % (see docs/physics.md).
        guard_all_candidates: add, for every contact candidate *not* in contact, the row
            ``y + J_y (v + qdd dt) dt >= ground_y`` (no penetration after the step, no force)
            so that joints outside contact (e.g. a foot whose probability is low) do not sink
            into the ground (val walking clip: 2.5 cm deepest penetration without, 0 with).
            Not in the paper; False = off.
        foot_square_shift: the square of a foot joint is centred this fraction of the way from
            the foot joint to its ankle (horizontally). PIP centres every square on its joint
            (0.0); SMPL's foot joint is the ball of the foot, so a square centred there covers
            toes to mid-foot and leaves the heel out (heel to toe tips span -3..23 cm in Z on
            the embedded asset; the ankle-foot midpoint is at 10 cm, the foot joint at 17 cm).
            0.5 centres it on the sole. Small effect, measured: standing T-pose residual force
            3.0 vs 7.5 N and drift 0.3 vs 0.7 cm in 2 s; walking about the same.
        foot_release_speed: a foot whose reference velocity (the kinematics' joint velocity, m/s)
            is faster than this is not planted whatever its contact probability (None = off, the
            paper). Why: PIP's contact labels are "foot slower than 0.48 m/s" (TransPose's
            threshold, ours too), so a foot the network itself moves faster is leaving the
            ground; on runs the network keeps the contact probability high for about twice the
            true stance, and a planted foot that may neither slide nor rise holds the body back
            (val, 30 clips: translation 65.0 -> 58.6 cm with dual PD; walking GRF 96.1 -> 93.7 %
            of body weight; docs/pip.md, "Translation"). Ground-truth references never trigger
            it (their contact label already requires the 0.48 m/s).
        ground_y: ground height in world Y, m; None = lowest contact candidate at reset.
        foot_joints: SMPL joints whose contact uses ``contact_prob`` (left, right).
        contact_candidates: SMPL joints tested for ground contact.
        position_joints: joints under the position controller (default: all 24).
        eliminate_torques: solve for (qdd, lambda) with tau eliminated through the equation of
            motion (same minimiser, smaller QP); False = (qdd, lambda, tau) with equalities.
        weights_in_norm: how the weights enter the energy. PIP's Eq. 8-9 write ``k * |r|^2``;
            PIP's released implementation multiplies each residual by its weight inside the norm,
            ``|k r|^2`` (so ``k_res = 0.1`` acts as 0.01, ``k_tau = 0.01`` as 1e-4 and the
            Signorini term as ``(k_lambda d_c)^2 |lambda_c|^2``). True (default) follows the
            implementation. Measured on the val split with ground-truth kinematics
            (``benchmarks/results/physics_val_*.json``): the literal reading penalises joint
            torques so much that the body does not hold still -- a standing T-pose slides
            8.7 cm in 2 s (0.3 cm in-norm), waving/arm-raising clips drift 0.10-0.12 m
            (0.01-0.03 m) and their root-relative joints are 1.4-3.2 cm off (0.3 cm) -- while on
            walking it gives a lower translation error (0.08 vs 0.15 m mean, 4 clips).
        eps_abs: proxsuite absolute accuracy.
        blas_threads: threads of numpy's OpenBLAS, set process-wide when the optimizer is built
            (1: the step's matrices are small and multi-threaded BLAS costs 10-50 ms per step on
            a loaded 2-core machine); None leaves BLAS alone.
    """

    fps: float = 60.0
    dual_pd: bool = True
    kp_theta: float = 2400.0
    kd_theta: float = 60.0
    kp_r: float = 3600.0
    kd_r: float = 60.0
    k_theta: float = 1.0
    k_r: float = 1.0
    k_lambda: float = 10.0
    k_res: float = 0.1
    k_tau: float = 0.01
    mu: float = 0.6
    sigma: float = 0.01
    square_size: float = 0.2
    contact_height: float = 0.005
    foot_contact_height: float = 0.03
    contact_prob_threshold: float = 0.5
    min_contact_weight: float = 0.001
    ground_bound: bool = True
    foot_contact_requires_prob: bool = True
    guard_all_candidates: bool = True
    foot_square_shift: float = 0.5
    contact_no_lift: bool = True
    foot_release_speed: float | None = 0.48
    ground_y: float | None = None
    foot_joints: tuple[int, int] = (JOINT_INDEX["left_foot"], JOINT_INDEX["right_foot"])
    contact_candidates: tuple[int, ...] = tuple(
        j for j in range(NUM_JOINTS) if j not in {JOINT_INDEX[n] for n in _NO_CONTACT})
    position_joints: tuple[int, ...] = tuple(range(NUM_JOINTS))
    eliminate_torques: bool = True
    eps_abs: float = 1e-6
    weights_in_norm: bool = True
    blas_threads: int | None = 1

    def __post_init__(self) -> None:
        if not self.fps > 0:
            raise ConfigError(f"PhysicsConfig.fps: expected a positive frame rate in Hz, got {self.fps}")
        for name in ("kp_theta", "kd_theta", "kp_r", "kd_r", "k_theta", "k_r", "k_lambda", "k_res", "k_tau", "mu",
                     "sigma", "square_size"):
            if getattr(self, name) < 0:
                raise ConfigError(f"PhysicsConfig.{name}: expected >= 0, got {getattr(self, name)}")
        if self.foot_release_speed is not None and not self.foot_release_speed > 0:
            raise ConfigError(f"PhysicsConfig.foot_release_speed: expected a speed > 0 m/s or None (off), "
                              f"got {self.foot_release_speed}")
        for name in ("foot_joints", "contact_candidates", "position_joints"):
            bad = [j for j in getattr(self, name) if not 0 <= j < NUM_JOINTS]
            if bad:
                raise ConfigError(f"PhysicsConfig.{name}: joint indices {bad} outside 0..23")
        missing = [j for j in self.foot_joints if j not in self.contact_candidates]
        if missing:
            raise ConfigError(f"PhysicsConfig.contact_candidates: must include the foot joints {missing}")

    @property
    def dt(self) -> float:
        return 1.0 / self.fps


@dataclass
class PhysicsState:
    """Output of one :meth:`PhysicsOptimizer.step` (the state after the update, frame t+1).

    Attributes:
        pose_local: ``(24, 3, 3)`` float32 local joint rotations.
        trans: ``(3,)`` float32 root translation, m (SMPL ``trans``).
        joints: ``(24, 3)`` float32 world joint positions after the update, m.
        torques: ``(24, 3)`` float32 joint torques, N*m, each in its joint's own frame (row j:
            torque of the parent on body j about joint j); row 0 = the root's residual
            (virtual) torque in the root frame.
        residual: ``(6,)`` float32 residual root wrench (force N, torque N*m) in the root frame.
        grf: ``(2, 3)`` float32 ground reaction force on the left / right foot, N, world frame
            (sum over that foot joint's 4 contact points).
        grf_joints: ``(24, 3)`` float32 ground reaction force per contact joint, N, world.
        contacts: ``(2,)`` bool, left / right foot used as contact in this step's QP.
        contact_joints: ``(24,)`` bool, every joint used as contact.
        zmp: ``(2,)`` float32 centre of pressure of the GRF on the ground, world (x, z), m;
            NaN when nothing touches the ground.
        penetration_m: largest depth of a contact-candidate joint below the ground after the
            update, m (0 when none is below).
        qp_ms: proxsuite solve time, ms (building the QP excluded).
        step_ms: wall time of the whole step, ms.
        qp_cpu_ms: CPU time of this thread in the solve, ms.
        step_cpu_ms: CPU time of this thread in the step, ms (less inflated than the wall time
            when other processes compete for the cores).
        qp_status: proxsuite status string.
        contact_points: ``(nc, 3)`` float32 world positions of this step's contact points (m,
            before the update; 4 per contact joint, in the order of ``contact_joints``).
        contact_forces: ``(nc, 3)`` float32 force on each contact point, N, world.
    """

    pose_local: torch.Tensor
    trans: torch.Tensor
    joints: torch.Tensor
    torques: torch.Tensor
    residual: torch.Tensor
    grf: torch.Tensor
    grf_joints: torch.Tensor
    contacts: torch.Tensor
    contact_joints: torch.Tensor
    zmp: torch.Tensor
    penetration_m: float
    qp_ms: float
    step_ms: float
    step_cpu_ms: float = 0.0
    qp_cpu_ms: float = 0.0
    qp_status: str = ""
    contact_points: torch.Tensor | None = None
    contact_forces: torch.Tensor | None = None


@dataclass
class _Dyn:
    """Dynamics quantities at the current state (float64 numpy)."""

    M: np.ndarray  # (nv, nv)
    R: np.ndarray  # (24, 3, 3) local joint rotations (SMPL order)
    h: np.ndarray  # (nv,)
    pos: np.ndarray  # (24, 3) joint positions, world
    J: np.ndarray  # (24, 6, nv) LWA joint Jacobians (linear rows 0:3, angular 3:6)
    dJv: np.ndarray  # (24, 3) classical linear acceleration bias dJ v of each joint origin
    extra: dict = field(default_factory=dict)


def _skew(o: np.ndarray) -> np.ndarray:
    """``(..., 3) -> (..., 3, 3)`` cross-product matrices."""
    z = np.zeros(o.shape[:-1])
    x, y, w = o[..., 0], o[..., 1], o[..., 2]
    return np.stack([np.stack([z, -w, y], -1), np.stack([w, z, -x], -1), np.stack([-y, x, z], -1)], -2)


def contact_square(square_size: float) -> np.ndarray:
    """World offsets ``(4, 3)`` m of the 4 points of a horizontal, world-aligned contact square of
    side ``square_size`` (PIP's facet contact) centred on its joint."""
    h = square_size / 2
    return np.array([[-h, 0, -h], [h, 0, -h], [-h, 0, h], [h, 0, h]])


def contact_offsets(pos: np.ndarray, cj: Any, square: np.ndarray, foot_joints: Any, foot_square_shift: float
                    ) -> np.ndarray:
    """World offsets ``(nj, 4, 3)`` m of the contact points of joints ``cj`` from the joints.

    Args:
        pos: ``(24, 3)`` joint positions, m, world.
        cj: ``nj`` joint indices in contact.
        square: ``(4, 3)`` :func:`contact_square`.
        foot_joints, foot_square_shift: a foot joint's square is moved this fraction of the way
            (horizontally) towards its parent, the ankle (see :class:`PhysicsConfig`).
    """
    offs = np.repeat(square[None], len(cj), axis=0)
    if foot_square_shift:
        for i, j in enumerate(cj):
            if j in foot_joints:
                d = pos[PARENTS[j]] - pos[j]
                offs[i, :, [0, 2]] += foot_square_shift * d[[0, 2]][:, None]
    return offs


class PhysicsOptimizer:
    """Online physics optimizer of PIP for one character.

    Example:
        >>> char = PhysicsCharacter.from_body(BodyModel(), torch.zeros(10))
        >>> opt = PhysicsOptimizer(char, PhysicsConfig())
        >>> opt.reset(torch.eye(3).expand(24, 3, 3), torch.zeros(3))
        >>> st = opt.step(torch.eye(3).expand(24, 3, 3), torch.zeros(24, 3), torch.ones(2))
    """

    def __init__(self, character: PhysicsCharacter, config: PhysicsConfig | None = None) -> None:
        self.char = character
        self.config = config or PhysicsConfig()
        if self.config.blas_threads is not None:
            limit_blas_threads(self.config.blas_threads)
        self.model = character.model
        self.data = self.model.createData()
        self.nv = self.model.nv
        self._square = contact_square(self.config.square_size)
        mu = self.config.mu
        # Friction pyramid rows F lambda <= 0 per point (Eq. 10): |x| <= mu y, |z| <= mu y.
        self._fric = np.array([[1.0, -mu, 0.0], [-1.0, -mu, 0.0], [0.0, -mu, 1.0], [0.0, -mu, -1.0]])
        c = self.config
        w = np.full(self.nv, c.k_tau)
        w[:6] = c.k_res
        self._w_tau = w ** 2 if c.weights_in_norm else w
        rot = np.zeros((self.nv - 3, self.nv))
        rot[:, 3:] = np.eye(self.nv - 3)
        self._S_rot = rot
        self._dfs = np.array(DFS_ORDER)
        self._pin_ids = [int(j) for j in character.pin_id]
        self._rot_diag = (np.arange(3, self.nv), np.arange(3, self.nv))
        self._pos_joints = np.array(c.position_joints if c.dual_pd else (0,))
        self._qps: dict[tuple[int, int], Any] = {}
        #: solves repeated with a fresh proxsuite object after the reused one failed (diagnostics)
        self.qp_rebuilds = 0
        self.q: np.ndarray | None = None
        self.v = np.zeros(self.nv)
        self.ground_y = 0.0

    # ------------------------------------------------------------------ state
    def reset(self, pose_local: torch.Tensor, trans: torch.Tensor, velocity: np.ndarray | None = None,
              ground_y: float | None = None) -> None:
        """Start at pose ``(24, 3, 3)`` local rotations and ``trans`` ``(3,)`` m, at rest.

        Args:
            velocity: optional initial generalised velocity ``(75,)`` (Pinocchio layout).
            ground_y: ground height (m); default ``config.ground_y``, and if that is None the
                lowest contact-candidate joint of this pose.
        """
        self.q = self.char.q_from_pose(pose_local, trans)
        self._qps = {}  # a fresh solver state per sequence: results do not depend on earlier sequences
        self.v = np.zeros(self.nv) if velocity is None else np.asarray(velocity, dtype=np.float64).copy()
        if ground_y is None:
            ground_y = self.config.ground_y
        if ground_y is None:
            pin.forwardKinematics(self.model, self.data, self.q)
            ground_y = float(self.joint_positions()[list(self.config.contact_candidates), 1].min())
        self.ground_y = float(ground_y)

    def joint_positions(self, q: np.ndarray | None = None) -> np.ndarray:
        """World joint positions ``(24, 3)`` m at ``q`` (default: the current state)."""
        pin.forwardKinematics(self.model, self.data, self.q if q is None else q)
        return np.array([self.data.oMi[k].translation for k in self._pin_ids])

    def _dynamics(self) -> _Dyn:
        m, d, q, v = self.model, self.data, self.q, self.v
        pin.computeJointJacobiansTimeVariation(m, d, q, v)  # also runs forward kinematics (pos, vel)
        pin.crba(m, d, q)
        M = np.triu(d.M) + np.triu(d.M, 1).T  # crba fills the upper triangle
        h = pin.nonLinearEffects(m, d, q, v).copy()
        pos = np.empty((NUM_JOINTS, 3))
        R = np.empty((NUM_JOINTS, 3, 3))
        J = np.empty((NUM_JOINTS, 6, self.nv))
        dJ = np.empty((NUM_JOINTS, 6, self.nv))
        for k, jid in enumerate(self._pin_ids):
            pos[k] = d.oMi[jid].translation
            R[k] = d.liMi[jid].rotation
            J[k] = pin.getJointJacobian(m, d, jid, _LWA)
            dJ[k] = pin.getJointJacobianTimeVariation(m, d, jid, _LWA)
        return _Dyn(M=M, R=R, h=h, pos=pos, J=J, dJv=(dJ[:, :3] @ v))

    # ------------------------------------------------------------------ contacts
    def contact_mask(self, heights: np.ndarray, contact_prob: np.ndarray) -> np.ndarray:
        """Joints in contact ``(24,)`` bool from joint heights above the ground ``(24,)`` m and
        the feet's contact probabilities ``(2,)`` (Sec. 3.2.3)."""
        c = self.config
        mask = np.zeros(NUM_JOINTS, dtype=bool)
        cand = np.array(c.contact_candidates)
        mask[cand] = heights[cand] < c.contact_height
        if c.foot_contact_requires_prob:
            mask[list(c.foot_joints)] = False
        for f, p in zip(c.foot_joints, contact_prob):
            if heights[f] < c.foot_contact_height and p > c.contact_prob_threshold:
                mask[f] = True
        return mask

    def _contact_offsets(self, pos: np.ndarray, cj: np.ndarray) -> np.ndarray:
        """World offsets ``(nj, 4, 3)`` of the 4 contact points of each contact joint from the joint."""
        return contact_offsets(pos, cj, self._square, self.config.foot_joints, self.config.foot_square_shift)

    def _solve_reused(self, H: np.ndarray, g: np.ndarray, C: np.ndarray, l: np.ndarray, u: np.ndarray) -> Any:
        """Solve ``min x'Hx/2 + g'x s.t. l <= Cx <= u`` with a proxsuite dense QP object kept per
        problem size (the size only changes with the number of contact joints, so a handful of
        objects serve a whole sequence): ``update`` reuses the workspace instead of allocating
        one per frame. Initial guess: the equality-constrained one (as ``dense.solve``); warm
        starting from the previous frame's result was tried and ended at inaccurate contact
        forces (up to 1 kN off) within the tolerance test, so it is not used."""
        key = (H.shape[0], C.shape[0])
        qp = self._qps.get(key)
        if qp is not None:
            qp.update(H, g, None, None, C, l, u)
            qp.solve()
            if qp.results.info.status == _SOLVED:
                return qp.results
            # A reused object keeps the proximal/penalty parameters its earlier solves adapted;
            # from those it occasionally declares a feasible problem primal infeasible (or runs out
            # of iterations) and returns an iterate that violates the contact rows -- a foot then
            # sinks through the ground (4.2 cm on a test running clip). A fresh object solves
            # these in ~15 iterations: rebuild it.
            self.qp_rebuilds += 1
        qp = proxsuite.proxqp.dense.QP(H.shape[0], 0, C.shape[0])
        qp.settings.eps_abs = self.config.eps_abs
        qp.settings.eps_rel = 0.0
        qp.settings.initial_guess = proxsuite.proxqp.InitialGuess.EQUALITY_CONSTRAINED_INITIAL_GUESS
        qp.init(H, g, None, None, C, l, u)
        qp.solve()
        self._qps[key] = qp
        return qp.results

    # ------------------------------------------------------------------ step
    def step(self, pose_target: torch.Tensor, joint_vel: torch.Tensor, contact_prob: torch.Tensor) -> PhysicsState:
        """One frame: reference pose ``(24, 3, 3)`` (local rotations), reference joint velocities
        ``(24, 3)`` m/s in the world frame (root = row 0), foot contact probabilities ``(2,)``
        (left, right) in [0, 1]. Returns the state after the update (see :class:`PhysicsState`)."""
        t_start, c_start = time.perf_counter(), time.thread_time()
        if self.q is None:
            raise ConfigError("PhysicsOptimizer.step: call reset(pose, trans) first")
        c, dt, nv = self.config, self.config.dt, self.nv
        v_ref = np.asarray(torch.as_tensor(joint_vel, dtype=torch.float64))
        probs = np.asarray(torch.as_tensor(contact_prob, dtype=torch.float64)).reshape(-1)
        if v_ref.shape != (NUM_JOINTS, 3):
            raise ShapeError(f"joint_vel: expected (24, 3) world joint velocities in m/s, got {v_ref.shape}")
        if probs.shape != (2,):
            raise ShapeError(f"contact_prob: expected (2,) left/right foot probabilities, got {probs.shape}")
        R_ref = np.asarray(torch.as_tensor(pose_target, dtype=torch.float64))
        if R_ref.shape != (NUM_JOINTS, 3, 3):
            raise ShapeError(f"pose_target: expected (24, 3, 3) local rotation matrices, got {R_ref.shape}")
        if c.foot_release_speed is not None:
            fast = np.linalg.norm(v_ref[list(c.foot_joints)], axis=1) > c.foot_release_speed
            probs = np.where(fast, 0.0, probs)
        dyn = self._dynamics()
        v = self.v

        # --- dual PD controller (Eq. 3-6)
        # log(R^T R_ref) per joint, in the joint's frame = Pinocchio's difference(q, q_ref) on the
        # rotational DoFs (tested), without building q_ref.
        rel = np.swapaxes(dyn.R, 1, 2) @ R_ref
        # Pinocchio's SO(3) log per joint: a tenth of the cost of a batched torch call at this size
        rot_err = np.concatenate([pin.log3(rel[j]) for j in self._dfs])
        qdd_rot_des = c.kp_theta * rot_err - c.kd_theta * v[3:]
        pj = self._pos_joints
        Jp = dyn.J[pj, :3].reshape(-1, nv)  # (3P, nv)
        r_dot = Jp @ v
        rdd_des = c.kp_r * (v_ref[pj].reshape(-1) * dt) - c.kd_r * r_dot  # r_ref - r = v_ref dt (Eq. 4)
        b_r = rdd_des - dyn.dJv[pj].reshape(-1)

        # --- contacts (Sec. 3.2.3)
        heights = dyn.pos[:, 1] - self.ground_y
        cmask = self.contact_mask(heights, probs)
        cj = np.flatnonzero(cmask)
        nj, npts = len(cj), 4 * len(cj)
        if nj:
            Jl, Ja = dyn.J[cj, :3], dyn.J[cj, 3:]  # (nj, 3, nv)
            offs = self._contact_offsets(dyn.pos, cj)  # (nj, 4, 3)
            # Point p = joint + o (o a world offset fixed to the joint's body): J_p = J_lin - [o]x J_ang.
            Jc = (Jl[:, None] - _skew(offs) @ Ja[:, None]).reshape(3 * npts, nv)
            d_c = np.maximum(np.repeat(heights[cj], 4), c.min_contact_weight)
        else:
            Jc = np.zeros((0, nv))
            d_c = np.zeros(0)

        # --- QP (Eq. 7-12); energy sum_k w_k |A_k x - b_k|^2 -> H = sum A^T W A, g = -sum A^T W b
        k_th, k_r = (c.k_theta ** 2, c.k_r ** 2) if c.weights_in_norm else (c.k_theta, c.k_r)
        H_qq = k_r * (Jp.T @ Jp)
        H_qq[self._rot_diag] += k_th
        g_q = -k_r * (Jp.T @ b_r)
        g_q[3:] -= k_th * qdd_rot_des
        lam_w = np.repeat(c.k_lambda * d_c, 3)
        if c.weights_in_norm:
            lam_w = lam_w ** 2
        # No sliding / no penetration per contact joint (Eq. 11-12): J_j (v + qdd dt) in C_j.
        Jj = dyn.J[cj, :3].reshape(-1, nv)
        vj = (Jj @ v).reshape(nj, 3)
        lo = np.empty((nj, 3))
        hi = np.empty((nj, 3))
        lo[:, [0, 2]], hi[:, [0, 2]] = -c.sigma, c.sigma
        lo[:, 1] = -heights[cj] / dt if c.ground_bound else 0.0
        hi[:, 1] = np.inf
        if c.contact_no_lift:  # planted feet only: other joints (knees, hands) leave the ground freely
            feet = np.isin(cj, c.foot_joints)
            hi[feet, 1] = np.maximum(c.sigma, -heights[cj[feet]] / dt)
        rows = [dt * Jj]
        lows, highs = [(lo - vj).reshape(-1)], [(hi - vj).reshape(-1)]
        if c.guard_all_candidates:
            # Other candidates: only "not below the ground after the step" (no force, no friction).
            free = np.array([j for j in c.contact_candidates if not cmask[j]], dtype=int)
            Jy = dyn.J[free, 1]
            rows.append(dt * Jy)
            vy = Jy @ v
            lows.append(-heights[free] / dt - vy)
            up = np.full(len(free), np.inf)
            if c.contact_no_lift:
                # a foot the network calls planted but that is still above the ground may come
                # down, not go up (PIP's released code bounds the feet this way whatever the height)
                for f, p in zip(c.foot_joints, probs):
                    if p > c.contact_prob_threshold and not cmask[f]:
                        up[free == f] = c.sigma
            highs.append(up - vy)
        Jk = np.vstack(rows)
        n_k = Jk.shape[0]
        n_l = 3 * npts
        n = nv + n_l if c.eliminate_torques else 2 * nv + n_l
        # Inequalities l <= C x <= u: friction pyramid on lambda (F lambda <= 0), kinematic rows on qdd.
        C = np.zeros((4 * npts + n_k, n))
        blocks = C[:4 * npts, nv:nv + n_l].reshape(npts, 4, npts, 3)  # a view: block-diagonal fill
        blocks[np.arange(npts), :, np.arange(npts), :] = self._fric
        C[4 * npts:, :nv] = Jk
        l = np.concatenate([np.full(4 * npts, -np.inf), *lows])
        u = np.concatenate([np.zeros(4 * npts), *highs])
        if c.eliminate_torques:
            # tau = M qdd + h - Jc^T lambda: A_tau = [M, -Jc^T], b_tau = -h.
            A_t = np.hstack([dyn.M, -Jc.T])
            H = A_t.T @ (self._w_tau[:, None] * A_t)
            H[:nv, :nv] += H_qq
            H[nv:, nv:] += np.diag(lam_w)
            g = A_t.T @ (self._w_tau * dyn.h)
            g[:nv] += g_q
            t_qp, c_qp = time.perf_counter(), time.thread_time()
            res = self._solve_reused(H, g, C, l, u)
            qp_ms, qp_cpu_ms = (time.perf_counter() - t_qp) * 1000.0, (time.thread_time() - c_qp) * 1000.0
            qdd, lam = res.x[:nv], res.x[nv:]
            tau = dyn.M @ qdd + dyn.h - Jc.T @ lam
        else:
            H = np.zeros((n, n))
            g = np.zeros(n)
            H[:nv, :nv] = H_qq
            g[:nv] = g_q
            H[nv:nv + n_l, nv:nv + n_l] = np.diag(lam_w)
            H[nv + n_l:, nv + n_l:] = np.diag(self._w_tau)
            A = np.hstack([dyn.M, -Jc.T, -np.eye(nv)])  # M qdd - Jc^T lambda - tau = -h
            t_qp, c_qp = time.perf_counter(), time.thread_time()
            res = proxsuite.proxqp.dense.solve(H, g, A, -dyn.h, C, l, u, eps_abs=c.eps_abs, eps_rel=0.0)
            qp_ms, qp_cpu_ms = (time.perf_counter() - t_qp) * 1000.0, (time.thread_time() - c_qp) * 1000.0
            qdd, lam, tau = res.x[:nv], res.x[nv:nv + n_l], res.x[nv + n_l:]

        if not np.all(np.isfinite(qdd)):  # solver breakdown: coast one frame rather than poison the state
            qdd, lam, tau = np.zeros(nv), np.zeros(n_l), dyn.h.copy()
        # --- state update (Eq. 13, semi-implicit)
        self.v = v + qdd * dt
        self.q = pin.integrate(self.model, self.q, self.v * dt)
        pos_new = self.joint_positions()
        cand = np.array(c.contact_candidates)
        depth = float(np.max(np.maximum(self.ground_y - pos_new[cand, 1], 0.0)))

        grf_j = np.zeros((NUM_JOINTS, 3))
        zmp = np.full(2, np.nan)
        pts = np.zeros((0, 3))
        if nj:
            pts = (dyn.pos[cj][:, None] + offs).reshape(-1, 3)
            lam_pts = lam.reshape(nj, 4, 3)
            grf_j[cj] = lam_pts.sum(1)
            fy = lam_pts[..., 1].reshape(-1)
            if fy.sum() > 1e-6:
                zmp = (fy[:, None] * pts[:, [0, 2]]).sum(0) / fy.sum()
        torques = tau[3:].reshape(NUM_JOINTS, 3)[self.char.pin_id - 1]  # root: residual torque
        # Local rotations straight from Pinocchio's joint transforms (joint placements carry no
        # rotation, so liMi's rotation is the joint's own); trans is q[:3].
        pose = torch.from_numpy(np.stack([self.data.liMi[j].rotation for j in self._pin_ids]).astype(np.float32))
        trans = torch.from_numpy(self.q[:3].astype(np.float32))
        f32 = lambda a: torch.from_numpy(np.ascontiguousarray(a, dtype=np.float32))  # noqa: E731
        return PhysicsState(
            pose_local=pose, trans=trans, joints=f32(pos_new), torques=f32(torques), residual=f32(tau[:6]),
            grf=f32(grf_j[list(c.foot_joints)]), grf_joints=f32(grf_j),
            contacts=torch.from_numpy(cmask[list(c.foot_joints)].copy()), contact_joints=torch.from_numpy(cmask),
            zmp=f32(zmp), penetration_m=depth, qp_ms=qp_ms, qp_cpu_ms=qp_cpu_ms, step_ms=(time.perf_counter() - t_start) * 1000.0,
            step_cpu_ms=(time.thread_time() - c_start) * 1000.0,
            qp_status=str(res.info.status).rsplit(".", 1)[-1],
            contact_points=f32(pts), contact_forces=f32(lam.reshape(-1, 3)),
        )

    # ------------------------------------------------------------------ offline
    def run(self, poses: torch.Tensor, joint_vel: torch.Tensor, contact: torch.Tensor,
            trans0: torch.Tensor) -> dict[str, torch.Tensor]:
        """Offline convenience: reset at ``poses[0]``/``trans0`` and step through every frame.

        Args:
            poses: ``(T, 24, 3, 3)`` reference local rotations.
            joint_vel: ``(T, 24, 3)`` reference world joint velocities, m/s.
            contact: ``(T, 2)`` foot contact probabilities.
            trans0: ``(3,)`` initial translation, m.

        Returns:
            dict of stacked tensors: ``pose_local (T, 24, 3, 3)``, ``trans (T, 3)``,
            ``joints (T, 24, 3)``, ``torques (T, 24, 3)``, ``residual (T, 6)``, ``grf (T, 2, 3)``,
            ``grf_joints (T, 24, 3)``, ``contacts (T, 2)``, ``zmp (T, 2)``, ``penetration_m (T,)``,
            ``qp_ms (T,)``, ``step_ms (T,)``, ``step_cpu_ms (T,)``, ``qp_cpu_ms (T,)``; plus ``ground_y`` (scalar tensor).
        """
        T = poses.shape[0]
        if joint_vel.shape[0] != T or contact.shape[0] != T:
            raise ShapeError(f"run: poses, joint_vel and contact need the same T, got {T}, "
                             f"{joint_vel.shape[0]}, {contact.shape[0]}")
        self.reset(poses[0], trans0)
        states = [self.step(poses[t], joint_vel[t], contact[t]) for t in range(T)]
        out: dict[str, torch.Tensor] = {}
        for k in ("pose_local", "trans", "joints", "torques", "residual", "grf", "grf_joints", "contacts", "zmp"):
            out[k] = torch.stack([getattr(s, k) for s in states])
        for k in ("penetration_m", "qp_ms", "qp_cpu_ms", "step_ms", "step_cpu_ms"):
            out[k] = torch.tensor([getattr(s, k) for s in states], dtype=torch.float32)
        out["ground_y"] = torch.tensor(self.ground_y)
        return out
