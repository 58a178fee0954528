"""BodyModel: LBS correctness, batching, differentiability and the site fast path (tiny asset)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from tests.conftest import make_tiny_asset
from wearpose.body import JOINT_NAMES, BodyModel, forward_kinematics
from wearpose.errors import ShapeError, WearposeError
from wearpose.geometry import axis_angle_to_matrix


@pytest.fixture
def body() -> BodyModel:
    return BodyModel(make_tiny_asset(), dtype=torch.float64)


def test_zero_pose_is_template(body: BodyModel) -> None:
    out = body()
    np.testing.assert_allclose(out.vertices.numpy(), body.v_template.numpy(), atol=1e-12)
    np.testing.assert_allclose(out.joints.numpy(), (body.J_regressor @ body.v_template).numpy(), atol=1e-12)
    np.testing.assert_allclose(out.global_rot.numpy(), np.broadcast_to(np.eye(3), (24, 3, 3)), atol=1e-12)


def test_joints_are_regressed_from_shaped_mesh(body: BodyModel) -> None:
    betas = torch.randn(3, 10, dtype=torch.float64)
    out = body(betas=betas)
    v_shaped = body.v_template + torch.einsum("vcs,bs->bvc", body.shapedirs, betas)
    np.testing.assert_allclose(out.rest_joints.numpy(), (body.J_regressor @ v_shaped).numpy(), atol=1e-12)


def test_root_rotation_and_translation_are_rigid(body: BodyModel) -> None:
    R0 = axis_angle_to_matrix(torch.tensor([0.3, -1.2, 0.5], dtype=torch.float64))
    pose = torch.eye(3, dtype=torch.float64).repeat(24, 1, 1)
    pose[0] = R0
    t = torch.tensor([1.0, 2.0, -3.0], dtype=torch.float64)
    out = body(pose, trans=t, return_normals=True)
    rest = body(return_normals=True)
    pelvis = rest.joints[0]
    expect = (rest.vertices - pelvis) @ R0.T + pelvis + t
    np.testing.assert_allclose(out.vertices.numpy(), expect.numpy(), atol=1e-10)
    np.testing.assert_allclose(out.normals.numpy(), (rest.normals @ R0.T).numpy(), atol=1e-10)


def test_lbs_matches_per_vertex_reference(body: BodyModel) -> None:
    """Vertex = sum_j w_vj (G_j (v - J_j) + P_j), computed naively here."""
    aa = torch.randn(24, 3, dtype=torch.float64) * 0.5
    R = axis_angle_to_matrix(aa)
    out = body(R)
    G, P = forward_kinematics(R, body.rest_joints())
    J = body.rest_joints()
    v = body.v_template
    ref = torch.zeros_like(v)
    for j in range(24):
        ref += body.weights[:, j:j + 1] * ((v - J[j]) @ G[j].T + P[j])
    np.testing.assert_allclose(out.vertices.numpy(), ref.numpy(), atol=1e-12)


def test_axis_angle_input_equals_matrix_input(body: BodyModel) -> None:
    aa = torch.randn(5, 72, dtype=torch.float64) * 0.4
    a = body(aa)
    b = body(axis_angle_to_matrix(aa.view(5, 24, 3)))
    np.testing.assert_allclose(a.vertices.numpy(), b.vertices.numpy(), atol=1e-12)


def test_any_batch_shape_and_broadcast(body: BodyModel) -> None:
    pose = axis_angle_to_matrix(torch.randn(2, 3, 24, 3, dtype=torch.float64) * 0.3)
    betas = torch.randn(10, dtype=torch.float64)
    trans = torch.randn(2, 1, 3, dtype=torch.float64)
    out = body(pose, betas, trans)
    assert out.vertices.shape == (2, 3, body.num_vertices, 3)
    assert out.joints.shape == (2, 3, 24, 3) and out.global_rot.shape == (2, 3, 24, 3, 3)
    one = body(pose[1, 2], betas, trans[1, 0])
    np.testing.assert_allclose(out.vertices[1, 2].numpy(), one.vertices.numpy(), atol=1e-12)
    nov = body(pose, betas, trans, return_vertices=False)
    assert nov.vertices is None
    np.testing.assert_allclose(nov.joints.numpy(), out.joints.numpy(), atol=1e-12)


def test_posedirs_apply_pose_correctives() -> None:
    asset = make_tiny_asset(posedirs=True)
    body = BodyModel(asset, dtype=torch.float64)
    R = axis_angle_to_matrix(torch.randn(24, 3, dtype=torch.float64) * 0.3)
    out = body(R)
    no_pd = BodyModel(make_tiny_asset(posedirs=False), dtype=torch.float64)(R)
    assert (out.vertices - no_pd.vertices).abs().max() > 1e-4
    zero = body()
    np.testing.assert_allclose(zero.vertices.numpy(), body.v_template.numpy(), atol=1e-12)


@pytest.mark.budget(30)  # finite differences through the full mesh: 15 s measured
def test_gradcheck_float64(body: BodyModel) -> None:
    aa = (torch.randn(2, 72, dtype=torch.float64) * 0.3).requires_grad_()
    betas = torch.randn(2, 10, dtype=torch.float64, requires_grad=True)
    trans = torch.randn(2, 3, dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(lambda a, b, t: body(a, b, t).vertices, (aa, betas, trans))
    assert torch.autograd.gradcheck(lambda a, b, t: body.sites(a, b, t).rotations, (aa, betas, trans))


def test_site_fast_path_matches_full_mesh(body: BodyModel) -> None:
    pose = axis_angle_to_matrix(torch.randn(4, 24, 3, dtype=torch.float64) * 0.5)
    betas = torch.randn(4, 10, dtype=torch.float64)
    full = body(pose, betas, return_normals=True)
    s = body.sites(pose, betas)
    names, vids, tids = body.site_ids()
    np.testing.assert_allclose(s.positions.numpy(), full.vertices[:, vids].numpy(), atol=1e-12)
    np.testing.assert_allclose(s.rotations[..., 2].numpy(), full.normals[:, vids].numpy(), atol=1e-12)
    R = s.rotations
    np.testing.assert_allclose((R.transpose(-1, -2) @ R).numpy(), np.broadcast_to(np.eye(3), R.shape), atol=1e-12)
    np.testing.assert_allclose(torch.det(R).numpy(), 1.0, atol=1e-12)
    # tangent lies along the projected edge to the fixed neighbour vertex
    e = full.vertices[:, tids] - full.vertices[:, vids]
    assert torch.all((e * s.rotations[..., 0]).sum(-1) > 0)
    # arbitrary vertices work too
    s2 = body.sites(pose, betas, vertex_ids=[3, 17])
    np.testing.assert_allclose(s2.positions.numpy(), full.vertices[:, [3, 17]].numpy(), atol=1e-12)


def _reference_normals(verts: torch.Tensor, faces: torch.Tensor) -> torch.Tensor:
    """Area-weighted vertex normals the plain way (the previous implementation)."""
    v0, v1, v2 = verts[:, faces[:, 0]], verts[:, faces[:, 1]], verts[:, faces[:, 2]]
    fn = torch.cross(v1 - v0, v2 - v0, dim=-1)
    n = torch.zeros_like(verts)
    for k in range(3):
        n = n.index_add(1, faces[:, k], fn)
    return n / n.norm(dim=-1, keepdim=True)


def test_chunked_component_major_skinning_equals_reference(monkeypatch: pytest.MonkeyPatch) -> None:
    """More frames than one skinning chunk and one pose-corrective block, pose correctives on:
    vertices equal the per-vertex LBS sum, normals the plain area-weighted normals, joints the
    joints-only path, sites the mesh."""
    import wearpose.body.model as model

    body = BodyModel(make_tiny_asset(posedirs=True), dtype=torch.float64)
    monkeypatch.setattr(model, "SKIN_CHUNK_VERTEX_FRAMES", 3 * body.num_vertices)  # chunks of 3 frames
    monkeypatch.setattr(model, "POSE_BLOCK_FRAMES", 6)  # pose correctives 6 frames (2 chunks) per product
    N = 11
    g = torch.Generator().manual_seed(1)
    R = axis_angle_to_matrix(torch.randn(N, 24, 3, generator=g, dtype=torch.float64) * 0.5)
    betas = torch.randn(N, 10, generator=g, dtype=torch.float64)
    trans = torch.randn(N, 3, generator=g, dtype=torch.float64)
    out = body(R, betas, trans, return_normals=True)
    assert body(R, betas, trans).normals is None  # normals only when asked for
    J_rest = body.rest_joints(betas)
    G, P = forward_kinematics(R, J_rest)
    feat = (R[:, 1:] - torch.eye(3, dtype=torch.float64)).reshape(N, -1)
    v = (body.v_template + torch.einsum("vcs,ns->nvc", body.shapedirs, betas)
         + (feat @ body.posedirs).view(N, -1, 3))
    ref = torch.zeros_like(v)
    for j in range(24):
        ref += body.weights[:, j:j + 1] * ((v - J_rest[:, j:j + 1]) @ G[:, j].transpose(-1, -2) + P[:, j:j + 1])
    ref = ref + trans[:, None]
    np.testing.assert_allclose(out.vertices.numpy(), ref.numpy(), atol=1e-12)
    np.testing.assert_allclose(out.normals.numpy(), _reference_normals(ref, body.faces).numpy(), atol=1e-12)
    np.testing.assert_allclose(out.joints.numpy(), body(R, betas, trans, return_vertices=False).joints.numpy(), atol=1e-12)
    s = body.sites(R, betas, trans)
    _, vids, _ = body.site_ids()
    np.testing.assert_allclose(s.positions.numpy(), ref[:, vids].numpy(), atol=1e-12)
    np.testing.assert_allclose(s.rotations[..., 2].numpy(), out.normals[:, vids].numpy(), atol=1e-12)


def test_level_fk_equals_joint_loop() -> None:
    """The level-by-level FK (small batches) computes the same products as the per-joint loop;
    a tree whose depths are not contiguous runs of ids takes the loop."""
    from wearpose.body.kinematics import _fk_loop, _level_plan
    from wearpose.body.skeleton import PARENTS

    g = torch.Generator().manual_seed(2)
    for dtype in (torch.float32, torch.float64):
        for B in (1, 5, 64):
            R = axis_angle_to_matrix(torch.randn(B, 24, 3, generator=g, dtype=dtype))
            rest = torch.randn(24, 3, generator=g, dtype=dtype)
            G, P = forward_kinematics(R, rest)  # no autograd: the in-place joint-major levels
            G0, P0 = _fk_loop(R, rest.expand(B, 24, 3), PARENTS)
            assert torch.equal(G, G0) and torch.equal(P, P0), (dtype, B)
            Gg, Pg = forward_kinematics(R.clone().requires_grad_(), rest)  # autograd: the levels concatenated
            assert Gg.requires_grad and torch.equal(Gg, G0) and torch.equal(Pg, P0), (dtype, B)
    assert _level_plan(PARENTS) is not None and len(_level_plan(PARENTS)) == 8
    chain_then_branch = (-1, 0, 1, 0)  # depths 0 1 2 1: not sorted
    assert _level_plan(chain_then_branch) is None
    R = axis_angle_to_matrix(torch.randn(4, 3, generator=g, dtype=torch.float64))
    G, P = forward_kinematics(R, torch.randn(4, 3, dtype=torch.float64), chain_then_branch)
    np.testing.assert_allclose(G[2].numpy(), (R[0] @ R[1] @ R[2]).numpy(), atol=1e-12)


def test_site_setup_follows_buffer_changes(body: BodyModel) -> None:
    """The sites' patch set-up is cached; writing the buffers (load_state_dict) refreshes it."""
    pose = axis_angle_to_matrix(torch.randn(2, 24, 3, dtype=torch.float64) * 0.3)
    _, vids, _ = body.site_ids()
    a = body.sites(pose).positions
    state = {k: v.clone() for k, v in body.state_dict().items()}
    state["v_template"] += 0.05
    body.load_state_dict(state)
    b = body.sites(pose).positions
    assert float((b - a).abs().max()) > 0.01
    np.testing.assert_allclose(b.numpy(), body(pose).vertices[:, vids].numpy(), atol=1e-12)


def test_errors_are_clear(body: BodyModel) -> None:
    with pytest.raises(ShapeError, match=r"\(\.\.\., 24, 3, 3\)"):
        body(torch.zeros(2, 23, 3, 3))
    with pytest.raises(ShapeError, match="betas"):
        body(betas=torch.zeros(2, 7))
    with pytest.raises(WearposeError, match="unknown sensor site"):
        body.sites(names=["nose"])
    with pytest.raises(ShapeError, match="broadcast"):
        body(torch.zeros(2, 72), torch.zeros(3, 10))


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_lowest_height_matches_the_skinned_mesh(dtype) -> None:
    """Rigid parts on their hulls: exact where a vertex follows one joint (the tiny asset's
    tetrahedra do, up to their blend with the parent), about 1 cm on the real mesh."""
    g = torch.Generator().manual_seed(3)
    R = axis_angle_to_matrix(torch.randn(40, 24, 3, generator=g, dtype=torch.float64) * 0.6).to(dtype)
    trans = torch.randn(40, 3, generator=g, dtype=torch.float64).to(dtype)
    betas = torch.randn(10, generator=g, dtype=torch.float64).to(dtype)
    for body, tol in ((BodyModel(make_tiny_asset(), dtype=dtype), 0.03), (BodyModel(dtype=dtype), 0.03)):
        full = body(R, betas, trans, return_normals=False).vertices[..., 1].amin(-1)
        low = body.lowest_height(R, betas, trans, chunk=16)
        assert low.shape == (40,) and low.dtype == dtype
        assert float((low - full).abs().max()) < tol and float((low - full).abs().mean()) < 0.005
    assert len(body._support_vertices()) < body.num_vertices / 3  # only the hull vertices are read


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_lowest_point_names_the_joint_that_carries_it(dtype) -> None:
    """The lowest point's joint is the dominant joint of the skinned mesh's lowest vertex where
    the two agree on the vertex (standing: a foot; lying on the back: the torso), and the joints
    are the posed joints plus the translation."""
    body = BodyModel(dtype=dtype)
    R = torch.eye(3, dtype=dtype).expand(2, 24, 3, 3).clone()
    R[1, 0] = axis_angle_to_matrix(torch.tensor([-torch.pi / 2, 0.0, 0.0], dtype=torch.float64)).to(dtype)  # on the back
    trans = torch.tensor([[0.0, 1.0, 0.0], [0.3, 0.2, -1.0]], dtype=dtype)
    out = body.lowest_point(R, None, trans)
    full = body(R, None, trans, return_normals=False)
    assert out.height.shape == (2,) and out.joint.dtype == torch.long and out.joints.dtype == dtype
    torch.testing.assert_close(out.joints, full.joints)
    torch.testing.assert_close(out.height, body.lowest_height(R, None, trans))
    names = [JOINT_NAMES[int(j)] for j in out.joint]
    assert names[0] in {"left_foot", "right_foot", "left_ankle", "right_ankle"}, names
    assert names[1] in {"pelvis", "spine1", "spine2", "spine3", "head", "left_collar", "right_collar",
                        "left_shoulder", "right_shoulder", "neck"}, names


def test_normals_with_autograd() -> None:
    """The face cross product is the same arithmetic with and without autograd (bit-equal), and
    normals through the sparse face operators have correct gradients."""
    from wearpose.body.model import _cross_dim1

    g = torch.Generator().manual_seed(4)
    a, b = torch.randn(50, 3, 4, generator=g), torch.randn(50, 3, 4, generator=g)
    with torch.no_grad():
        plain = _cross_dim1(a, b)
    tracked = _cross_dim1(a.clone().requires_grad_(), b)
    assert tracked.requires_grad and torch.equal(plain, tracked.detach())
    np.testing.assert_allclose(plain.numpy(), torch.linalg.cross(a, b, dim=1).numpy(), atol=1e-6)
    body = BodyModel(make_tiny_asset(), dtype=torch.float64)
    aa = (torch.randn(2, 72, generator=g, dtype=torch.float64) * 0.3).requires_grad_()
    assert torch.autograd.gradcheck(lambda x: body(x, return_normals=True).normals, (aa,))


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_sites_without_autograd_equal_sites_with_it(dtype: torch.dtype) -> None:
    """Without autograd the site patch is skinned vertex-major and forward kinematics goes in
    place (:func:`wearpose.body.kinematics._fk_levels_nograd`); with it, component-major and
    concatenated. The same arithmetic: bit-equal positions, frames, joints and rotations, at
    B = 1 and at a batch of the level path, on the embedded asset (real faces and sites)."""
    body = BodyModel(dtype=dtype)
    g = torch.Generator().manual_seed(5)
    for B in (1, 7):
        R = axis_angle_to_matrix(torch.randn(B, 24, 3, generator=g, dtype=dtype) * 0.5)
        betas, trans = torch.randn(B, 10, generator=g, dtype=dtype), torch.randn(B, 3, generator=g, dtype=dtype)
        with torch.no_grad():
            plain = body.sites(R, betas, trans)
        tracked = body.sites(R.clone().requires_grad_(), betas.clone().requires_grad_(), trans)
        assert tracked.rotations.requires_grad
        for k in ("positions", "rotations", "joints", "global_rot"):
            assert torch.equal(getattr(plain, k), getattr(tracked, k).detach()), (B, k)
        # the skinning's rest joints (one bmm) are rest_joints' (einsum) bit for bit
        assert torch.equal(body._skin_prefix(R, betas, trans, False)[0], body.rest_joints(betas))


def test_site_patch_follows_a_copy_with_other_site_vertices(body: BodyModel) -> None:
    """The patch cache is keyed by the names and the site table: a shallow copy sharing the cache
    with a site moved (as motion.augment.jitter_sites makes) gets its own patch, the original keeps its."""
    import copy

    pose = axis_angle_to_matrix(torch.randn(2, 24, 3, dtype=torch.float64) * 0.3)
    before = body.sites(pose).positions
    moved = copy.copy(body)
    moved._site_vertices = body._site_vertices.copy()
    moved._site_vertices[0] = body._site_tangent[0]  # a neighbouring vertex
    verts = body(pose).vertices
    np.testing.assert_allclose(moved.sites(pose).positions[:, 0].numpy(), verts[:, body._site_tangent[0]].numpy(), atol=1e-12)
    assert torch.equal(body.sites(pose).positions, before)
