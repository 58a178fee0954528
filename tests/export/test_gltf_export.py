"""GLB export: decoding the file and skinning it as a glTF viewer would reproduces BodyModel."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch
from scipy.spatial.transform import Rotation

from tests.conftest import make_tiny_asset
from wearpose.body import PARENTS, BodyModel
from wearpose.export.gltf import read_glb, write_glb
from wearpose.geometry import axis_angle_to_matrix
from wearpose.motion import MotionSequence

_NP = {5126: np.float32, 5125: np.uint32, 5123: np.uint16}
_N = {"SCALAR": 1, "VEC3": 3, "VEC4": 4, "MAT4": 16}


def _accessor(doc: dict, binary: bytes, i: int) -> np.ndarray:
    acc = doc["accessors"][i]
    view = doc["bufferViews"][acc["bufferView"]]
    arr = np.frombuffer(binary, dtype=_NP[acc["componentType"]], count=acc["count"] * _N[acc["type"]],
                        offset=view["byteOffset"])
    return arr.reshape(acc["count"], _N[acc["type"]])


def test_glb_skinning_matches_body_model(tmp_path: Path) -> None:
    body = BodyModel(make_tiny_asset(), dtype=torch.float64)
    g = torch.Generator().manual_seed(3)
    T = 6
    pose = axis_angle_to_matrix(torch.randn(T, 24, 3, generator=g, dtype=torch.float64) * 0.5)
    betas = torch.randn(10, generator=g, dtype=torch.float64)
    trans = torch.randn(T, 3, generator=g, dtype=torch.float64)
    seq = MotionSequence(pose, betas, trans, 30.0, {"clip": "t"})
    doc, binary = read_glb(write_glb(seq, tmp_path / "m.glb", body))
    prim = doc["meshes"][0]["primitives"][0]
    verts = _accessor(doc, binary, prim["attributes"]["POSITION"]).astype(np.float64)
    joints = _accessor(doc, binary, prim["attributes"]["JOINTS_0"]).astype(int)
    weights = _accessor(doc, binary, prim["attributes"]["WEIGHTS_0"]).astype(np.float64)
    ibm = _accessor(doc, binary, doc["skins"][0]["inverseBindMatrices"]).reshape(-1, 4, 4).transpose(0, 2, 1)
    anim = doc["animations"][0]
    times = _accessor(doc, binary, anim["samplers"][0]["input"])[:, 0]
    np.testing.assert_allclose(times, np.arange(T) / 30.0, atol=1e-6)
    rot = {c["target"]["node"]: _accessor(doc, binary, anim["samplers"][c["sampler"]]["output"])
           for c in anim["channels"] if c["target"]["path"] == "rotation"}
    tr = [_accessor(doc, binary, anim["samplers"][c["sampler"]]["output"])
          for c in anim["channels"] if c["target"]["path"] == "translation"][0]
    ref = body(pose, betas, trans).vertices.numpy()
    for t in (0, T - 1):
        world = [None] * 24
        for j in range(24):  # node transforms: T(translation) R(rotation), parents first
            local = np.eye(4)
            local[:3, :3] = Rotation.from_quat(rot[j][t].astype(np.float64)).as_matrix()  # x, y, z, w
            local[:3, 3] = tr[t] if j == 0 else doc["nodes"][j]["translation"]
            world[j] = local if PARENTS[j] < 0 else world[PARENTS[j]] @ local
        M = np.stack([world[j] @ ibm[j] for j in range(24)])  # (24, 4, 4) joint matrices
        vh = np.concatenate([verts, np.ones((len(verts), 1))], axis=1)
        skinned = np.einsum("vk,vkij,vj->vi", weights, M[joints], vh)[:, :3]
        np.testing.assert_allclose(skinned, ref[t], atol=1e-5)
