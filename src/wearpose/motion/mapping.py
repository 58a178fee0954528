"""Which joint of a foreign skeleton is which SMPL joint: built-in maps, automatic matching by
name patterns and tree position, and user joint maps (YAML).

Order of precedence (:func:`match_skeleton`):

1. a user joint map (``--joint-map FILE``) -- entries override everything below, ``null`` unmaps;
2. a built-in map whose joint names all occur in the skeleton: the corpus skeletons
   (:data:`~wearpose.motion.retarget.CMU_DAZ`, :data:`~wearpose.motion.retarget.BANDAI`, with
   their measured hinge axes) and the naming schemes :data:`CMU_ASF` (``lfemur``, ``ltibia``,
   ``lhumerus``...), :data:`MIXAMO` (``mixamorig:LeftUpLeg``...), :data:`RIGIFY` (Blender,
   ``thigh.L``, ``upper_arm.L``..., with or without ``DEF-``), :data:`SMPL_NAMES` (our own BVH
   export). Namespaces (``mixamorig:``, ``Armature|``) are ignored when comparing names, and
   spine2, hands and toes may be absent;
3. otherwise the automatic match (:func:`auto_map`):

   - names are split into words (``LeftUpLeg`` -> left, up, leg; ``thigh.L`` -> thigh, L;
     ``Bip01 L Calf`` -> L, calf; ``lfemur`` -> l, femur) and a side (left/right) is read from
     ``left``/``l``/``lf``, ``right``/``r``/``rt`` words;
   - limbs by name, each searched **below** the previous one: thigh (``upleg|upperleg|thigh|
     femur|hip``) > shin (``leg|lowerleg|shin|calf|knee|tibia``) > foot (``foot|ankle``) > toe
     (``toe|ball``); upper arm (``arm|upperarm|humerus|shldr|shoulder``) > forearm (``forearm|
     lowerarm|elbow|radius``) > hand (``hand|wrist``); a ``clavicle|collar`` (or a ``shoulder``
     with an upper arm below it) on the way from the trunk to the upper arm is the collar. The
     shallowest match wins; ``twist``/``roll``/``end``/``nub``/``link`` helpers and joints at their
     parent's place (zero-length connectors) are skipped;
   - **tree position** for the trunk: pelvis = the lowest common ancestor of the two thighs,
     spine3 (chest) = that of the two upper arms; the joints strictly between them (ignoring
     zero-length links) become spine1 (one), spine1 + spine2 (two), or the ones nearest 1/3
     and 4/5 of the way up (more); neck and head are the ``neck``/``head`` names below the
     chest outside the arms, else the first and last joints of the longest chain there;
   - a limb joint with no name match is taken from its chain: the next joint with a non-zero
     bone below the last one found.

SMPL joints left unmapped are filled by the retargeting rule (:mod:`wearpose.motion.retarget`):
spine2 takes half of the spine1 -> spine3 rotation, every other missing joint (hands, toes,
collars...) keeps the identity local rotation, i.e. follows its parent. Required: pelvis, both
hips, knees and ankles.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from wearpose.body.skeleton import JOINT_NAMES, PARENTS
from wearpose.errors import InputFileError
from wearpose.motion.bvh import BvhSkeleton
from wearpose.motion.retarget import BANDAI, CMU_DAZ, SkeletonMap

#: SMPL joints a skeleton must provide (the leg scale and the floor need them).
REQUIRED_JOINTS: tuple[str, ...] = ("pelvis", "left_hip", "right_hip", "left_knee", "right_knee", "left_ankle", "right_ankle")
#: SMPL joints a built-in map may miss in a file and still match (rigs without fingers or toes).
OPTIONAL_JOINTS: tuple[str, ...] = ("spine2", "left_hand", "right_hand", "left_foot", "right_foot")


def _sided(l_names: dict[str, str], r_names: dict[str, str]) -> dict[str, str]:
    return {**{f"left_{k}": v for k, v in l_names.items()}, **{f"right_{k}": v for k, v in r_names.items()}}


_LIMBS = ("collar", "shoulder", "elbow", "wrist", "hand", "hip", "knee", "ankle", "foot")

#: CMU database ASF skeleton (the ASF reader puts each joint at its bone's start: ``lfemur`` at
#: the hip). The three spine segments ``lowerback > upperback > thorax`` are SMPL's
#: spine1 > spine2 > spine3, so no spine rotation is lost between pelvis and chest (``lowerback``
#: starts at the root: SMPL's short pelvis -> spine1 bone has no source bone and follows the
#: root, as the hips do). Both clavicles start at the thorax end, where the neck starts, so the
#: chest's twist comes from the shoulders (:data:`wearpose.motion.retarget._LATERAL`).
#: ``upperneck`` (between ``lowerneck`` and ``head``) and ``lwrist`` (the forearm twist segment
#: before ``lhand``) are left out; the neck and forearm bones are swung onto the source's per
#: frame (:class:`wearpose.motion.retarget.BoneFix`).
CMU_ASF = SkeletonMap(
    name="cmu_asf",
    joints={"pelvis": "root", "spine1": "lowerback", "spine2": "upperback", "spine3": "thorax", "neck": "lowerneck", "head": "head",
            **_sided(dict(zip(_LIMBS, ("lclavicle", "lhumerus", "lradius", "lhand", "lfingers", "lfemur", "ltibia", "lfoot", "ltoes"))),
                     dict(zip(_LIMBS, ("rclavicle", "rhumerus", "rradius", "rhand", "rfingers", "rfemur", "rtibia", "rfoot", "rtoes"))))},
    units_to_m=0.0254 / 0.45, foot_joints=("lfoot", "rfoot", "ltoes", "rtoes"),
    description="CMU mocap ASF skeleton (root, lfemur, ltibia, lhumerus...), 1 unit = 1/0.45 inch")

#: Mixamo rigs (``mixamorig:`` prefix optional).
MIXAMO = SkeletonMap(
    name="mixamo",
    joints={"pelvis": "Hips", "spine1": "Spine", "spine2": "Spine1", "spine3": "Spine2", "neck": "Neck", "head": "Head",
            **_sided(dict(zip(_LIMBS, ("LeftShoulder", "LeftArm", "LeftForeArm", "LeftHand", "LeftHandMiddle1", "LeftUpLeg", "LeftLeg", "LeftFoot", "LeftToeBase"))),
                     dict(zip(_LIMBS, ("RightShoulder", "RightArm", "RightForeArm", "RightHand", "RightHandMiddle1", "RightUpLeg", "RightLeg", "RightFoot", "RightToeBase"))))},
    foot_joints=("LeftFoot", "RightFoot", "LeftToeBase", "RightToeBase"),
    description="Mixamo rig (mixamorig:Hips, LeftUpLeg, LeftArm...)")

#: Blender Rigify metarig / deform bones (``DEF-`` prefix optional).
RIGIFY = SkeletonMap(
    name="rigify",
    joints={"pelvis": "spine", "spine1": "spine.001", "spine2": "spine.002", "spine3": "spine.003", "neck": "spine.004", "head": "spine.006",
            **_sided(dict(zip(_LIMBS[:4] + _LIMBS[5:], ("shoulder.L", "upper_arm.L", "forearm.L", "hand.L", "thigh.L", "shin.L", "foot.L", "toe.L"))),
                     dict(zip(_LIMBS[:4] + _LIMBS[5:], ("shoulder.R", "upper_arm.R", "forearm.R", "hand.R", "thigh.R", "shin.R", "foot.R", "toe.R"))))},
    foot_joints=("foot.L", "foot.R", "toe.L", "toe.R"),
    description="Blender Rigify (spine, thigh.L, upper_arm.L...; DEF- prefix optional)")

#: Our own SMPL-skeleton BVH export (read exactly by ``read_smpl_bvh`` when the tree is SMPL's).
SMPL_NAMES = SkeletonMap(name="smpl", joints={n: n for n in JOINT_NAMES}, foot_joints=("left_foot", "right_foot"),
                         description="SMPL joint names (wearpose export)")

#: Built-in maps tried in this order (first full match wins).
NAMED_MAPS: tuple[SkeletonMap, ...] = (CMU_DAZ, BANDAI, CMU_ASF, MIXAMO, RIGIFY, SMPL_NAMES)


# ---------------------------------------------------------------------------- names
def strip_namespace(name: str) -> str:
    """``mixamorig:Hips`` -> ``Hips``; ``Armature|Hips`` -> ``Hips``; ``DEF-thigh.L`` -> ``thigh.L``."""
    n = re.split(r"[:|]", name)[-1]
    return re.sub(r"^(DEF|ORG|MCH)-", "", n)


_LEFT = {"left", "l", "lf", "lft"}
_RIGHT = {"right", "r", "rt", "rgt"}
_NOISE = re.compile(r"^(bip\d*|def|org|mch|mixamorig\d*|cc|base|jnt|bn|joint|ctrl|b)$")
_HELPER = re.compile(r"twist|roll|nub|helper|ik|pole|end$|_end|end_|top|link|lnk")
_BODY = re.compile(r"^(femur|tibia|foot|toes?|hand|humerus|radius|wrist|clavicle|shoulder|shldr|hip|thigh|shin|"
                   r"knee|ankle|elbow|arm|forearm|leg|upleg|collar|fingers?|thumb|hipjoint)")

ROLE_PATTERNS: dict[str, str] = {
    "hip": r"upleg|upperleg|legupper|thigh|femur|^hip\d*$",
    "knee": r"^leg\d*$|lowerleg|lowleg|leglower|shin|calf|knee|tibia|crus",
    "ankle": r"foot|ankle|tarsal",
    "foot": r"toe|ball",
    "collar": r"clavicle|collar|clav",
    "shoulder": r"upperarm|uparm|armupper|humerus|^u?arm\d*$|shldr|shoulder",
    "elbow": r"forearm|lowerarm|lowarm|armlower|elbow|radius|ulna|^farm$",
    "wrist": r"^hand\d*$|wrist",
    "neck": r"neck",
    "head": r"head",
}


def split_name(name: str) -> tuple[str | None, str]:
    """``(side, base)`` of a joint name: side ``"left"``/``"right"``/``None``, base = the other
    words, lower case, joined (``"Bip01 L Calf"`` -> ``("left", "calf")``)."""
    n = strip_namespace(name)
    n = re.sub(r"^([LR])(?=[A-Z]{1,2}[a-z])", r"\1 ", n)  # OptiTrack style LUArm, RThigh (not ROOT)
    n = re.sub(r"([a-z0-9])([A-Z])", r"\1 \2", n)
    n = re.sub(r"([A-Z])([A-Z][a-z])", r"\1 \2", n)
    words = [w.lower() for w in re.split(r"[^A-Za-z0-9]+", n) if w]
    side = None
    rest: list[str] = []
    for w in words:
        if side is None and w in _LEFT:
            side = "left"
        elif side is None and w in _RIGHT:
            side = "right"
        elif _NOISE.match(w):
            continue
        else:
            rest.append(w)
    if side is None and rest:
        # CMU-ASF style: a side letter glued to a body word (lfemur, rhumerus, ltoes).
        w = rest[0]
        if w[0] in "lr" and _BODY.match(w[1:]):
            side = "left" if w[0] == "l" else "right"
            rest[0] = w[1:]
    return side, "".join(rest)


# ---------------------------------------------------------------------------- result
@dataclass
class SkeletonMatch:
    """Result of :func:`match_skeleton`.

    Attributes:
        smap: the map (SMPL joint -> skeleton joint name; units not decided here).
        source: ``"built-in <name>"``, ``"automatic"`` or ``"joint map <file>"`` (+ overrides).
        how: SMPL joint -> ``"map"``, ``"name"``, ``"tree"``, ``"joint map"`` or ``"fill"``.
        notes: remarks worth showing the user (dropped joints, ambiguities).
        joint_map_options: extra keys of a user joint map (``units``, ``up``).
    """

    smap: SkeletonMap
    source: str
    how: dict[str, str]
    notes: list[str] = field(default_factory=list)
    joint_map_options: dict[str, Any] = field(default_factory=dict)

    def table(self) -> list[tuple[str, str, str]]:
        """Rows ``(SMPL joint, skeleton joint or "-", how)`` in SMPL order."""
        return [(n, self.smap.joints.get(n, "-"), self.how.get(n, "fill")) for n in JOINT_NAMES]


def _lookup(skel: BvhSkeleton) -> dict[str, str]:
    """Case-insensitive, namespace-free name -> actual name (first occurrence wins)."""
    out: dict[str, str] = {}
    for n in skel.names:
        out.setdefault(strip_namespace(n).lower(), n)
    return out


def builtin_match(skel: BvhSkeleton) -> SkeletonMap | None:
    """The first of :data:`NAMED_MAPS` whose joints all occur in ``skel`` (names compared
    without namespace and case; :data:`OPTIONAL_JOINTS` may be absent), re-targeted at the
    skeleton's actual names; else ``None``."""
    look = _lookup(skel)
    for m in NAMED_MAPS:
        if all(strip_namespace(v).lower() in look for k, v in m.joints.items() if k not in OPTIONAL_JOINTS):
            joints = {k: look[strip_namespace(v).lower()] for k, v in m.joints.items() if strip_namespace(v).lower() in look}
            feet = tuple(look[strip_namespace(f).lower()] for f in m.foot_joints if strip_namespace(f).lower() in look)
            return replace(m, joints=joints, foot_joints=feet)
    return None


# ---------------------------------------------------------------------------- automatic match
class _Tree:
    def __init__(self, skel: BvhSkeleton, offsets: np.ndarray):
        self.skel = skel
        self.parents = skel.parents
        self.kids = {j: skel.children(j) for j in range(skel.num_joints)}
        self.depth = [0] * skel.num_joints
        for j, p in enumerate(self.parents):
            self.depth[j] = 0 if p < 0 else self.depth[p] + 1
        self.off = np.linalg.norm(offsets, axis=1)
        nz = self.off[self.off > 0]
        self.eps = 0.02 * float(np.median(nz)) if len(nz) else 0.0
        pos = np.zeros_like(offsets)
        for j, p in enumerate(self.parents):
            pos[j] = offsets[j] if p < 0 else pos[p] + offsets[j]
        self.pos = pos
        self.split = [split_name(n) for n in skel.names]

    def ancestors(self, j: int) -> list[int]:
        out = []
        while self.parents[j] >= 0:
            j = self.parents[j]
            out.append(j)
        return out

    def below(self, j: int, a: int) -> bool:
        return a in self.ancestors(j)

    def subtree(self, j: int) -> list[int]:
        out, stack = [], [j]
        while stack:
            k = stack.pop()
            out.append(k)
            stack += self.kids[k]
        return out

    def lca(self, a: int, b: int) -> int:
        aa = [a, *self.ancestors(a)]
        for k in [b, *self.ancestors(b)]:
            if k in aa:
                return k
        return 0

    def matches(self, role: str, side: str | None, within: list[int] | None = None) -> list[int]:
        pat = re.compile(ROLE_PATTERNS[role])
        cands = within if within is not None else range(self.skel.num_joints)
        out = [j for j in cands if self.split[j][0] == side and pat.search(self.split[j][1])
               and not _HELPER.search(self.split[j][1])]
        # A joint at its parent's place (zero-length link, e.g. an ASF connector) is skipped when
        # another match exists: the real joint sits where the bone starts.
        placed = [j for j in out if self.off[j] > self.eps or self.parents[j] < 0]
        return sorted(placed or out, key=lambda j: self.depth[j])

    def chain_next(self, j: int) -> int | None:
        """The next joint with a non-zero bone down the longest path below ``j`` (helpers skipped)."""
        def height(k: int) -> float:
            return max((self.off[c] + height(c) for c in self.kids[k]), default=0.0)
        k = j
        while self.kids[k]:
            k = max(self.kids[k], key=lambda c: self.off[c] + height(c))
            if self.off[k] > self.eps and not _HELPER.search(self.split[k][1]):
                return k
        return None


def auto_map(skel: BvhSkeleton, offsets: np.ndarray) -> tuple[dict[str, str], dict[str, str], list[str]]:
    """Automatic SMPL map by name patterns and tree position (rules in the module doc).

    Args:
        skel: the skeleton; offsets: ``(J, 3)`` rest bone vectors (any unit).

    Returns:
        ``(joints, how, notes)``: SMPL joint -> skeleton joint name, SMPL joint -> ``"name"`` or
        ``"tree"``, remarks.
    """
    t = _Tree(skel, offsets)
    names = skel.names
    found: dict[str, int] = {}
    how: dict[str, str] = {}
    notes: list[str] = []

    def put(smpl: str, j: int | None, kind: str) -> None:
        if j is not None:
            found[smpl] = j
            how[smpl] = kind

    for side in ("left", "right"):
        hips = t.matches("hip", side)
        hips = [j for j in hips if split_name(names[j])[1] != "hipjoint"]
        if hips:
            put(f"{side}_hip", hips[0], "name")
            prev = hips[0]
            for role in ("knee", "ankle", "foot"):
                m = t.matches(role, side, t.subtree(prev)[1:])
                if role == "ankle":
                    m = [j for j in m if not re.search(ROLE_PATTERNS["foot"], t.split[j][1])]
                if m:
                    put(f"{side}_{role}", m[0], "name")
                else:
                    put(f"{side}_{role}", t.chain_next(prev), "tree")
                if f"{side}_{role}" not in found:
                    break
                prev = found[f"{side}_{role}"]
        # Arms: collars are clavicle/collar names, or a "shoulder" with an upper arm below it.
        ua_pat = re.compile(r"upperarm|uparm|armupper|humerus|^u?arm\d*$|shldr")
        arms = t.matches("shoulder", side)
        collar_like = [j for j in arms if "shoulder" in t.split[j][1]
                       and any(ua_pat.search(t.split[k][1]) and t.split[k][0] == side for k in t.subtree(j)[1:])]
        arms = [j for j in arms if j not in collar_like]
        if arms:
            sh = arms[0]
            put(f"{side}_shoulder", sh, "name")
            coll = [j for j in t.matches("collar", side) + collar_like if t.below(sh, j)]
            if coll:
                put(f"{side}_collar", max(coll, key=lambda j: t.depth[j]), "name")
            prev = sh
            for role in ("elbow", "wrist"):
                m = t.matches(role, side, t.subtree(prev)[1:])
                put(f"{side}_{role}", m[0] if m else t.chain_next(prev), "name" if m else "tree")
                if f"{side}_{role}" not in found:
                    break
                prev = found[f"{side}_{role}"]
    # Trunk by tree position.
    if "left_hip" in found and "right_hip" in found:
        put("pelvis", t.lca(found["left_hip"], found["right_hip"]), "tree")
    chest = None
    if "left_shoulder" in found and "right_shoulder" in found:
        chest = t.lca(found["left_shoulder"], found["right_shoulder"])
        if "pelvis" in found and (chest == found["pelvis"] or not t.below(chest, found["pelvis"])):
            notes.append(f"arms meet at {names[chest]}, not above the pelvis {names[found['pelvis']]}: trunk left unmapped")
            chest = None
    if chest is not None and "pelvis" in found:
        put("spine3", chest, "tree")
        path = [j for j in reversed(t.ancestors(chest)) if t.below(j, found["pelvis"])]
        path = [j for j in path if t.off[j] > t.eps]
        base, top = t.pos[found["pelvis"]], t.pos[chest]
        h = float(np.linalg.norm(top - base)) or 1.0
        frac = [float(np.linalg.norm(t.pos[j] - base)) / h for j in path]
        if len(path) == 1:
            put("spine1", path[0], "tree")
        elif len(path) == 2:
            put("spine1", path[0], "tree")
            put("spine2", path[1], "tree")
        elif len(path) > 2:
            i1 = int(np.argmin([abs(f - 1 / 3) for f in frac]))
            put("spine1", path[i1], "tree")
            later = list(range(i1 + 1, len(path)))
            if later:
                put("spine2", path[min(later, key=lambda i: abs(frac[i] - 0.8))], "tree")
        arm_roots = {j for s in ("left", "right") for j in [found.get(f"{s}_shoulder")] if j is not None}
        region = [k for k in t.subtree(chest)[1:] if not any(a == k or t.below(a, k) or t.below(k, a) for a in arm_roots)]
        neck = t.matches("neck", None, region)
        head = t.matches("head", None, region)
        if neck:
            put("neck", neck[0], "name")
        if head and (not neck or t.below(head[0], neck[0])):
            put("head", head[0], "name")
        if "neck" not in found and region:
            nk = t.chain_next(chest)
            if nk is not None and nk in region:
                put("neck", nk, "tree")
        if "head" not in found and "neck" in found:
            k = found["neck"]
            last = None
            while (nxt := t.chain_next(k)) is not None:
                last = k = nxt
            put("head", last, "tree")
    return {k: names[j] for k, j in found.items()}, how, notes


# ---------------------------------------------------------------------------- joint map files
def load_joint_map(path: str | Path) -> dict[str, Any]:
    """Read a YAML joint map: top-level keys are SMPL joint names (value: the skeleton's joint
    name, or ``null`` to leave it unmapped), plus optional ``units`` (``m``, ``cm``, ``mm``,
    ``inch``, ``acclaim`` or metres per unit) and ``up`` (``y``, ``z``, ``-z``...).

    Raises:
        InputFileError: unreadable YAML, not a mapping, unknown SMPL joint or key.
    """
    import yaml  # start-up: yaml adds ~15 ms to import wearpose.motion

    path = Path(path)
    if not path.is_file():
        raise InputFileError(path, "joint map not found", "a YAML file 'smpl_joint: your_joint' per line")
    try:
        data = yaml.safe_load(path.read_text(encoding="utf-8"))
    except yaml.YAMLError as exc:
        line = getattr(getattr(exc, "problem_mark", None), "line", None)
        raise InputFileError(path, f"invalid YAML ({exc.__class__.__name__})", "a YAML mapping 'smpl_joint: your_joint'",
                             field=f"line {line + 1}" if line is not None else None) from exc
    if data is None:
        data = {}
    if not isinstance(data, Mapping):
        raise InputFileError(path, f"top level is a {type(data).__name__}", "a YAML mapping 'smpl_joint: your_joint'")
    if isinstance(data.get("joints"), Mapping):
        data = {**{k: v for k, v in data.items() if k != "joints"}, **data["joints"]}
    out: dict[str, Any] = {"joints": {}, "options": {}}
    for k, v in data.items():
        k = str(k)
        if k in ("units", "up", "name"):
            out["options"][k] = v
        elif k in JOINT_NAMES:
            if v is not None and not isinstance(v, str):
                raise InputFileError(path, f"{k}: {v!r} is not a joint name", "a joint name of your skeleton or null", field=k)
            out["joints"][k] = v
        else:
            raise InputFileError(path, f"unknown key {k!r}", f"SMPL joint names ({', '.join(JOINT_NAMES)}) or units/up/name", field=k)
    return out


# ---------------------------------------------------------------------------- entry
def _check_tree(smap_joints: dict[str, str], skel: BvhSkeleton) -> list[tuple[str, str]]:
    """SMPL joints whose skeleton joint is not below the skeleton joint of their nearest mapped
    SMPL ancestor: ``[(smpl joint, ancestor smpl joint)]``."""
    idx = {n: i for i, n in enumerate(skel.names)}
    bad = []
    for j, n in enumerate(JOINT_NAMES):
        if n not in smap_joints:
            continue
        p = PARENTS[j]
        while p >= 0 and JOINT_NAMES[p] not in smap_joints:
            p = PARENTS[p]
        if p < 0:
            continue
        a, k = idx[smap_joints[JOINT_NAMES[p]]], idx[smap_joints[n]]
        while k >= 0 and k != a:
            k = skel.parents[k]
        if k != a or idx[smap_joints[n]] == a:
            bad.append((n, JOINT_NAMES[p]))
    return bad


def _missing_lines(missing: list[str], skel: Any, joints: Mapping[str, str]) -> str:
    """Joint-map lines for SMPL joints no joint was found for, and the skeleton's joints that
    nothing is mapped to yet (the candidates for the right-hand side)."""
    used = set(joints.values())
    free = [n for n in skel.names if n not in used]
    lines = ", ".join(f"'{m}: <your joint>'" for m in missing)
    cand = ", ".join(free[:12]) + ("..." if len(free) > 12 else "")
    return f"{lines} (joints of yours mapped to nothing yet: {cand})" if free else lines


def match_skeleton(skel: BvhSkeleton, offsets: np.ndarray, joint_map: str | Path | Mapping[str, Any] | None = None,
                   path: str | Path = "<skeleton>") -> SkeletonMatch:
    """Map ``skel`` onto SMPL-24 (precedence in the module doc).

    Args:
        skel: the source skeleton; offsets: ``(J, 3)`` rest bone vectors (for tree position).
        joint_map: a YAML file (see :func:`load_joint_map`) or an already loaded mapping.
        path: the motion file, for error messages.

    Raises:
        InputFileError: a joint map names a joint the skeleton lacks, the result misses a
            required joint, or a mapped joint is not below its SMPL parent's.
    """
    user: dict[str, Any] = {"joints": {}, "options": {}}
    map_src = None
    if joint_map is not None:
        if isinstance(joint_map, Mapping):
            user = {"joints": dict(joint_map.get("joints", {})), "options": dict(joint_map.get("options", {}))}
            map_src = "joint map"
        else:
            user = load_joint_map(joint_map)
            map_src = f"joint map {joint_map}"
        for k, v in user["joints"].items():
            if v is not None and v not in skel.names:
                raise InputFileError(path, f"the joint map maps {k} to {v!r}, which this skeleton does not have",
                                     f"one of its joints ({', '.join(skel.names[:12])}{'...' if skel.num_joints > 12 else ''})", field=f"joint {v}")
    builtin = builtin_match(skel)
    notes: list[str] = []
    if builtin is not None:
        joints = dict(builtin.joints)
        how = {k: "map" for k in joints}
        base, source = builtin, f"built-in {builtin.name}"
    else:
        joints, how, notes = auto_map(skel, offsets)
        base = SkeletonMap(name=str(user["options"].get("name", "auto")), joints={})
        source = "automatic"
    if user["joints"]:
        for k, v in user["joints"].items():
            if v is None:
                joints.pop(k, None)
                how.pop(k, None)
            else:
                joints[k] = v
                how[k] = "joint map"
        source = f"{source} + {map_src}"
        if builtin is not None:
            # Measured constants hold only for the built-in joints they were measured on.
            changed = {k for k, v in user["joints"].items() if builtin.joints.get(k) != v}
            seg = {"left_knee": "left_hip", "right_knee": "right_hip", "left_elbow": "left_shoulder", "right_elbow": "right_shoulder"}
            base = replace(base, hinge_axes={h: a for h, a in base.hinge_axes.items() if h not in changed and seg[h] not in changed},
                           mean_twist=tuple(j for j in base.mean_twist if j not in changed))
    missing = [n for n in REQUIRED_JOINTS if n not in joints]
    if missing:
        raise InputFileError(path, f"no joint found for SMPL {', '.join(missing)} (skeleton root {skel.names[0]!r}, {skel.num_joints} joints)",
                             "a skeleton whose leg joints are named (thigh/upleg, shin/calf/leg, foot/ankle with a left/right mark), "
                             f"or a --joint-map YAML file with the lines {_missing_lines(missing, skel, joints)} "
                             "(see docs/motion-import.md)", field=f"joint {missing[0]}")
    for n, anc in _check_tree(joints, skel):
        if user["joints"].get(n) or user["joints"].get(anc):
            raise InputFileError(path, f"joint map: {joints[n]} (SMPL {n}) is not below {joints[anc]} (SMPL {anc})",
                                 "mapped joints in the same parent-child order as SMPL's tree", field=f"joint {joints[n]}")
        notes.append(f"{n} ({joints[n]}) is not below {anc} ({joints[anc]}): left unmapped")
        joints.pop(n)
        how.pop(n, None)
    feet = tuple(joints[k] for k in ("left_ankle", "right_ankle", "left_foot", "right_foot") if k in joints)
    smap = replace(base, joints=joints, foot_joints=base.foot_joints if builtin is not None and not user["joints"] else feet)
    return SkeletonMatch(smap, source, how, notes, dict(user["options"]))
