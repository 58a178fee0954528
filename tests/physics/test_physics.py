"""Physics module of PIP: character model, dynamics consistency, optimizer behaviour."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
import torch

from tests.conftest import make_tiny_asset
from wearpose.body import JOINT_INDEX, NUM_JOINTS, BodyModel
from wearpose.errors import ConfigError, ShapeError, WearposeError
from wearpose.geometry import axis_angle_to_matrix
from wearpose.physics import (
    DEFAULT_MASS_KG, SEGMENT_MASS_FRACTION, PhysicsCharacter, PhysicsConfig, PhysicsOptimizer,
)

G = 9.81
EYE = torch.eye(3).expand(NUM_JOINTS, 3, 3)


@pytest.fixture(scope="module")
def body() -> BodyModel:
    return BodyModel()


@pytest.fixture(scope="module")
def char(body) -> PhysicsCharacter:
    return PhysicsCharacter.from_body(body, torch.zeros(10))


def _random_pose(seed: int, scale: float = 0.4) -> torch.Tensor:
    g = torch.Generator().manual_seed(seed)
    return axis_angle_to_matrix(torch.randn(NUM_JOINTS, 3, generator=g, dtype=torch.float64) * scale)


def _state(char, seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    q = char.q_from_pose(_random_pose(seed), torch.tensor([0.1, 0.2, -0.3]))
    return q, rng.normal(size=char.nv)


# ---------------------------------------------------------------------------- character
def test_mass_distribution_is_sane(char):
    assert char.mass_source == "mesh"
    assert 50.0 < char.mass_kg < 90.0  # 1.69 m adult: density x mesh volume
    assert np.isclose(char.segment_mass.sum(), char.mass_kg)
    assert np.isclose(sum(SEGMENT_MASS_FRACTION.values()), 1.0)
    data = char.model.createData()
    q = char.q_from_pose(EYE, torch.zeros(3))
    assert np.isclose(pin.computeTotalMass(char.model), char.mass_kg)
    com = char.center_of_mass(q)
    rest = char.rest_joints
    # Upright T-pose: COM on the mid-sagittal plane, between the knees and the neck, near the pelvis.
    assert abs(com[0]) < 0.01
    assert rest[JOINT_INDEX["left_knee"], 1] < com[1] < rest[JOINT_INDEX["neck"], 1]
    assert abs(com[1] - rest[0, 1]) < 0.15
    # Thigh heavier than shank heavier than foot (de Leva ordering).
    m = char.segment_mass
    assert m[JOINT_INDEX["left_hip"]] > m[JOINT_INDEX["left_knee"]] > m[JOINT_INDEX["left_ankle"]]
    pin.crba(char.model, data, q)


def test_mass_override_and_fallback(body):
    heavy = PhysicsCharacter.from_body(body, torch.zeros(10), mass_kg=90.0)
    assert heavy.mass_source == "given" and np.isclose(heavy.segment_mass.sum(), 90.0)
    tiny = PhysicsCharacter.from_body(BodyModel(make_tiny_asset()))  # tetrahedra: no usable volume
    assert tiny.mass_source == "default" and np.isclose(tiny.mass_kg, DEFAULT_MASS_KG)
    big = torch.zeros(10)
    big[0] = 2.0
    assert PhysicsCharacter.from_body(body, big).mass_kg > PhysicsCharacter.from_body(body, -big).mass_kg
    with pytest.raises(ShapeError):
        PhysicsCharacter.from_body(body, torch.zeros(3))
    with pytest.raises(WearposeError):
        PhysicsCharacter.from_body(body, torch.zeros(10), mass_kg=-1.0)


def test_configuration_matches_body_forward_kinematics(body, char):
    pose = _random_pose(3).float()
    trans = torch.tensor([0.3, -0.1, 0.7])
    q = char.q_from_pose(pose, trans)
    opt = PhysicsOptimizer(char)
    ours = opt.joint_positions(q)
    ref = body(pose, torch.zeros(10), trans, return_vertices=False).joints.numpy()
    np.testing.assert_allclose(ours, ref, atol=1e-5)
    back, t = char.pose_from_q(q)
    np.testing.assert_allclose(back.numpy(), pose.numpy(), atol=1e-5)
    np.testing.assert_allclose(t.numpy(), trans.numpy(), atol=1e-6)


# ---------------------------------------------------------------------------- dynamics
def test_mass_matrix_symmetric_positive_definite_and_rnea_consistent(char):
    opt = PhysicsOptimizer(char)
    for seed in range(3):
        q, v = _state(char, seed)
        opt.q, opt.v = q, v
        dyn = opt._dynamics()
        np.testing.assert_allclose(dyn.M, dyn.M.T, atol=1e-12)
        assert np.linalg.eigvalsh(dyn.M).min() > 0
        a = np.random.default_rng(seed + 10).normal(size=char.nv)
        tau = pin.rnea(char.model, char.model.createData(), q, v, a)
        np.testing.assert_allclose(dyn.M @ a + dyn.h, tau, rtol=1e-9, atol=1e-9)


def test_jacobians_and_time_variation_match_finite_differences(char):
    opt = PhysicsOptimizer(char)
    q, v = _state(char, 5)
    opt.q, opt.v = q, v
    dyn = opt._dynamics()
    eps = 1e-6
    # J v = joint linear velocity: finite difference of joint positions along v.
    p1 = opt.joint_positions(pin.integrate(char.model, q, v * eps))
    p0 = opt.joint_positions(q)
    np.testing.assert_allclose((p1 - p0) / eps, dyn.J[:, :3] @ v, rtol=1e-4, atol=1e-4)
    # dJ v = classical acceleration of the joint origin at zero joint acceleration.
    data = char.model.createData()
    pin.forwardKinematics(char.model, data, q, v, np.zeros(char.nv))
    for k in (1, 10, 22):
        acc = pin.getClassicalAcceleration(char.model, data, int(char.pin_id[k]), pin.ReferenceFrame.LOCAL_WORLD_ALIGNED).linear
        np.testing.assert_allclose(dyn.dJv[k], acc, rtol=1e-8, atol=1e-8)


# ---------------------------------------------------------------------------- optimizer
def _stand(char, steps: int, **kw):
    opt = PhysicsOptimizer(char, PhysicsConfig(**kw))
    opt.reset(EYE, torch.zeros(3))
    states = [opt.step(EYE, torch.zeros(NUM_JOINTS, 3), torch.ones(2)) for _ in range(steps)]
    return opt, states


def test_static_standing_carries_body_weight_without_drift(char):
    opt, states = _stand(char, 120)  # 2 s at 60 fps
    fy = np.array([s.grf[:, 1].sum().item() for s in states])
    mg = char.mass_kg * G
    assert np.all(np.abs(fy[10:] / mg - 1.0) < 0.03), (fy.min() / mg, fy.max() / mg)
    assert all(bool(s.contacts.all()) for s in states)
    assert np.linalg.norm(states[-1].trans.numpy()) < 0.01  # < 1 cm drift over 2 s
    assert max(s.penetration_m for s in states) < 1e-3
    assert all(s.qp_status == "PROXQP_SOLVED" for s in states)
    # Two feet share the load (symmetric pose): neither carries less than 40 %.
    share = states[-1].grf[0, 1].item() / fy[-1]
    assert 0.4 < share < 0.6
    # ZMP/CoP inside the feet's support area.
    feet = states[-1].joints[[JOINT_INDEX["left_foot"], JOINT_INDEX["right_foot"]]].numpy()
    zmp = states[-1].zmp.numpy()
    assert feet[1, 0] - 0.1 < zmp[0] < feet[0, 0] + 0.1


def test_eliminated_and_full_qp_agree(char):
    _, a = _stand(char, 5)
    _, b = _stand(char, 5, eliminate_torques=False)
    for sa, sb in zip(a, b):
        np.testing.assert_allclose(sa.grf.numpy(), sb.grf.numpy(), atol=0.5)  # N, of ~670 N
        np.testing.assert_allclose(sa.torques.numpy(), sb.torques.numpy(), atol=0.5)
        np.testing.assert_allclose(sa.trans.numpy(), sb.trans.numpy(), atol=1e-5)


def test_friction_cone_respected_under_horizontal_demand(char):
    """Reference velocities ask every joint to move sideways at 3 m/s while both feet are held:
    the friction pyramid must bound every point force, and bind somewhere. (The feet's reference
    velocity is 3 m/s too: ``foot_release_speed`` off, or it would release them.)"""
    cfg = PhysicsConfig(foot_release_speed=None)
    opt = PhysicsOptimizer(char, cfg)
    opt.reset(EYE, torch.zeros(3))
    vel = torch.zeros(NUM_JOINTS, 3)
    vel[:, 0] = 3.0
    ratios = []
    for _ in range(5):
        st = opt.step(EYE, vel, torch.ones(2))
        f = st.contact_forces.numpy().astype(np.float64)
        if not len(f):
            continue
        assert np.all(f[:, 1] >= -1e-3)
        assert np.all(np.abs(f[:, 0]) <= cfg.mu * f[:, 1] + 1e-2)
        assert np.all(np.abs(f[:, 2]) <= cfg.mu * f[:, 1] + 1e-2)
        ratios.append(np.abs(f[:, 0]).sum() / max(f[:, 1].sum(), 1e-9))
    assert ratios and max(ratios) > 0.9 * cfg.mu  # the demand really pushes on the cone (it binds)


def test_dual_pd_tracks_joint_velocities_single_pd_does_not(char):
    """A hand velocity in the reference (static pose target): the joint position controller of the
    dual PD moves the hand, the single PD (root position only) ignores it."""
    hand = JOINT_INDEX["left_hand"]
    moved = {}
    for dual in (True, False):
        opt = PhysicsOptimizer(char, PhysicsConfig(dual_pd=dual, ground_y=-10.0))  # airborne: no contacts
        opt.reset(EYE, torch.zeros(3))
        p0 = opt.joint_positions()[hand] - opt.q[:3]
        vel = torch.zeros(NUM_JOINTS, 3)
        vel[hand, 1] = 1.0
        for _ in range(10):
            st = opt.step(EYE, vel, torch.zeros(2))
        moved[dual] = float((st.joints[hand].numpy() - st.trans.numpy() - p0)[1])
        assert not st.contacts.any()
    assert moved[True] > 0.01
    assert abs(moved[False]) < 0.2 * moved[True]


def test_contact_rules():
    char_cfg = PhysicsConfig()
    opt = PhysicsOptimizer.__new__(PhysicsOptimizer)
    opt.config = char_cfg
    lf, rf = char_cfg.foot_joints
    h = np.full(NUM_JOINTS, 0.5)
    h[lf], h[rf] = 0.02, 0.02
    m = opt.contact_mask(h, np.array([0.9, 0.2]))
    assert m[lf] and not m[rf]
    h[lf] = 0.04  # above 3 cm: no contact whatever the probability
    assert not opt.contact_mask(h, np.array([1.0, 0.0]))[lf]
    h[JOINT_INDEX["left_knee"]] = 0.001  # kneeling: any candidate below 0.5 cm
    assert opt.contact_mask(h, np.zeros(2))[JOINT_INDEX["left_knee"]]
    h[rf] = 0.001  # a foot on the ground with low probability: free by default, in contact literally
    assert not opt.contact_mask(h, np.zeros(2))[rf]
    opt.config = PhysicsConfig(foot_contact_requires_prob=False)
    assert opt.contact_mask(h, np.zeros(2))[rf]


def test_run_shapes_and_errors(char):
    opt = PhysicsOptimizer(char)
    with pytest.raises(ConfigError):
        opt.step(EYE, torch.zeros(NUM_JOINTS, 3), torch.ones(2))
    T = 4
    out = opt.run(EYE.expand(T, -1, -1, -1), torch.zeros(T, NUM_JOINTS, 3), torch.ones(T, 2), torch.zeros(3))
    assert out["pose_local"].shape == (T, NUM_JOINTS, 3, 3) and out["pose_local"].dtype == torch.float32
    assert out["trans"].shape == (T, 3) and out["grf"].shape == (T, 2, 3) and out["torques"].shape == (T, NUM_JOINTS, 3)
    assert out["contacts"].dtype == torch.bool and out["qp_ms"].shape == (T,)
    with pytest.raises(ShapeError):
        opt.step(EYE, torch.zeros(NUM_JOINTS, 2), torch.ones(2))
    with pytest.raises(ShapeError):
        opt.step(EYE, torch.zeros(NUM_JOINTS, 3), torch.ones(3))
    with pytest.raises(ShapeError):
        opt.reset(EYE[:5], torch.zeros(3))
    with pytest.raises(ConfigError):
        PhysicsConfig(fps=0)
    with pytest.raises(ConfigError):
        PhysicsConfig(contact_candidates=(0, 1))


def test_rotation_error_and_pose_output_match_pinocchio(char):
    """The step's rotation error log(R^T R_ref) equals Pinocchio's difference(q, q_ref) on the
    rotational DoFs, and the returned pose is the integrated configuration."""
    opt = PhysicsOptimizer(char, PhysicsConfig(ground_y=-10.0))
    opt.reset(_random_pose(7).float(), torch.tensor([0.0, 0.1, 0.0]))
    target = _random_pose(8).float()
    dyn = opt._dynamics()
    rel = np.swapaxes(dyn.R, 1, 2) @ target.double().numpy()
    ours = axis_angle(rel)[opt._dfs].reshape(-1)
    ref = pin.difference(char.model, opt.q, char.q_from_pose(target, opt.q[:3]))[3:]
    np.testing.assert_allclose(ours, ref, atol=1e-5)
    st = opt.step(target, torch.zeros(NUM_JOINTS, 3), torch.zeros(2))
    pose, trans = char.pose_from_q(opt.q)
    np.testing.assert_allclose(st.pose_local.numpy(), pose.numpy(), atol=1e-5)
    np.testing.assert_allclose(st.trans.numpy(), trans.numpy(), atol=1e-6)


def axis_angle(R: np.ndarray) -> np.ndarray:
    from wearpose.geometry import matrix_to_axis_angle
    return matrix_to_axis_angle(torch.from_numpy(R)).numpy()


def test_planted_foot_does_not_lift_and_released_foot_may(char):
    """A foot in contact that the network calls planted may not rise faster than sigma; with a
    low probability it leaves contact and may; without ``contact_no_lift`` the planted one may too."""
    lf = JOINT_INDEX["left_foot"]
    vel = torch.zeros(NUM_JOINTS, 3)
    vel[[lf, JOINT_INDEX["left_ankle"], JOINT_INDEX["left_knee"]], 1] = 1.0  # lift the left leg at 1 m/s
    rise = {}
    for p in (1.0, 0.0, None):
        opt = PhysicsOptimizer(char, PhysicsConfig(contact_no_lift=p is not None, foot_release_speed=None))
        p = 1.0 if p is None else p
        opt.reset(EYE, torch.zeros(3))
        y0 = opt.joint_positions()[lf, 1]
        for _ in range(6):
            st = opt.step(EYE, vel, torch.tensor([p, 1.0]))
        rise[(p, opt.config.contact_no_lift)] = float(st.joints[lf, 1]) - y0
    dt = 1 / 60
    assert rise[(1.0, True)] <= 6 * PhysicsConfig().sigma * dt + 1e-6
    assert rise[(0.0, True)] > 5 * rise[(1.0, True)] and rise[(0.0, True)] > 5e-3
    assert rise[(1.0, False)] > 5 * rise[(1.0, True)]


def test_foot_release_speed_frees_a_fast_planted_foot(char):
    """A foot called planted (p = 1) whose reference velocity is above ``foot_release_speed`` is
    released (may rise as with p = 0); below the speed, or with the rule off, it stays planted."""
    lf = JOINT_INDEX["left_foot"]
    vel = torch.zeros(NUM_JOINTS, 3)
    vel[[lf, JOINT_INDEX["left_ankle"], JOINT_INDEX["left_knee"]], 1] = 1.0  # lift the left leg at 1 m/s
    rise = {}
    for release in (None, 0.5, 2.0):
        opt = PhysicsOptimizer(char, PhysicsConfig(foot_release_speed=release))
        opt.reset(EYE, torch.zeros(3))
        y0 = opt.joint_positions()[lf, 1]
        for _ in range(6):
            st = opt.step(EYE, vel, torch.tensor([1.0, 1.0]))
        rise[release] = float(st.joints[lf, 1]) - y0
    bound = 6 * PhysicsConfig().sigma / 60 + 1e-6
    assert rise[None] <= bound and rise[2.0] <= bound  # 1 m/s is below 2 m/s: still planted
    assert rise[0.5] > 5e-3
    assert PhysicsConfig().foot_release_speed == 0.48  # the contact labels' speed threshold
    with pytest.raises(ConfigError, match="foot_release_speed"):
        PhysicsConfig(foot_release_speed=0.0)


def test_reused_qp_matches_a_fresh_solve(char):
    import proxsuite

    opt = PhysicsOptimizer(char)
    rng = np.random.default_rng(0)
    for _ in range(3):  # same size: the object is reused
        M = rng.normal(size=(6, 6))
        H, g = M @ M.T + np.eye(6), rng.normal(size=6)
        C, l, u = rng.normal(size=(4, 6)), np.full(4, -np.inf), rng.uniform(0, 1, 4)
        x = opt._solve_reused(H, g, C, l, u).x
        ref = proxsuite.proxqp.dense.solve(H, g, None, None, C, l, u, eps_abs=1e-9, eps_rel=0.0).x
        np.testing.assert_allclose(x, ref, atol=1e-4)
    assert len(opt._qps) == 1


def test_failed_reused_qp_is_solved_again_fresh(char):
    # a reused proxsuite object that stops early (here: 1 iteration allowed) must not hand back
    # its iterate: the frame is solved again with a fresh object
    opt = PhysicsOptimizer(char, PhysicsConfig())
    opt.reset(EYE, torch.zeros(3))
    opt.step(EYE, torch.zeros(NUM_JOINTS, 3), torch.ones(2))
    assert opt.qp_rebuilds == 0 and len(opt._qps) == 1
    (qp,) = opt._qps.values()
    qp.settings.max_iter = 1
    st = opt.step(EYE, torch.zeros(NUM_JOINTS, 3), torch.ones(2))
    assert opt.qp_rebuilds == 1
    assert st.qp_status == "PROXQP_SOLVED"
    assert next(iter(opt._qps.values())) is not qp
    # standing: the fresh solve carries the body weight on the feet
    assert abs(float(st.grf[:, 1].sum()) / (char.mass_kg * G) - 1.0) < 0.05
