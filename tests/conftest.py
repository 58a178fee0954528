"""Shared fixtures: tiny synthetic body assets (no dependency on the embedded asset)."""

from __future__ import annotations

import numpy as np
import pytest

from wearpose.body.asset import BodyAsset
from wearpose.body.skeleton import NUM_JOINTS, PARENTS

# SMPL-like rest joints (m), T-pose facing +Z, left at +X.
SMPL_LIKE_REST = np.array([
    [0.00, -0.22, 0.03], [0.06, -0.31, 0.02], [-0.06, -0.31, 0.02], [0.00, -0.11, 0.00],
    [0.10, -0.69, 0.02], [-0.10, -0.69, 0.02], [0.00, 0.03, 0.03], [0.09, -1.09, -0.02],
    [-0.09, -1.09, -0.02], [0.00, 0.08, 0.05], [0.11, -1.15, 0.10], [-0.11, -1.15, 0.10],
    [0.00, 0.29, 0.01], [0.08, 0.19, 0.00], [-0.08, 0.19, 0.00], [0.00, 0.36, 0.05],
    [0.19, 0.23, -0.01], [-0.19, 0.23, -0.01], [0.45, 0.22, -0.03], [-0.45, 0.22, -0.03],
    [0.71, 0.23, -0.01], [-0.71, 0.23, -0.01], [0.80, 0.22, -0.02], [-0.80, 0.22, -0.02],
])


def make_tiny_asset(seed: int = 0, num_betas: int = 10, posedirs: bool = False) -> BodyAsset:
    """A closed tetrahedron around each joint; each vertex skinned to its joint and its parent.

    96 vertices, 96 faces. Joint regressor = tetra centroid, so joints are exactly regressable.
    """
    rng = np.random.default_rng(seed)
    tet = np.array([[1, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]], dtype=np.float64) * 0.03
    tet_faces = np.array([[0, 1, 2], [0, 3, 1], [0, 2, 3], [1, 3, 2]])
    verts, faces, weights, J_reg = [], [], np.zeros((NUM_JOINTS * 4, NUM_JOINTS)), np.zeros((NUM_JOINTS, NUM_JOINTS * 4))
    for j in range(NUM_JOINTS):
        base = 4 * j
        offs = tet + rng.normal(scale=0.005, size=tet.shape)
        offs -= offs.mean(0)
        verts.append(SMPL_LIKE_REST[j] + offs)
        faces.append(tet_faces + base)
        J_reg[j, base:base + 4] = 0.25
        p = max(PARENTS[j], 0)
        w = rng.uniform(0.6, 1.0, size=4)
        weights[base:base + 4, j] += w
        weights[base:base + 4, p] += 1 - w
    v = np.concatenate(verts)
    shapedirs = rng.normal(scale=0.01, size=(v.shape[0], 3, num_betas))
    pd = rng.normal(scale=0.002, size=((NUM_JOINTS - 1) * 9, v.shape[0] * 3)) if posedirs else None
    return BodyAsset(
        v_template=v.astype(np.float32), faces=np.concatenate(faces).astype(np.int64),
        shapedirs=shapedirs.astype(np.float32), J_regressor=J_reg.astype(np.float32),
        weights=weights.astype(np.float32), parents=np.array(PARENTS, dtype=np.int64),
        posedirs=None if pd is None else pd.astype(np.float32),
        site_names=("head", "left_forearm"), site_vertices=np.array([60, 72]), site_tangent=np.array([61, 73]),
        meta={"asset_id": "tiny-test"},
    )


@pytest.fixture
def one_torch_thread():
    """Run a test with one torch thread: suites of many tiny tensor ops are dominated by
    thread hand-offs on a loaded 2-core machine. Directories opt in from their conftest."""
    import torch

    n = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(n)


@pytest.fixture
def tiny_asset() -> BodyAsset:
    return make_tiny_asset()
