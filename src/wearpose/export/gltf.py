"""glTF 2.0 binary (GLB) export: the skinned body mesh with its skeleton and the motion as a
skeletal animation, playable in Blender, three.js, Babylon, Windows 3D Viewer, etc.

Layout: one skinned mesh (shaped rest vertices for the motion's betas, top-4 skinning weights),
24 joint nodes named as SMPL's in SMPL's tree (rest translations = bone offsets, identity rest
rotations, since SMPL joint frames are aligned with the body at rest), inverse bind matrices =
translation by ``-rest_joint``, and one animation with a rotation channel per joint (the SMPL
local rotations as unit quaternions, glTF's (x, y, z, w) order) and a translation channel on the
pelvis node (``rest_joints[0] + trans``). glTF is Y up, metres, right-handed: the same world as
wearpose, so nothing is converted. The document's ``asset.extras`` states that frame and how an
estimate was placed (:mod:`wearpose.export.meta`), and so do the scene's ``extras`` (where
Blender and trimesh look).
"""

from __future__ import annotations

import json
import struct
from pathlib import Path

import numpy as np
import torch

from wearpose.body import PARENTS, BodyModel
from wearpose.body.skeleton import JOINT_NAMES, NUM_JOINTS
from wearpose.export.meta import export_metadata
from wearpose.fileio import atomic_write_bytes
from wearpose.geometry import matrix_to_quat
from wearpose.motion.sequence import MotionSequence

_FLOAT, _UINT, _USHORT = 5126, 5125, 5123
_ARRAY_BUFFER, _ELEMENT_ARRAY_BUFFER = 34962, 34963


class _Bin:
    """Accumulates binary blobs (4-byte aligned) with their bufferViews and accessors."""

    def __init__(self) -> None:
        self.data = bytearray()
        self.views: list[dict] = []
        self.accessors: list[dict] = []

    def add(self, arr: np.ndarray, ctype: int, gtype: str, target: int | None = None, minmax: bool = False) -> int:
        arr = np.ascontiguousarray(arr)
        while len(self.data) % 4:
            self.data.append(0)
        view = {"buffer": 0, "byteOffset": len(self.data), "byteLength": arr.nbytes}
        if target is not None:
            view["target"] = target
        self.data += arr.tobytes()
        self.views.append(view)
        acc = {"bufferView": len(self.views) - 1, "componentType": ctype, "count": int(arr.shape[0]), "type": gtype}
        if minmax:
            flat = arr.reshape(arr.shape[0], -1)
            acc["min"] = [float(x) for x in flat.min(0)]
            acc["max"] = [float(x) for x in flat.max(0)]
        self.accessors.append(acc)
        return len(self.accessors) - 1


def write_glb(seq: MotionSequence, path: str | Path, body: BodyModel) -> Path:
    """Write ``seq`` played on ``body`` as a GLB file (format in the module docstring).

    Args:
        seq: motion; pose ``(T, 24, 3, 3)``, betas ``(10,)``, trans ``(T, 3)`` m, fps.
        path: output ``.glb``.
        body: the body model (mesh, weights, rest skeleton).
    """
    with torch.no_grad():
        betas = seq.betas.to(body.dtype)
        out = body(torch.eye(3, dtype=body.dtype).expand(NUM_JOINTS, 3, 3), betas, return_normals=True)
        verts = out.vertices.cpu().numpy().astype(np.float32)  # (V, 3) shaped rest mesh
        normals = out.normals.cpu().numpy().astype(np.float32)
        rest = body.rest_joints(betas).cpu().numpy().astype(np.float64)  # (24, 3)
    w = body.weights.cpu().numpy()
    idx = np.argsort(-w, axis=1)[:, :4]
    wk = np.take_along_axis(w, idx, axis=1).astype(np.float32)
    wk /= wk.sum(1, keepdims=True)
    faces = body.faces.cpu().numpy().astype(np.uint32).reshape(-1)

    b = _Bin()
    a_pos = b.add(verts, _FLOAT, "VEC3", _ARRAY_BUFFER, minmax=True)
    a_nrm = b.add(normals, _FLOAT, "VEC3", _ARRAY_BUFFER)
    a_jnt = b.add(idx.astype(np.uint16), _USHORT, "VEC4", _ARRAY_BUFFER)
    a_wgt = b.add(wk, _FLOAT, "VEC4", _ARRAY_BUFFER)
    a_idx = b.add(faces, _UINT, "SCALAR", _ELEMENT_ARRAY_BUFFER)
    ibm = np.tile(np.eye(4, dtype=np.float32), (NUM_JOINTS, 1, 1))
    ibm[:, :3, 3] = -rest
    # glTF matrices are column-major: store the transpose of each row-major matrix.
    a_ibm = b.add(ibm.transpose(0, 2, 1).reshape(NUM_JOINTS, 16), _FLOAT, "MAT4")

    T = seq.num_frames
    times = (np.arange(T, dtype=np.float32) / np.float32(seq.fps))
    a_time = b.add(times, _FLOAT, "SCALAR", minmax=True)
    q = matrix_to_quat(seq.pose.detach().to(torch.float64).cpu()).numpy()  # (T, 24, 4) w, x, y, z
    q = np.concatenate([q[..., 1:], q[..., :1]], axis=-1).astype(np.float32)  # glTF: x, y, z, w
    root = (rest[0] + seq.trans.detach().to(torch.float64).cpu().numpy()).astype(np.float32)  # (T, 3)
    samplers, channels = [], []
    for j in range(NUM_JOINTS):
        a = b.add(np.ascontiguousarray(q[:, j]), _FLOAT, "VEC4")
        samplers.append({"input": a_time, "output": a, "interpolation": "LINEAR"})
        channels.append({"sampler": len(samplers) - 1, "target": {"node": j, "path": "rotation"}})
    a_tr = b.add(root, _FLOAT, "VEC3")
    samplers.append({"input": a_time, "output": a_tr, "interpolation": "LINEAR"})
    channels.append({"sampler": len(samplers) - 1, "target": {"node": 0, "path": "translation"}})

    nodes = []
    for j in range(NUM_JOINTS):
        p = PARENTS[j]
        t = rest[j] - rest[p] if p >= 0 else rest[j]
        node = {"name": JOINT_NAMES[j], "translation": [float(x) for x in t]}
        kids = [c for c in range(NUM_JOINTS) if PARENTS[c] == j]
        if kids:
            node["children"] = kids
        nodes.append(node)
    nodes.append({"name": "body", "mesh": 0, "skin": 0})
    meta = export_metadata(seq, ".glb")
    gltf = {
        "asset": {"version": "2.0", "generator": "wearpose", "extras": meta},
        "scene": 0,
        # also the scene's extras: Blender shows them as the scene's custom properties, trimesh as scene.metadata
        "scenes": [{"nodes": [0, NUM_JOINTS], "extras": meta}],
        "nodes": nodes,
        "meshes": [{"name": body.asset_id, "primitives": [{
            "attributes": {"POSITION": a_pos, "NORMAL": a_nrm, "JOINTS_0": a_jnt, "WEIGHTS_0": a_wgt},
            "indices": a_idx, "mode": 4}]}],
        "skins": [{"joints": list(range(NUM_JOINTS)), "inverseBindMatrices": a_ibm, "skeleton": 0}],
        "animations": [{"name": str(seq.meta.get("clip", "motion")), "samplers": samplers, "channels": channels}],
        "buffers": [{"byteLength": len(b.data)}],
        "bufferViews": b.views,
        "accessors": b.accessors,
    }
    js = json.dumps(gltf, separators=(",", ":")).encode("utf-8")
    js += b" " * (-len(js) % 4)
    binary = bytes(b.data) + b"\x00" * (-len(b.data) % 4)
    total = 12 + 8 + len(js) + 8 + len(binary)
    blob = (struct.pack("<4sII", b"glTF", 2, total) + struct.pack("<I4s", len(js), b"JSON") + js
            + struct.pack("<I4s", len(binary), b"BIN\x00") + binary)
    return atomic_write_bytes(path, blob)


def read_glb(path: str | Path) -> tuple[dict, bytes]:
    """Split a GLB into its JSON document and binary chunk (for tests and inspection)."""
    data = Path(path).read_bytes()
    magic, version, total = struct.unpack_from("<4sII", data, 0)
    if magic != b"glTF" or version != 2 or total != len(data):
        raise ValueError(f"{path}: not a GLB 2.0 file")
    jlen, _ = struct.unpack_from("<I4s", data, 12)
    doc = json.loads(data[20:20 + jlen])
    blen, _ = struct.unpack_from("<I4s", data, 20 + jlen)
    return doc, data[28 + jlen:28 + jlen + blen]
