"""Writers for the import tests: a custom skeleton made from known SMPL motion (renamed joints,
A-pose rest, any unit and up axis) written as BVH and as ASF/AMC."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import torch

from wearpose.body.kinematics import forward_kinematics
from wearpose.body.skeleton import JOINT_INDEX, JOINT_NAMES, PARENTS
from wearpose.geometry import Y_UP_TO_Z_UP, matrix_to_euler, rotation_z
from wearpose.motion.asf import acclaim_rotation
from motion_testutils import bvh_text, random_rotations

#: 3ds Max Biped-style names (not a built-in map: exercises the automatic match).
BIPED_NAMES: dict[str, str] = {
    "pelvis": "Bip01 Pelvis", "spine1": "Bip01 Spine", "spine2": "Bip01 Spine1", "spine3": "Bip01 Spine2",
    "neck": "Bip01 Neck", "head": "Bip01 Head",
    "left_hip": "Bip01 L Thigh", "left_knee": "Bip01 L Calf", "left_ankle": "Bip01 L Foot", "left_foot": "Bip01 L Toe0",
    "right_hip": "Bip01 R Thigh", "right_knee": "Bip01 R Calf", "right_ankle": "Bip01 R Foot", "right_foot": "Bip01 R Toe0",
    "left_collar": "Bip01 L Clavicle", "left_shoulder": "Bip01 L UpperArm", "left_elbow": "Bip01 L Forearm",
    "left_wrist": "Bip01 L Hand", "right_collar": "Bip01 R Clavicle", "right_shoulder": "Bip01 R UpperArm",
    "right_elbow": "Bip01 R Forearm", "right_wrist": "Bip01 R Hand",
}
TREE_JOINTS = [n for n in JOINT_NAMES if n in BIPED_NAMES]  # SMPL minus the two hands


def smpl_world(local: torch.Tensor, pelvis: torch.Tensor, rest: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """SMPL global rotations ``(T, 24, 3, 3)`` and joint positions ``(T, 24, 3)`` (m, Y up)."""
    G, J = forward_kinematics(local, rest)
    return G, J - J[:, :1] + pelvis[:, None]


def apose_globals(rest: torch.Tensor, arm_down_deg: float = 45.0) -> tuple[torch.Tensor, torch.Tensor]:
    """Global rotations ``(24, 3, 3)`` and joint positions ``(24, 3)`` of SMPL's A-pose (shoulders
    lowered by ``arm_down_deg``)."""
    pose = torch.eye(3, dtype=torch.float64).repeat(1, 24, 1, 1)
    a = math.radians(arm_down_deg)
    pose[0, JOINT_INDEX["left_shoulder"]] = rotation_z(torch.tensor(-a, dtype=torch.float64))
    pose[0, JOINT_INDEX["right_shoulder"]] = rotation_z(torch.tensor(a, dtype=torch.float64))
    G, J = forward_kinematics(pose, rest)
    return G[0], J[0]


def custom_skeleton_motion(local: torch.Tensor, pelvis: torch.Tensor, rest: torch.Tensor, scale: float = 1000.0,
                           z_up: bool = True, arm_down_deg: float = 45.0, world: torch.Tensor | None = None) -> dict:
    """The custom skeleton's joint tree and motion: SMPL minus the hands, zero pose = A-pose with
    world-aligned joint frames, in ``scale`` units per metre (1000: mm), Z up when ``z_up`` (or
    any file world: ``world`` maps Y-up coordinates to the file's).

    Returns a dict: ``names`` (SMPL names), ``parents``, ``rest_pos`` ``(J, 3)``, ``G`` ``(T, J, 3, 3)``
    world rotations of the custom joints, ``pos`` ``(T, J, 3)`` world positions (file units),
    ``smpl_pos`` ``(T, J, 3)`` the same positions in metres, Y up (the source truth), ``ends``:
    joint -> End Site vector (the wrists', towards SMPL's hand joints).
    """
    G_s, P_s = smpl_world(local, pelvis, rest)
    GA, XA = apose_globals(rest, arm_down_deg)
    W = Y_UP_TO_Z_UP.to(torch.float64) if z_up else torch.eye(3, dtype=torch.float64)
    if world is not None:
        W = world.to(torch.float64)  # maps wearpose (Y-up) coordinates to the file's
    idx = [JOINT_INDEX[n] for n in TREE_JOINTS]
    parents = []
    for n in TREE_JOINTS:
        p = PARENTS[JOINT_INDEX[n]]
        parents.append(TREE_JOINTS.index(JOINT_NAMES[p]) if p >= 0 else -1)
    G_c = G_s[:, idx] @ GA[idx].transpose(-1, -2)  # zero pose = A-pose, frames world-aligned
    G_c = W @ G_c @ W.T
    rest_pos = (XA[idx] - XA[0]) @ W.T * scale
    pos = P_s[:, idx] @ W.T * scale
    # The wrists' End Sites point to SMPL's hand joints (the hand's direction, as in real rigs).
    ends = {TREE_JOINTS.index(w): (XA[JOINT_INDEX[h]] - XA[JOINT_INDEX[w]]) @ W.T * scale
            for w, h in (("left_wrist", "left_hand"), ("right_wrist", "right_hand"))}
    return {"names": TREE_JOINTS, "parents": parents, "rest_pos": rest_pos, "G": G_c, "pos": pos, "smpl_pos": P_s[:, idx],
            "ends": ends}


def custom_bvh_text(sk: dict, names: dict[str, str] = BIPED_NAMES, fps: float = 30.0) -> str:
    """BVH of :func:`custom_skeleton_motion` (root 6 channels, others ``Zrotation Xrotation
    Yrotation``), joints renamed by ``names``, a static extra root ``Bip01`` above the pelvis."""
    J = len(sk["names"])
    G = sk["G"]
    Tn = G.shape[0]
    out_names = ["Bip01"] + [names[n] for n in sk["names"]]
    parents = [-1] + [p + 1 for p in sk["parents"]]
    parents[1] = 0
    offsets = np.zeros((J + 1, 3))
    vals = [torch.zeros(Tn, 6, dtype=torch.float64)]
    for k in range(J):
        p = sk["parents"][k]
        if p < 0:
            L = G[:, k]
            offsets[k + 1] = 0.0
            pos = sk["pos"][:, k]
            eul = torch.rad2deg(matrix_to_euler(L, "ZXY"))
            vals.append(torch.cat([pos, eul], -1))
        else:
            L = G[:, p].transpose(-1, -2) @ G[:, k]
            offsets[k + 1] = (sk["rest_pos"][k] - sk["rest_pos"][p]).numpy()
            vals.append(torch.rad2deg(matrix_to_euler(L, "ZXY")))
    chans = [("Xposition", "Yposition", "Zposition", "Zrotation", "Xrotation", "Yrotation")] * 2 + \
        [("Zrotation", "Xrotation", "Yrotation")] * (J - 1)
    ends = sk.get("ends", {})
    leaves = {i + 1: (ends[i].tolist() if i in ends else list(0.3 * offsets[i + 1])) for i in range(J) if i not in sk["parents"]}
    return bvh_text(out_names, parents, offsets, chans, torch.cat(vals, -1).numpy(), 1 / fps, leaves)


def _primary_child(parents: Sequence[int], names: Sequence[str], j: int) -> int | None:
    kids = [c for c, p in enumerate(parents) if p == j]
    if not kids or parents[j] < 0:
        return None
    # SMPL trunk: the chain continues up the spine (spine3 -> neck), else the first child.
    for pref in ("spine", "neck", "head"):
        for c in kids:
            if names[c].startswith(pref):
                return c
    return kids[0]


def joint_tree_to_asf_amc(sk: dict, names: dict[str, str] | None = None, length_mult: float = 1.0,
                          angle: str = "deg", seed: int = 0, root_order: str = "TX TY TZ RX RY RZ",
                          end_len: float = 0.3) -> tuple[str, str, dict[str, str]]:
    """ASF + AMC text for a joint tree with world rotations ``sk["G"]`` ``(T, J, 3, 3)`` (zero pose
    = ``sk["rest_pos"]``, world-aligned frames) and root positions ``sk["pos"][:, 0]``.

    Each non-root joint ``j`` becomes the bone ``name(j)`` from ``j`` to its primary child (leaves:
    ``end_len`` times the parent bone further); a joint that is not its parent's primary child hangs
    from a static link bone ``<name>_lnk`` of non-zero length from the end of the parent's bone
    (from the root for the root's children). Real CMU files have no such links: their layout is
    :func:`cmu_layout_asf_amc`. Every bone
    gets a random ``axis`` (random order letters) and a random permutation of ``rx ry rz``, so the
    reader's ``C M C^-1`` and dof order are exercised. Values are ``file = length_mult * units``.

    Returns ``(asf_text, amc_text, {joint name: bone name})``.
    """
    g = torch.Generator().manual_seed(seed)
    nm = names or {n: n for n in sk["names"]}
    J = len(sk["names"])
    par = sk["parents"]
    X = sk["rest_pos"].to(torch.float64)
    G = sk["G"].to(torch.float64)
    Tn = G.shape[0]
    bones: list[dict] = []  # name, parent_bone, dir, length, rotation (T,3,3) relative to parent bone
    end_of: dict[int, str] = {}  # joint -> bone ending at it
    prim = {j: _primary_child(par, sk["names"], j) for j in range(J)}

    joint_bone: dict[str, str] = {}
    for j in range(J):  # parents precede children
        if par[j] < 0:
            continue
        p = par[j]
        if prim[p] != j:
            lnk = f"{nm[sk['names'][j]].replace(' ', '_')}_lnk"
            eye = torch.eye(3, dtype=torch.float64).expand(Tn, 3, 3)
            if par[p] < 0:  # from the root
                bones.append({"name": lnk, "parent": "root", "vec": X[j] - X[p], "rel": eye, "animated": False})
            else:  # from the end of the parent's bone, rigid with it (CMU: clavicles from the thorax end)
                pb = nm[sk["names"][p]].replace(" ", "_")
                bones.append({"name": lnk, "parent": pb, "vec": X[j] - X[prim[p]], "rel": eye, "animated": False})
            end_of[j] = lnk
            parent_bone = lnk
        else:
            parent_bone = end_of[j]  # the parent's bone ends where this joint is
        c = prim[j]
        v = X[c] - X[j] if c is not None else (sk["ends"][j].to(torch.float64) if j in sk.get("ends", {}) else end_len * (X[j] - X[p]))
        bname = nm[sk["names"][j]].replace(" ", "_")
        joint_bone[sk["names"][j]] = bname
        bones.append({"name": bname, "parent": parent_bone, "vec": v, "rel": G[:, p].transpose(-1, -2) @ G[:, j], "animated": True})
        if c is not None:
            end_of[c] = bname
    asf, amc = write_asf_amc(bones, G[:, 0], sk["pos"][:, 0], length_mult, angle, g, root_order)
    return asf, amc, joint_bone


def write_asf_amc(bones: list[dict], root_rot: torch.Tensor, root_pos: torch.Tensor, length_mult: float = 1.0,
                  angle: str = "deg", g: torch.Generator | None = None, root_order: str = "TX TY TZ RX RY RZ"
                  ) -> tuple[str, str]:
    """ASF + AMC text for a bone list (parents first).

    Each bone: ``name``, ``parent`` (bone name or ``"root"``), ``vec`` ``(3,)`` from its start to
    its end in the zero pose (file world, units before ``length_mult``), ``rel`` ``(T, 3, 3)`` its
    rotation relative to the parent bone (world-aligned zero-pose frames), ``animated`` (static
    bones get no dofs). ``root_rot`` ``(T, 3, 3)`` and ``root_pos`` ``(T, 3)`` are the root's world
    rotation and position. Every bone gets a random ``axis`` and a permutation of ``rx ry rz``.
    """
    g = g if g is not None else torch.Generator().manual_seed(0)
    to_a = (lambda r: math.degrees(r)) if angle == "deg" else (lambda r: r)
    Tn = root_rot.shape[0]
    asf = [":version 1.10", ":name synthetic", ":units", "  mass 1.0", f"  length {length_mult:g}", f"  angle {angle}",
           ":documentation", "  written by tests/motion/import_testutils.py", ":root",
           f"   order {root_order}", "   axis XYZ", "   position 0 0 0", "   orientation 0 0 0", ":bonedata"]
    perms = ["rx ry rz", "rz rx ry", "ry rz rx", "rx rz ry", "rz ry rx", "ry rx rz"]
    amc_vals: list[tuple[str, np.ndarray]] = []
    for i, b in enumerate(bones):
        ax = (torch.rand(3, generator=g, dtype=torch.float64) - 0.5) * 2 * math.pi * 0.9
        axo = "XYZ" if i % 2 == 0 else "ZYX"
        C = acclaim_rotation(ax, axo)
        n = float(b["vec"].norm())
        d = (b["vec"] / n).tolist() if n > 0 else [0.0, 1.0, 0.0]
        lines = ["  begin", f"    id {i + 1}", f"    name {b['name']}", f"    direction {d[0]:.12f} {d[1]:.12f} {d[2]:.12f}",
                 f"    length {n * length_mult:.12f}", f"    axis {to_a(float(ax[0])):.12f} {to_a(float(ax[1])):.12f} {to_a(float(ax[2])):.12f} {axo}"]
        if b["animated"]:
            dof = perms[i % len(perms)]
            letters = "".join(t[1].upper() for t in dof.split())
            M = C.T @ b["rel"] @ C
            # Fixed-axis order abc == intrinsic cba: M = R_c R_b R_a.
            ang = matrix_to_euler(M, letters[::-1]).flip(-1)
            lines += [f"    dof {dof}", "    limits " + " ".join("(-inf inf)" for _ in range(3))]
            amc_vals.append((b["name"], ang.numpy()))
        lines.append("  end")
        asf += lines
    asf.append(":hierarchy")
    asf.append("  begin")
    kids: dict[str, list[str]] = {}
    for b in bones:
        kids.setdefault(b["parent"], []).append(b["name"])
    for p, cs in kids.items():
        asf.append(f"    {p} {' '.join(cs)}")
    asf.append("  end")
    # AMC: root translation (file units) and rotation (fixed axes, root order).
    toks = root_order.split()
    rl = "".join(t[1] for t in toks if t.startswith("R"))
    ang_root = matrix_to_euler(root_rot.to(torch.float64), rl[::-1]).flip(-1).numpy()
    pos = root_pos.to(torch.float64).numpy() * length_mult
    amc = ["# synthetic", ":FULLY-SPECIFIED", ":DEGREES" if angle == "deg" else ":RADIANS"]
    for t in range(Tn):
        amc.append(str(t + 1))
        rv = []
        ri = 0
        for tok in toks:
            if tok.startswith("T"):
                rv.append(pos[t, "XYZ".index(tok[1])])
            else:
                rv.append(to_a(float(ang_root[t, ri])))
                ri += 1
        amc.append("root " + " ".join(f"{v:.10f}" for v in rv))
        for name, a in amc_vals:
            amc.append(f"{name} " + " ".join(f"{to_a(float(v)):.10f}" for v in a[t]))
    return "\n".join(asf) + "\n", "\n".join(amc) + "\n"


#: CMU's ASF bones in file order: (bone, parent bone, SMPL joint whose world rotation it takes).
#: The real layout: ``lowerback`` and the hip links start at the root, both clavicles start at
#: the thorax end (where ``lowerneck`` starts), ``upperneck`` sits between ``lowerneck`` and
#: ``head``, ``lwrist`` (forearm twist) between ``lradius`` and ``lhand``, ``lthumb`` hangs from
#: ``lwrist``. ``None``: a static link (no dofs).
CMU_LAYOUT: tuple[tuple[str, str, str | None], ...] = (
    *((f"{s}hipjoint", "root", None) for s in "lr"),
    *(b for s, side in (("l", "left"), ("r", "right")) for b in (
        (f"{s}femur", f"{s}hipjoint", f"{side}_hip"), (f"{s}tibia", f"{s}femur", f"{side}_knee"),
        (f"{s}foot", f"{s}tibia", f"{side}_ankle"), (f"{s}toes", f"{s}foot", f"{side}_foot"))),
    ("lowerback", "root", "spine1"), ("upperback", "lowerback", "spine2"), ("thorax", "upperback", "spine3"),
    ("lowerneck", "thorax", "neck"), ("upperneck", "lowerneck", "neck"), ("head", "upperneck", "head"),
    *(b for s, side in (("l", "left"), ("r", "right")) for b in (
        (f"{s}clavicle", "thorax", f"{side}_collar"), (f"{s}humerus", f"{s}clavicle", f"{side}_shoulder"),
        (f"{s}radius", f"{s}humerus", f"{side}_elbow"), (f"{s}wrist", f"{s}radius", f"{side}_elbow"),
        (f"{s}hand", f"{s}wrist", f"{side}_wrist"), (f"{s}fingers", f"{s}hand", f"{side}_hand"),
        (f"{s}thumb", f"{s}wrist", f"{side}_wrist"))),
)


def _cmu_zero_pose(rest: torch.Tensor) -> dict[str, tuple[torch.Tensor, torch.Tensor]]:
    """Start and end (m, Y up, T-pose facing +Z) of every :data:`CMU_LAYOUT` bone, built from
    SMPL's rest joints: the spine starts at the pelvis, the clavicles where the neck starts."""
    X = {n: rest[JOINT_INDEX[n]].to(torch.float64) for n in JOINT_NAMES}
    mid_neck = 0.5 * (X["neck"] + X["head"])
    out = {"lowerback": (X["pelvis"], X["spine2"]), "upperback": (X["spine2"], X["spine3"]),
           "thorax": (X["spine3"], X["neck"]), "lowerneck": (X["neck"], mid_neck), "upperneck": (mid_neck, X["head"]),
           "head": (X["head"], X["head"] + torch.tensor([0.0, 0.15, 0.02], dtype=torch.float64))}
    for s, side in (("l", "left"), ("r", "right")):
        J = {k: X[f"{side}_{k}"] for k in ("hip", "knee", "ankle", "foot", "collar", "shoulder", "elbow", "wrist", "hand")}
        twist_at = J["elbow"] + 0.85 * (J["wrist"] - J["elbow"])
        out.update({f"{s}hipjoint": (X["pelvis"], J["hip"]), f"{s}femur": (J["hip"], J["knee"]),
                    f"{s}tibia": (J["knee"], J["ankle"]), f"{s}foot": (J["ankle"], J["foot"]),
                    f"{s}toes": (J["foot"], J["foot"] + torch.tensor([0.0, -0.01, 0.05], dtype=torch.float64)),
                    f"{s}clavicle": (X["neck"], J["shoulder"]), f"{s}humerus": (J["shoulder"], J["elbow"]),
                    f"{s}radius": (J["elbow"], twist_at), f"{s}wrist": (twist_at, J["wrist"]),
                    f"{s}hand": (J["wrist"], J["hand"]), f"{s}fingers": (J["hand"], J["hand"] + 0.5 * (J["hand"] - J["wrist"])),
                    f"{s}thumb": (J["wrist"], J["wrist"] + 0.5 * (J["hand"] - J["wrist"]) + torch.tensor([0.0, 0.0, 0.03], dtype=torch.float64))})
    return out


def cmu_layout_motion(local: torch.Tensor, pelvis: torch.Tensor, rest: torch.Tensor, tilt_deg: tuple[float, float] = (30.0, 40.0),
                      neck_deg: float = 20.0, twist_deg: float = 60.0) -> dict:
    """Known motion on CMU's ASF layout (:data:`CMU_LAYOUT`), Y up, T-pose zero pose.

    Every bone takes the world rotation of its SMPL joint in the SMPL motion ``local`` ``(T, 24,
    3, 3)`` / ``pelvis`` ``(T, 3)`` (m), except: the **root is tilted forward against
    ``lowerback``** by an angle sweeping ``tilt_deg`` (root = lowerback's world rotation turned
    about its lateral axis; the hips, on static links from the root, tilt with it), ``upperneck`` bends up to ``neck_deg`` against
    ``lowerneck``, and ``lwrist``/``rwrist`` twist up to ``twist_deg`` about the forearm.

    Returns a dict: ``bones`` (for :func:`write_asf_amc`, vectors in metres), ``root_rot``
    ``(T, 3, 3)``, ``root_pos`` ``(T, 3)`` m, ``world`` bone -> ``(T, 3, 3)``, ``start`` bone ->
    ``(T, 3)`` the true world position (m) of each bone's start, i.e. of the reader's joint, and
    ``root_vs_lowerback_deg`` ``(T,)`` the angle of lowerback's rotation relative to the root.
    """
    from wearpose.geometry import axis_angle_to_matrix, geodesic_angle

    G_s, _ = smpl_world(local.to(torch.float64), pelvis.to(torch.float64), rest.to(torch.float64))
    Tn = G_s.shape[0]
    t = torch.linspace(0.0, 1.0, Tn, dtype=torch.float64)
    zero = _cmu_zero_pose(rest)

    def about(axis: torch.Tensor, ang: torch.Tensor) -> torch.Tensor:
        return axis_angle_to_matrix(axis / axis.norm() * ang[:, None])

    lo, hi = (math.radians(a) for a in tilt_deg)
    tilt = lo + (hi - lo) * 0.5 * (1 - torch.cos(2 * math.pi * t))
    # The root's frame is lowerback's turned forward about the lateral axis: CMU's root is
    # tilted against lowerback by 15-25 deg (median) in real takes; 30-40 deg here.
    root_rot = G_s[:, JOINT_INDEX["spine1"]] @ about(torch.tensor([1.0, 0.0, 0.0], dtype=torch.float64), tilt)
    world: dict[str, torch.Tensor] = {"root": root_rot}
    for name, parent, smpl in CMU_LAYOUT:
        if smpl is None:
            world[name] = world[parent]
        else:
            world[name] = G_s[:, JOINT_INDEX[smpl]]
    bend = math.radians(neck_deg) * torch.sin(2 * math.pi * t)
    world["upperneck"] = world["lowerneck"] @ about(torch.tensor([1.0, 0.0, 0.3], dtype=torch.float64), bend)
    for s in "lr":
        bone = zero[f"{s}wrist"][1] - zero[f"{s}wrist"][0]
        world[f"{s}wrist"] = world[f"{s}radius"] @ about(bone, math.radians(twist_deg) * torch.sin(3 * math.pi * t))
    bones, start = [], {}
    for name, parent, smpl in CMU_LAYOUT:
        a, b = zero[name]
        rel = world[parent].transpose(-1, -2) @ world[name]
        bones.append({"name": name, "parent": parent, "vec": b - a, "rel": rel, "animated": smpl is not None})
    # True positions: each bone starts where its parent ends (the root's children at the root).
    ends: dict[str, torch.Tensor] = {"root": pelvis.to(torch.float64)}
    for name, parent, _ in CMU_LAYOUT:
        start[name] = ends[parent]
        a, b = zero[name]
        ends[name] = start[name] + world[name] @ (b - a)
    rel_lb = geodesic_angle(world["lowerback"], root_rot)
    return {"bones": bones, "root_rot": root_rot, "root_pos": pelvis.to(torch.float64), "world": world, "start": start,
            "root_vs_lowerback_deg": torch.rad2deg(rel_lb)}


def cmu_layout_asf_amc(cmu: dict, seed: int = 0) -> tuple[str, str]:
    """ASF + AMC text of :func:`cmu_layout_motion` in CMU's units (``:units length 0.45``: file
    values are 0.45 x inches) and degrees, root order ``TX TY TZ RX RY RZ``."""
    inch = 1.0 / 0.0254
    bones = [{**b, "vec": b["vec"] * inch} for b in cmu["bones"]]
    return write_asf_amc(bones, cmu["root_rot"], cmu["root_pos"] * inch, length_mult=0.45, angle="deg",
                         g=torch.Generator().manual_seed(seed))


__all__ = ["BIPED_NAMES", "TREE_JOINTS", "custom_skeleton_motion", "custom_bvh_text", "joint_tree_to_asf_amc",
           "apose_globals", "smpl_world", "random_rotations", "write_asf_amc", "CMU_LAYOUT", "cmu_layout_motion",
           "cmu_layout_asf_amc"]
