"""Procedural motion families the corpus lacks: squat, kneel, pick up from the floor, sit down and
stand up, lie down and get up, crawl, reach high.

Each clip is built from keyframed *postures* (:class:`Posture`: a few anatomical angles, degrees)
on the body, interpolated with a cosine ease (every angle's velocity is zero at each key, so
nothing jumps), and placed physically on the floor:

- **vertical**: every frame the lowest vertex of the posed mesh (full linear blend skinning,
  pose correctives included) is put on the floor ``y = 0``; nobody in these families leaves the
  ground, so this is where gravity would put them;
- **horizontal**: the parts the family rests on (``contacts`` of each phase: feet, knees, hands,
  pelvis, back) do not slide: the root's horizontal travel cancels the mean horizontal velocity of
  the phase's anchor joints (:data:`CONTACT_ANCHORS`), so a single resting part is exactly still
  and several resting parts move only by what the posture's own geometry makes them disagree by;
- **two-part contacts** (a knee and the other foot, hands and feet, buttocks and feet) are made to
  touch the floor together by solving one angle of the key posture by bisection on the posed
  mesh (:func:`solve_gap`).

Variation, all drawn from one ``torch.Generator``: timing (hold and transition durations,
repetitions), depth, arm posture, side, heading (a yaw of the whole clip), body shape (``betas``
the asset's adult shape space, :func:`wearpose.body.shapes.sample_betas`; ``body_shape=False``
keeps the mean body).

PIP's synthetic sitting (:mod:`wearpose.estimators.pip.sitting`) is a special case of family
``sit``: the same seated postures (hip flexion 75-100 deg, shanks vertical, trunk lean while
sitting down and standing up), here on any body shape, with the whole mesh on the floor and the
feet still. The PIP clips that trained the shipped weights stay as they are (their seeds and
cache); new training data should draw from here.

Seeds: a clip is named ``procedural/<family>/<namespace>/<index>`` and its generator is seeded
from that name and a base seed (:func:`procedural_seed`); the namespaces are ``train`` and
``val`` for training data and ``eval`` for held-out evaluation sets (the ``"eval"`` namespace the
estimators' evaluation simulations use), so a held-out clip is never drawn for training.

Frames as :mod:`wearpose.motion.sequence`: SMPL local rotations, Y up, at zero heading the body
faces +Z with its left at +X.
"""

from __future__ import annotations

import math
import zlib
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any

import torch

from wearpose.body.kinematics import forward_kinematics
from wearpose.body.shapes import sample_betas
from wearpose.body.skeleton import JOINT_INDEX, JOINT_NAMES, NUM_JOINTS
from wearpose.errors import ConfigError
from wearpose.geometry import matrix_to_axis_angle, rotation_between, rotation_x, rotation_y, rotation_z
from wearpose.motion.sequence import NUM_BETAS, MotionSequence

#: The families, in the order the docs list them.
FAMILIES: tuple[str, ...] = ("squat", "kneel", "pickup", "sit", "lie", "crawl", "reach")
#: Seed namespaces: training, validation and held-out evaluation draws.
NAMESPACES: tuple[str, ...] = ("train", "val", "eval")
#: Clip-id prefix of every procedural clip.
PREFIX = "procedural/"

#: Resting parts: the SMPL joints whose vertices (by dominant skinning weight) make up each part.
CONTACT_PARTS: dict[str, tuple[int, ...]] = {
    **{f"{s}_foot": (JOINT_INDEX[f"{s}_ankle"], JOINT_INDEX[f"{s}_foot"]) for s in ("left", "right")},
    **{f"{s}_knee": (JOINT_INDEX[f"{s}_hip"], JOINT_INDEX[f"{s}_knee"]) for s in ("left", "right")},
    **{f"{s}_hand": (JOINT_INDEX[f"{s}_wrist"], JOINT_INDEX[f"{s}_hand"]) for s in ("left", "right")},
    "pelvis": (JOINT_INDEX["pelvis"], JOINT_INDEX["left_hip"], JOINT_INDEX["right_hip"]),
    "back": (JOINT_INDEX["spine1"], JOINT_INDEX["spine2"], JOINT_INDEX["spine3"]),
}
#: The joint that stays still while each part rests (foot: the ball of the foot, so a heel may
#: lift; knee: the knee; hand: the wrist; pelvis: the pelvis; back: the chest).
CONTACT_ANCHORS: dict[str, int] = {
    **{f"{s}_foot": JOINT_INDEX[f"{s}_foot"] for s in ("left", "right")},
    **{f"{s}_knee": JOINT_INDEX[f"{s}_knee"] for s in ("left", "right")},
    **{f"{s}_hand": JOINT_INDEX[f"{s}_wrist"] for s in ("left", "right")},
    "pelvis": JOINT_INDEX["pelvis"], "back": JOINT_INDEX["spine3"],
}
FEET = ("left_foot", "right_foot")

#: Largest rotation (deg) of each joint's local rotation that the families may reach: human
#: ranges of motion, rounded up (knee flexion 150, hip flexion 130 ...). Knees and elbows are
#: hinges: they bend one way only, about X (knees, +) and Y (elbows: left -, right +).
JOINT_LIMITS_DEG: dict[str, float] = {
    "pelvis": 180.0, "left_hip": 135.0, "right_hip": 135.0, "spine1": 30.0, "left_knee": 150.0,
    "right_knee": 150.0, "spine2": 30.0, "left_ankle": 50.0, "right_ankle": 50.0, "spine3": 30.0,
    "left_foot": 70.0, "right_foot": 70.0, "neck": 45.0, "left_collar": 20.0, "right_collar": 20.0,
    "head": 45.0, "left_shoulder": 180.0, "right_shoulder": 180.0, "left_elbow": 150.0, "right_elbow": 150.0,
    "left_wrist": 60.0, "right_wrist": 60.0, "left_hand": 30.0, "right_hand": 30.0,
}
HINGES: dict[str, tuple[int, float]] = {  # joint -> (axis index, sign of flexion)
    "left_knee": (0, 1.0), "right_knee": (0, 1.0), "left_elbow": (1, -1.0), "right_elbow": (1, 1.0),
}


def procedural_seed(family: str, index: int, seed: int = 0, namespace: str = "train") -> int:
    """Generator seed of clip ``index`` of ``family`` in ``namespace`` (:data:`NAMESPACES`)."""
    _check(family, namespace)
    return (zlib.crc32(f"procedural:{namespace}:{clip_id(family, namespace, index)}".encode())
            + 7919 * int(seed)) % (2 ** 31 - 1)


def clip_id(family: str, namespace: str, index: int) -> str:
    """``procedural/<family>/<namespace>/<index:04d>``."""
    return f"{PREFIX}{family}/{namespace}/{int(index):04d}"


def _check(family: str, namespace: str = "train") -> None:
    if family not in FAMILIES:
        raise ConfigError(f"procedural motion: unknown family {family!r}; expected one of {', '.join(FAMILIES)}")
    if namespace not in NAMESPACES:
        raise ConfigError(f"procedural motion: unknown seed namespace {namespace!r}; expected one of {', '.join(NAMESPACES)}")


# ---------------------------------------------------------------------------------------- postures
@dataclass(frozen=True)
class Posture:
    """A body posture by anatomical angles, degrees (SMPL frames, facing +Z before heading).

    Trunk: ``pelvis_pitch`` forward lean of the pelvis (+ forward, -90 = lying on the back),
    ``pelvis_twist`` about the trunk's long axis, ``spine_flex`` (+ forward, spread over spine1-3;
    ``spine_twist`` likewise), ``neck_flex`` (+ chin down, shared by neck and head).
    Legs, ``l_``/``r_``: ``thigh`` forward angle of the thigh from hanging straight down (world
    sagittal plane: 90 = horizontal forward), ``shank`` the shank's angle with the ankle behind the
    knee (+; 90 = shin flat on the floor behind the knee), ``foot`` pitch of the foot, toes down
    (+; 0 = flat), ``toe`` bend of the toes (+ up), ``abd`` abduction, ``out`` toe-out about the
    vertical. Knee flexion is ``thigh + shank``; the ankle takes whatever puts the foot at
    ``foot``. Arms, ``l_``/``r_``: ``raise`` from hanging (0) to overhead (180) in the chest frame,
    ``plane`` 0 forward .. 90 sideways, ``elbow`` flexion.
    """

    pelvis_pitch: float = 0.0
    pelvis_twist: float = 0.0
    spine_flex: float = 0.0
    spine_twist: float = 0.0
    neck_flex: float = 0.0
    l_thigh: float = 0.0
    r_thigh: float = 0.0
    l_shank: float = 0.0
    r_shank: float = 0.0
    l_foot: float = 0.0
    r_foot: float = 0.0
    l_toe: float = 0.0
    r_toe: float = 0.0
    l_abd: float = 0.0
    r_abd: float = 0.0
    l_out: float = 0.0
    r_out: float = 0.0
    l_raise: float = 10.0
    r_raise: float = 10.0
    l_plane: float = 60.0
    r_plane: float = 60.0
    l_elbow: float = 10.0
    r_elbow: float = 10.0

    def with_(self, **kw: float) -> Posture:
        """A copy with the given angles; ``leg_<x>`` / ``arm_<x>`` set both sides."""
        out: dict[str, float] = {}
        for k, v in kw.items():
            if k.startswith("both_"):
                out[f"l_{k[5:]}"] = out[f"r_{k[5:]}"] = float(v)
            else:
                out[k] = float(v)
        return replace(self, **out)


PARAMS: tuple[str, ...] = tuple(Posture.__dataclass_fields__)


def lerp(a: Posture, b: Posture, x: float) -> Posture:
    """The posture a fraction ``x`` of the way from ``a`` to ``b`` (every angle linearly)."""
    return Posture(**{k: getattr(a, k) + (getattr(b, k) - getattr(a, k)) * x for k in PARAMS})


def _rad(x: torch.Tensor) -> torch.Tensor:
    return x * (math.pi / 180.0)


def posture_matrices(p: dict[str, torch.Tensor], heading_deg: float = 0.0) -> torch.Tensor:
    """Local joint rotations ``(T, 24, 3, 3)`` float64 of postures given as ``(T,)`` angle tensors
    (degrees, keys :data:`PARAMS`, see :class:`Posture`), the whole body turned by ``heading_deg``
    about +Y."""
    T = p["pelvis_pitch"].shape[0]
    R = torch.eye(3, dtype=torch.float64).repeat(T, NUM_JOINTS, 1, 1)
    head = rotation_y(torch.full((T,), math.radians(heading_deg), dtype=torch.float64))
    root = head @ rotation_x(_rad(p["pelvis_pitch"])) @ rotation_y(_rad(p["pelvis_twist"]))
    R[:, 0] = root
    for name in ("spine1", "spine2", "spine3"):
        R[:, JOINT_INDEX[name]] = rotation_x(_rad(p["spine_flex"] / 3)) @ rotation_y(_rad(p["spine_twist"] / 3))
    for name in ("neck", "head"):
        R[:, JOINT_INDEX[name]] = rotation_x(_rad(p["neck_flex"] / 2))
    # the legs' angles are world-sagittal with the heading removed: relative to root orientation
    # without its pitch and twist (frame "H" = heading only)
    root_in_h = head.transpose(-1, -2) @ root
    for side, s in (("left", 1.0), ("right", -1.0)):
        k = side[0]
        G_t = (rotation_y(_rad(s * p[f"{k}_out"])) @ rotation_z(_rad(s * p[f"{k}_abd"]))
               @ rotation_x(_rad(-p[f"{k}_thigh"])))
        R[:, JOINT_INDEX[f"{side}_hip"]] = root_in_h.transpose(-1, -2) @ G_t
        knee = rotation_x(_rad(p[f"{k}_thigh"] + p[f"{k}_shank"]))
        R[:, JOINT_INDEX[f"{side}_knee"]] = knee
        G_f = rotation_y(_rad(s * p[f"{k}_out"])) @ rotation_x(_rad(p[f"{k}_foot"]))
        R[:, JOINT_INDEX[f"{side}_ankle"]] = (G_t @ knee).transpose(-1, -2) @ G_f
        R[:, JOINT_INDEX[f"{side}_foot"]] = rotation_x(_rad(-p[f"{k}_toe"]))
        r, pl = _rad(p[f"{k}_raise"]), _rad(p[f"{k}_plane"])
        d = torch.stack([s * torch.sin(r) * torch.sin(pl), -torch.cos(r), torch.sin(r) * torch.cos(pl)], -1)
        a = torch.tensor([s, 0.0, 0.0], dtype=torch.float64).expand_as(d)
        R[:, JOINT_INDEX[f"{side}_shoulder"]] = rotation_between(a, d)  # collars identity: chest frame
        R[:, JOINT_INDEX[f"{side}_elbow"]] = rotation_y(_rad(-s * p[f"{k}_elbow"]))
    return R


def _stack(postures: list[Posture]) -> dict[str, torch.Tensor]:
    return {k: torch.tensor([getattr(q, k) for q in postures], dtype=torch.float64) for k in PARAMS}


# ---------------------------------------------------------------------------------------- timeline
@dataclass
class Phase:
    """One stretch of a clip: ease from the previous posture to ``target`` over ``frames``
    (a hold when ``target`` is the previous one), resting on ``contacts``."""

    name: str
    target: Posture
    frames: int
    contacts: tuple[str, ...]


@dataclass
class Plan:
    """A family's clip before placement: phases, heading, body shape, per-frame overrides."""

    family: str
    start: Posture
    phases: list[Phase]
    heading_deg: float
    betas: torch.Tensor
    sway: bool = True
    params: dict[str, Any] = field(default_factory=dict)  # drawn settings, recorded in meta
    overlay: Callable[[dict[str, torch.Tensor], float], None] | None = None  # in-place per-frame edit
    anchor_weights: Callable[[torch.Tensor], None] | None = None  # in-place edit of the (T, 24) weights
    keep_feet_width: bool = True  # legs moving alike: hold the distance between the feet (see place)


def _ease(n: int) -> torch.Tensor:
    """``(n,)`` from just above 0 to 1 with zero slope at both ends (cosine ease)."""
    u = torch.arange(1, n + 1, dtype=torch.float64) / n
    return 0.5 - 0.5 * torch.cos(math.pi * u)


def timeline(plan: Plan) -> tuple[dict[str, torch.Tensor], list[tuple[str, int, int, tuple[str, ...]]]]:
    """Per-frame angles ``(T,)`` (degrees) and segments ``(name, first, frames, contacts)``:
    the start posture's frame, then each phase eased from the previous posture."""
    first = _stack([plan.start])
    parts = {k: [first[k]] for k in PARAMS}
    segs: list[tuple[str, int, int, tuple[str, ...]]] = []
    prev, at = plan.start, 1
    for ph in plan.phases:
        s = _ease(ph.frames)
        for k in PARAMS:
            a, b = getattr(prev, k), getattr(ph.target, k)
            parts[k].append(a + (b - a) * s)
        segs.append((ph.name, at, ph.frames, ph.contacts))
        at += ph.frames
        prev = ph.target
    # the start frame belongs to the first phase
    name, _, n, c = segs[0]
    segs[0] = (name, 0, n + 1, c)
    return {k: torch.cat(v) for k, v in parts.items()}, segs


# ---------------------------------------------------------------------------------------- placement
class _Skin:
    """Lowest vertex per frame, of the whole mesh and of each contact part (posed, trans 0).

    Only the vertices' heights are needed, so the skinning is done for the y row alone:
    ``y_v = sum_j w_vj (G_j[1] . v_v + t_j[1])`` over every vertex (exact linear blend skinning;
    a body with pose correctives goes through the full :meth:`BodyModel.forward`)."""

    def __init__(self, body: Any, betas: torch.Tensor) -> None:
        self.body, self.betas = body, betas.to(body.dtype)
        part = body.weights.argmax(1)
        self.masks = {n: torch.isin(part, torch.tensor(js, device=part.device)) for n, js in CONTACT_PARTS.items()}
        self.v = (body.v_template + torch.einsum("vcs,s->vc", body.shapedirs, self.betas)).double()  # (V, 3)
        self.J_rest = body.rest_joints(self.betas).double()  # (24, 3)
        self.w = body.weights.double()  # (V, 24)
        self.wv = (self.w[:, :, None] * self.v[:, None, :]).reshape(self.v.shape[0], -1)  # (V, 72): w_vj v_v

    def heights(self, pose: torch.Tensor, chunk: int = 512) -> torch.Tensor:
        """``(T, V)`` vertex heights, m, for local rotations ``pose`` ``(T, 24, 3, 3)`` (trans 0)."""
        out = []
        with torch.no_grad():
            for a in range(0, pose.shape[0], chunk):
                R = pose[a:a + chunk].double()
                if getattr(self.body, "has_posedirs", False):
                    o = self.body(R.to(self.body.dtype), self.betas, return_normals=False)
                    out.append(o.vertices[..., 1].double())
                    continue
                G, J = forward_kinematics(R, self.J_rest.expand(R.shape[0], -1, -1), self.body.parents)
                row = G[:, :, 1, :]  # (N, 24, 3)
                ty = J[..., 1] - (row * self.J_rest).sum(-1)  # (N, 24): y of each joint's skinning shift
                # one matrix product: y = sum_j w_vj (row_j . v_v) + sum_j w_vj ty_j
                out.append(row.reshape(R.shape[0], -1) @ self.wv.T + ty @ self.w.T)  # (N, V)
        return torch.cat(out)

    def lowest(self, pose: torch.Tensor) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
        """``pose`` ``(T, 24, 3, 3)`` -> ``(T,)`` lowest y of the mesh and ``{part: (T,)}``, m."""
        y = self.heights(pose)
        return y.amin(-1), {n: y[:, m].amin(-1) for n, m in self.masks.items()}


def solve_gap(skin: _Skin, make: Callable[[float], Posture], lo: float, hi: float, part_a: tuple[str, ...],
              part_b: tuple[str, ...], gap: float = 0.0, iters: int = 22) -> tuple[float, Posture]:
    """Bisection for the ``x`` in ``[lo, hi]`` at which ``make(x)``'s lowest point of parts
    ``part_a`` sits ``gap`` metres above that of ``part_b`` (``f(x) = low_a - low_b - gap`` must
    change sign over the interval; the end nearer zero is taken if it does not)."""

    def f(x: float) -> float:
        _, parts = skin.lowest(posture_matrices(_stack([make(x)])))
        return float(min(parts[n][0] for n in part_a) - min(parts[n][0] for n in part_b) - gap)

    fl, fh = f(lo), f(hi)
    if fl * fh > 0:
        x = lo if abs(fl) < abs(fh) else hi
        return x, make(x)
    for _ in range(iters):
        mid = 0.5 * (lo + hi)
        fm = f(mid)
        if fm * fl > 0:
            lo, fl = mid, fm
        else:
            hi = mid
    x = 0.5 * (lo + hi)
    return x, make(x)


def _feet_width(p: dict[str, torch.Tensor], heading: float, body: Any, betas: torch.Tensor) -> torch.Tensor:
    """``(T,)`` horizontal distance (m) between the balls of the two feet for angles ``p``."""
    with torch.no_grad():
        J = body(posture_matrices(p, heading).to(body.dtype), betas.to(body.dtype), return_vertices=False).joints
    d = (J[:, JOINT_INDEX["left_foot"]] - J[:, JOINT_INDEX["right_foot"]]).double()
    return d[:, [0, 2]].norm(dim=-1)


def keep_feet_width(p: dict[str, torch.Tensor], heading: float, body: Any, betas: torch.Tensor,
                    mask: torch.Tensor | None = None, iters: int = 6) -> None:
    """In place on angles ``p`` (``(T,)`` each): add the same abduction to both hips, per frame,
    so the feet stay as far apart as in frame 0. Flexing turned-out, abducted legs moves the feet
    sideways (the knees travel over the toes); feet that rest on the floor cannot, so the hips
    give (secant steps on the abduction). ``mask`` ``(T,)`` bool: the frames whose feet both rest
    (default all); between two such stretches the correction is eased from one end's to the
    other's (to 0 where the clip starts or ends without resting feet)."""
    T = p["l_abd"].shape[0]
    mask = torch.ones(T, dtype=torch.bool) if mask is None else mask
    target = _feet_width(p, heading, body, betas)[0]
    base_l, base_r = p["l_abd"].clone(), p["r_abd"].clone()

    def f(delta: torch.Tensor) -> torch.Tensor:
        q = dict(p, l_abd=base_l + delta, r_abd=base_r + delta)
        return _feet_width(q, heading, body, betas) - target

    x0, x1 = torch.zeros(T, dtype=torch.float64), torch.ones(T, dtype=torch.float64)
    f0, f1 = f(x0), f(x1)
    for _ in range(iters):
        den = f1 - f0
        safe = den.abs() > 1e-12
        x2 = torch.where(safe, x1 - f1 * (x1 - x0) / torch.where(safe, den, torch.ones_like(den)), x1)
        x0, f0, x1 = x1, f1, x2.clamp(-20.0, 20.0)
        f1 = f(x1)
    mask = mask & (f1.abs() < 0.005)  # where the secant did not converge, ease across as between stretches
    d = torch.where(mask, x1, torch.zeros_like(x1))
    t = 0
    while t < T:  # ease across each run of frames without resting feet
        if mask[t]:
            t += 1
            continue
        e = t
        while e < T and not mask[e]:
            e += 1
        a = float(d[t - 1]) if t > 0 else 0.0
        b = float(d[e]) if e < T else 0.0
        u = torch.arange(1, e - t + 1, dtype=torch.float64) / (e - t + 1)
        d[t:e] = a + (b - a) * (0.5 - 0.5 * torch.cos(math.pi * u))
        t = e
    p["l_abd"], p["r_abd"] = base_l + d, base_r + d


def _sway(g: torch.Generator, p: dict[str, torch.Tensor], fps: float, arms: bool) -> None:
    """In place: slow small angle sway (< 1.5 deg, 0.1-0.5 Hz) of the neck, and of the trunk and
    arms unless the hands rest on the floor (``arms`` False): people do not hold perfectly still."""
    T = p["pelvis_pitch"].shape[0]
    t = torch.arange(T, dtype=torch.float64) / fps
    names = ["neck_flex"] + (["spine_flex", "spine_twist", "l_raise", "r_raise", "l_elbow", "r_elbow"] if arms else [])
    for k in names:
        f = 0.1 + 0.4 * float(torch.rand((), generator=g))
        ph = 2 * math.pi * float(torch.rand((), generator=g))
        amp = 1.5 * float(torch.rand((), generator=g))
        p[k] = p[k] + amp * torch.sin(2 * math.pi * f * t + ph)
    for k in ("l_elbow", "r_elbow"):  # a hinge: sway never bends it backwards
        p[k] = p[k].clamp_min(0.0)


def place(plan: Plan, body: Any, fps: float, g: torch.Generator) -> MotionSequence:
    """Pose, sway and place ``plan`` on the floor (module doc) -> a :class:`MotionSequence`.

    ``meta``: ``clip``, ``family``, ``segments`` ``[(name, first, frames, [contacts])]``,
    ``params`` (the drawn settings), ``heading_deg``, ``source_format`` ``"procedural"``."""
    p, segs = timeline(plan)
    if plan.overlay is not None:
        plan.overlay(p, fps)
    if plan.sway:
        arms_rest = not any("hand" in c for s in segs for c in s[3])
        _sway(g, p, fps, arms_rest)
    if plan.keep_feet_width:
        mask = torch.zeros(p["l_abd"].shape[0], dtype=torch.bool)
        for _, first, n, contacts in segs:
            # standing on the feet only: a seat (feet and buttocks) keeps its solved legs
            mask[first:first + n] = set(FEET) <= set(contacts) and "pelvis" not in contacts
        keep_feet_width(p, plan.heading_deg, body, plan.betas, mask)
    pose = posture_matrices(p, plan.heading_deg)
    T = pose.shape[0]
    skin = _Skin(body, plan.betas)
    low, _ = skin.lowest(pose)
    with torch.no_grad():
        J = body(pose.to(body.dtype), plan.betas.to(body.dtype), return_vertices=False).joints.double()  # (T, 24, 3)
    w = torch.zeros(T, NUM_JOINTS, dtype=torch.float64)
    for _, first, n, contacts in segs:
        for c in contacts:
            w[first:first + n, CONTACT_ANCHORS[c]] += 1.0
    if plan.anchor_weights is not None:
        plan.anchor_weights(w)
    w = w / w.sum(1, keepdim=True).clamp_min(1e-9)
    anchor = (w[:, :, None] * J).sum(1)  # weighted anchor position per frame, trans 0
    step = torch.zeros(T, 3, dtype=torch.float64)
    # frame t's anchor set moves by (J[t] - J[t-1]); the root moves the opposite way
    step[1:] = -((w[1:, :, None] * (J[1:] - J[:-1])).sum(1))
    trans = torch.cumsum(step, 0)
    trans = trans - torch.tensor([anchor[0, 0], 0.0, anchor[0, 2]], dtype=torch.float64)
    trans[:, 1] = -low
    meta = {"clip": f"{PREFIX}{plan.family}", "family": plan.family, "source_format": "procedural",
            "segments": [[s[0], s[1], s[2], list(s[3])] for s in segs], "params": plan.params,
            "heading_deg": plan.heading_deg, "licence": "generated by wearpose (no restriction)"}
    return MotionSequence(pose.float(), plan.betas.float(), trans.float(), fps, meta)


# ---------------------------------------------------------------------------------------- families
def _u(g: torch.Generator, lo: float, hi: float) -> float:
    return lo + (hi - lo) * float(torch.rand((), generator=g, dtype=torch.float64))


def _n(g: torch.Generator, fps: float, lo: float, hi: float) -> int:
    """Frames of a duration drawn in ``[lo, hi]`` seconds (at least 2)."""
    return max(2, int(round(_u(g, lo, hi) * fps)))


def _arms(g: torch.Generator, base: Posture, raise_=(0.0, 40.0), plane=(0.0, 80.0), elbow=(0.0, 90.0),
          symmetric: float = 0.5) -> Posture:
    """``base`` with a random arm posture (both arms alike with probability ``symmetric``)."""
    a = {"l_raise": _u(g, *raise_), "l_plane": _u(g, *plane), "l_elbow": _u(g, *elbow)}
    if _u(g, 0, 1) < symmetric:
        b = {"r_" + k[2:]: v for k, v in a.items()}
    else:
        b = {"r_raise": _u(g, *raise_), "r_plane": _u(g, *plane), "r_elbow": _u(g, *elbow)}
    return base.with_(**a, **b)


def _stance(g: torch.Generator) -> Posture:
    """A random relaxed standing posture: feet a little apart and turned out, arms hanging."""
    abd, out = _u(g, 2.0, 8.0), _u(g, 3.0, 15.0)
    return _arms(g, Posture(), raise_=(3.0, 25.0), plane=(10.0, 80.0), elbow=(0.0, 40.0)).with_(
        both_abd=abd, both_out=out, spine_flex=_u(g, -3.0, 5.0), neck_flex=_u(g, -5.0, 10.0))


def _squat(g: torch.Generator, body: Any, skin: _Skin, fps: float, stand: Posture) -> tuple[Posture, list[Phase], dict[str, Any]]:
    """Squat down to a random depth (knees 57-140 deg, heels down, arms forward or free), hold, up; 1-3 times."""
    depth = _u(g, 0.2, 1.0)
    stand = stand.with_(both_abd=_u(g, 6.0, 16.0), both_out=_u(g, 10.0, 30.0))
    bottom = _arms(g, stand, raise_=(10.0, 90.0), plane=(0.0, 30.0), elbow=(0.0, 80.0), symmetric=0.8).with_(
        both_thigh=40.0 + 60.0 * depth, both_shank=10.0 + 28.0 * depth,
        pelvis_pitch=10.0 + 30.0 * depth * _u(g, 0.7, 1.0), spine_flex=_u(g, 0.0, 15.0), neck_flex=_u(g, -10.0, 10.0))
    phases = [Phase("stand", stand, _n(g, fps, 0.5, 1.5), FEET)]
    reps = int(_u(g, 1.0, 4.0))
    for _ in range(reps):
        phases += [Phase("down", bottom, _n(g, fps, 0.7, 2.0), FEET), Phase("hold", bottom, _n(g, fps, 0.1, 2.5), FEET),
                   Phase("up", stand, _n(g, fps, 0.7, 2.0), FEET), Phase("stand", stand, _n(g, fps, 0.3, 1.5), FEET)]
    return stand, phases, {"depth": depth, "repetitions": reps}


def _kneel(g: torch.Generator, body: Any, skin: _Skin, fps: float, stand: Posture) -> tuple[Posture, list[Phase], dict[str, Any]]:
    """Step back and go down on one knee (toes tucked under), maybe the other knee too, and back up."""
    side = "l" if _u(g, 0, 1) < 0.5 else "r"  # the leg that kneels
    o = "r" if side == "l" else "l"
    S, F = ("left" if side == "l" else "right"), ("right" if side == "l" else "left")
    both = _u(g, 0, 1) < 0.4
    stand = stand.with_(both_abd=_u(g, 2.0, 6.0))
    back_thigh, dorsi, toe, knee_over = _u(g, -15.0, 0.0), _u(g, 0.0, 20.0), _u(g, 45.0, 65.0), _u(g, -5.0, 10.0)
    arms = _arms(g, stand, raise_=(5.0, 45.0), plane=(0.0, 60.0), elbow=(0.0, 100.0))
    trunk = {"pelvis_pitch": _u(g, -2.0, 10.0), "spine_flex": _u(g, 0.0, 10.0)}

    def back_leg(k: str, shank: float) -> dict[str, float]:
        # toes tucked under: the foot about square to the shin (ankle dorsiflexed ``dorsi``), toes bent up
        return {f"{k}_thigh": back_thigh, f"{k}_shank": shank, f"{k}_foot": shank - dorsi, f"{k}_toe": toe, f"{k}_abd": 2.0}

    # the kneeling leg: shin tilted so that knee and toes both touch the floor
    shank, _ = solve_gap(skin, lambda x: arms.with_(**back_leg(side, x), **trunk), 80.0, 140.0,
                         (f"{S}_foot",), (f"{S}_knee",))
    # the front leg: thigh angle that puts its foot on the floor with the kneeling knee
    x, kneel1 = solve_gap(skin, lambda x: arms.with_(**back_leg(side, shank), **trunk, **{
        f"{o}_thigh": x, f"{o}_shank": 90.0 - x + knee_over, f"{o}_abd": 8.0}), 40.0, 115.0, (f"{F}_foot",), (f"{S}_knee",))
    step = arms.with_(**{f"{side}_thigh": -20.0, f"{side}_shank": 45.0, f"{side}_foot": 20.0,
                         f"{o}_thigh": 25.0, f"{o}_shank": 10.0})
    rest = (f"{S}_knee", f"{S}_foot")
    phases = [Phase("stand", stand, _n(g, fps, 0.5, 1.5), FEET),
              Phase("step back", step, _n(g, fps, 0.5, 1.0), (f"{F}_foot",)),
              Phase("down", kneel1, _n(g, fps, 0.6, 1.2), (f"{F}_foot",)),
              Phase("kneel", kneel1, _n(g, fps, 0.5, 4.0), (f"{F}_foot", *rest))]
    if both:
        kneel2 = kneel1.with_(**back_leg(o, shank))
        # the front foot swings back above the floor: lift it behind, bring the knee under the hip
        lift = kneel1.with_(**{f"{o}_shank": 45.0, f"{o}_foot": 15.0})
        tuck = kneel1.with_(**{f"{o}_thigh": 25.0, f"{o}_shank": 120.0, f"{o}_foot": 120.0 - dorsi, f"{o}_toe": toe,
                               f"{o}_abd": 2.0})
        phases += [Phase("lift foot", lift, _n(g, fps, 0.3, 0.6), rest), Phase("knee under", tuck, _n(g, fps, 0.3, 0.6), rest),
                   Phase("other knee down", kneel2, _n(g, fps, 0.3, 0.8), rest),
                   Phase("kneel both", kneel2, _n(g, fps, 0.5, 4.0), (*rest, f"{F}_knee", f"{F}_foot")),
                   Phase("other knee up", tuck, _n(g, fps, 0.3, 0.8), rest), Phase("knee forward", lift, _n(g, fps, 0.3, 0.6), rest),
                   Phase("foot down", kneel1, _n(g, fps, 0.3, 0.6), rest),
                   Phase("kneel", kneel1, _n(g, fps, 0.2, 0.8), (f"{F}_foot", *rest))]
    phases += [Phase("up", step, _n(g, fps, 0.6, 1.2), (f"{F}_foot",)),
               Phase("step in", stand, _n(g, fps, 0.5, 1.0), (f"{F}_foot",)),
               Phase("stand", stand, _n(g, fps, 0.5, 1.5), FEET)]
    return stand, phases, {"side": S, "both_knees": both, "front_thigh_deg": x, "back_shank_deg": shank}


def _pickup(g: torch.Generator, body: Any, skin: _Skin, fps: float, stand: Posture) -> tuple[Posture, list[Phase], dict[str, Any]]:
    """Reach down to the floor with one or both hands (from a stoop to a squat pick), lift, maybe put it back."""
    stoop = _u(g, 0.0, 1.0)  # 1: straight-ish legs, trunk bent; 0: a squat pick
    hands = "both" if _u(g, 0, 1) < 0.5 else ("left" if _u(g, 0, 1) < 0.5 else "right")
    stand = stand.with_(both_abd=_u(g, 4.0, 12.0), both_out=_u(g, 5.0, 25.0))
    knee = (1 - stoop) * 100.0 + stoop * _u(g, 10.0, 35.0)  # deep knee bend of a squat pick .. a stoop's
    trunk = (1 - stoop) * 45.0 + stoop * 95.0  # pelvis pitch + spine flex at full reach
    plane = _u(g, 0.0, 25.0)

    def reach(x: float) -> Posture:  # x in [0, 1]: how far down
        t = trunk * x
        q = stand.with_(both_thigh=knee * 0.6 * x, both_shank=knee * 0.4 * x, pelvis_pitch=0.7 * t,
                        spine_flex=min(0.3 * t, 29.0), neck_flex=-10.0 * x)
        arm = {"raise": t + 10.0 * x, "plane": plane, "elbow": 5.0}
        for k in ("l", "r"):
            if hands in ("both", "left" if k == "l" else "right"):
                q = q.with_(**{f"{k}_{a}": v for a, v in arm.items()})
        return q

    used = tuple(f"{s}_hand" for s in ("left", "right") if hands in ("both", s))
    x, low = solve_gap(skin, reach, 0.2, 1.6, used, FEET, gap=0.003)  # hands touch, feet stay lowest
    up = stand.with_(**{f"{k}_{a}": v for k in ("l", "r") if hands in ("both", "left" if k == "l" else "right")
                        for a, v in (("raise", _u(g, 20.0, 50.0)), ("plane", plane), ("elbow", _u(g, 60.0, 100.0)))})
    phases = [Phase("stand", stand, _n(g, fps, 0.5, 1.5), FEET),
              Phase("reach down", low, _n(g, fps, 0.8, 2.0), FEET),
              Phase("grasp", low, _n(g, fps, 0.2, 1.0), (*FEET, *used)),
              Phase("lift", up, _n(g, fps, 0.8, 2.0), FEET),
              Phase("hold", up, _n(g, fps, 0.5, 2.0), FEET)]
    if _u(g, 0, 1) < 0.6:  # put it back down
        phases += [Phase("put down", low, _n(g, fps, 0.8, 2.0), FEET), Phase("release", low, _n(g, fps, 0.2, 0.6), (*FEET, *used)),
                   Phase("stand up", stand, _n(g, fps, 0.8, 2.0), FEET), Phase("stand", stand, _n(g, fps, 0.3, 1.0), FEET)]
    return stand, phases, {"stoop": stoop, "hands": hands, "reach": x}


def _sit(g: torch.Generator, body: Any, skin: _Skin, fps: float, stand: Posture) -> tuple[Posture, list[Phase], dict[str, Any]]:
    """Sit down on an invisible chair (PIP's seated postures: hip 75-100 deg, shanks near vertical) leaning forward, sit, stand up; 1-2 times."""
    hip = _u(g, 75.0, 100.0)  # PIP's seated hip flexion; shanks vertical
    stand = _arms(g, stand, raise_=(0.0, 50.0), plane=(0.0, 40.0), elbow=(0.0, 90.0))
    seat = stand.with_(both_thigh=hip, both_shank=_u(g, -5.0, 10.0), pelvis_pitch=_u(g, -8.0, 5.0))
    lean = stand.with_(both_thigh=0.5 * hip + 10.0, both_shank=_u(g, 8.0, 20.0), pelvis_pitch=_u(g, 20.0, 40.0),
                       spine_flex=_u(g, 5.0, 20.0), neck_flex=-_u(g, 5.0, 15.0))
    phases = [Phase("stand", stand, _n(g, fps, 0.5, 3.0), FEET)]
    reps = int(_u(g, 1.0, 3.0))
    for _ in range(reps):
        phases += [Phase("lean", lean, _n(g, fps, 0.4, 1.0), FEET), Phase("down", seat, _n(g, fps, 0.4, 1.0), FEET),
                   Phase("sit", seat, _n(g, fps, 1.0, 8.0), FEET), Phase("lean", lean, _n(g, fps, 0.4, 1.0), FEET),
                   Phase("up", stand, _n(g, fps, 0.4, 1.0), FEET), Phase("stand", stand, _n(g, fps, 0.5, 3.0), FEET)]
    return stand, phases, {"hip_deg": hip, "repetitions": reps, "seat": "invisible chair, feet on the floor"}


def _lie(g: torch.Generator, body: Any, skin: _Skin, fps: float, stand: Posture) -> tuple[Posture, list[Phase], dict[str, Any]]:
    """Squat down, sit on the floor, lie back (legs out or knees up), and the same way back up."""
    stand = stand.with_(both_abd=_u(g, 3.0, 8.0), both_out=_u(g, 3.0, 15.0))
    squat = stand.with_(both_thigh=85.0, both_shank=32.0, pelvis_pitch=30.0, spine_flex=15.0,
                        both_raise=_u(g, 40.0, 80.0), both_plane=_u(g, 0.0, 30.0), both_elbow=_u(g, 10.0, 60.0))
    lean_back, thigh = _u(g, -25.0, -10.0), _u(g, 100.0, 125.0)
    seated = stand.with_(pelvis_pitch=lean_back, spine_flex=_u(g, 0.0, 15.0), both_thigh=thigh,
                         both_raise=_u(g, 45.0, 75.0), both_plane=_u(g, 0.0, 30.0), both_elbow=_u(g, 10.0, 60.0))  # hands off the floor

    def heel_down(x: float) -> dict[str, float]:  # shank x < 0: feet ahead of the knees; ankle <= 35 deg
        return {"both_shank": x, "both_foot": min(0.0, x + 35.0)}

    # the shank angle that puts buttocks and heels on the floor together
    _, sit = solve_gap(skin, lambda x: seated.with_(**heel_down(x)), -90.0, 0.0, FEET, ("pelvis",))
    # the buttocks touch down on the way from the squat to the seat: that posture ends a move of its
    # own (zero speed at the touch, a soft landing), the heels slide forward after it
    s_touch, touch = solve_gap(skin, lambda x: lerp(squat, sit, x), 0.0, 1.0, ("pelvis",), FEET, gap=0.002)
    knees_up = _u(g, 0, 1) < 0.5
    arms_lie = {"both_raise": _u(g, 5.0, 30.0), "both_plane": _u(g, 40.0, 90.0), "both_elbow": _u(g, 0.0, 30.0)} \
        if _u(g, 0, 1) < 0.7 else {"both_raise": _u(g, 150.0, 175.0), "both_plane": _u(g, 60.0, 90.0), "both_elbow": 10.0}
    lying = stand.with_(pelvis_pitch=-90.0, spine_flex=0.0, neck_flex=_u(g, -10.0, 10.0), **arms_lie)
    if knees_up:  # feet flat on the floor, knee flexion 80-110 deg
        knee = _u(g, 80.0, 110.0)
        _, lie = solve_gap(skin, lambda x: lying.with_(both_thigh=x, both_shank=knee - x, both_foot=min(0.0, knee - x + 35.0)),
                           100.0, 175.0, FEET, ("pelvis",))
    else:
        lie = lying.with_(both_thigh=90.0, both_shank=-90.0 + _u(g, 0.0, 5.0), both_foot=-90.0 + _u(g, 15.0, 40.0))
    rest = ("pelvis", *FEET) if knees_up else ("pelvis",)
    phases = [Phase("stand", stand, _n(g, fps, 0.5, 1.5), FEET),
              Phase("squat down", squat, _n(g, fps, 1.0, 2.0), FEET),
              Phase("sit down", touch, _n(g, fps, 0.6, 1.2), FEET),
              Phase("settle", sit, _n(g, fps, 0.3, 0.8), ("pelvis",)),  # the heels slide forward
              Phase("sit", sit, _n(g, fps, 0.3, 2.0), (*FEET, "pelvis")),
              Phase("lie back", lie, _n(g, fps, 1.0, 2.5), ("pelvis",)),  # the heels slide
              Phase("lie", lie, _n(g, fps, 1.0, 6.0), (*rest, "back")),
              Phase("sit up", sit, _n(g, fps, 1.0, 2.5), ("pelvis",)),
              Phase("sit", sit, _n(g, fps, 0.3, 1.5), (*FEET, "pelvis")),
              Phase("feet in", touch, _n(g, fps, 0.3, 0.8), ("pelvis",)),
              Phase("rise to squat", squat, _n(g, fps, 0.8, 1.5), FEET),
              Phase("stand up", stand, _n(g, fps, 1.0, 2.0), FEET),
              Phase("stand", stand, _n(g, fps, 0.5, 1.5), FEET)]
    return stand, phases, {"knees_up": knees_up, "lean_back_deg": lean_back, "seated_shank_deg": sit.l_shank,
                           "touch_down_at": s_touch}


def _reach(g: torch.Generator, body: Any, skin: _Skin, fps: float, stand: Posture) -> tuple[Posture, list[Phase], dict[str, Any]]:
    """Reach up with one or both arms (150-178 deg), look up, maybe on the toes; 1-3 times."""
    arms = "both" if _u(g, 0, 1) < 0.5 else ("left" if _u(g, 0, 1) < 0.5 else "right")
    toes = _u(g, 0.0, 30.0) if _u(g, 0, 1) < 0.6 else 0.0  # rise onto the toes (heels up)
    top = stand.with_(spine_flex=-_u(g, 0.0, 20.0), neck_flex=-_u(g, 10.0, 40.0), both_foot=toes, both_toe=toes)
    for k in ("l", "r"):
        if arms in ("both", "left" if k == "l" else "right"):
            top = top.with_(**{f"{k}_raise": _u(g, 150.0, 178.0), f"{k}_plane": _u(g, 0.0, 70.0), f"{k}_elbow": _u(g, 0.0, 25.0)})
    phases = [Phase("stand", stand, _n(g, fps, 0.5, 1.5), FEET)]
    reps = int(_u(g, 1.0, 4.0))
    for _ in range(reps):
        phases += [Phase("reach up", top, _n(g, fps, 0.6, 1.5), FEET), Phase("hold", top, _n(g, fps, 0.3, 2.0), FEET),
                   Phase("lower", stand, _n(g, fps, 0.6, 1.5), FEET), Phase("stand", stand, _n(g, fps, 0.3, 1.5), FEET)]
    return stand, phases, {"arms": arms, "heel_lift_deg": toes, "repetitions": reps}


def _crawl(g: torch.Generator, body: Any, skin: _Skin, fps: float, stand: Posture) -> tuple[Posture, list[Phase], dict[str, Any]]:
    """On hands and knees (toes tucked): a diagonal crawl (left hand with right knee) of a few
    cycles between two still holds; the swing limbs clear the floor by a pelvis/chest roll and an
    elbow bend."""
    dorsi, toe = _u(g, 0.0, 20.0), _u(g, 45.0, 65.0)
    neck, plane = -_u(g, 20.0, 35.0), _u(g, 0.0, 8.0)

    def fours(pitch: float, shank: float) -> Posture:  # arms vertical in the world
        return Posture().with_(pelvis_pitch=pitch, spine_flex=-6.0, neck_flex=neck, both_thigh=0.0, both_shank=shank,
                               both_foot=shank - dorsi, both_toe=toe, both_abd=4.0, both_raise=pitch - 6.0,
                               both_plane=plane, both_elbow=0.0)

    hands, knees = ("left_hand", "right_hand"), ("left_knee", "right_knee")
    shank, _ = solve_gap(skin, lambda x: fours(90.0, x), 80.0, 140.0, ("left_foot",), ("left_knee",))
    x, base = solve_gap(skin, lambda x: fours(x, shank), 50.0, 120.0, hands, knees)
    freq, amp = _u(g, 0.4, 0.9), _u(g, 8.0, 14.0)
    cycles = int(_u(g, 2.0, 5.0))
    n_go = max(2, int(round(cycles / freq * fps)))
    n0, n1 = _n(g, fps, 0.5, 1.5), _n(g, fps, 0.5, 1.5)
    lift = _u(g, 6.0, 10.0)
    all_four = (*hands, *knees)
    phases = [Phase("hold", base, n0, all_four), Phase("crawl", base, n_go, ()), Phase("hold", base, n1, all_four)]
    first_go = n0 + 1  # timeline frame 0 + phase frames

    def overlay(p: dict[str, torch.Tensor], fps_: float) -> None:
        T = p["pelvis_pitch"].shape[0]
        t = torch.arange(T, dtype=torch.float64)
        u = ((t - first_go) / n_go).clamp(0.0, 1.0)
        env = torch.sin(math.pi * u) ** 2  # ramps the gait in and out
        ph = 2 * math.pi * cycles * u
        sw = torch.sin(ph)  # > 0: left arm / right leg forward
        # swing (moving forward) when d(sw)/dt > 0, i.e. cos(ph) > 0
        swing_a = torch.clamp(torch.cos(ph), min=0.0) * env  # left hand + right knee in swing
        swing_b = torch.clamp(-torch.cos(ph), min=0.0) * env
        p["l_raise"] = p["l_raise"] + amp * sw * env
        p["r_raise"] = p["r_raise"] - amp * sw * env
        p["l_thigh"] = p["l_thigh"] - amp * sw * env
        p["r_thigh"] = p["r_thigh"] + amp * sw * env
        p["l_elbow"] = p["l_elbow"] + 3 * lift * swing_a
        p["r_elbow"] = p["r_elbow"] + 3 * lift * swing_b
        p["pelvis_twist"] = p["pelvis_twist"] + lift * (swing_a - swing_b)
        p["spine_twist"] = p["spine_twist"] - 2 * lift * (swing_a - swing_b)

    stance = {"frames": (first_go, n_go), "freq_hz": freq, "amp_deg": amp, "cycles": cycles}
    return base, phases, {"pelvis_pitch": x, **stance, "weights": "stance limbs"}, overlay


def _crawl_anchor_weights(params: dict[str, Any]) -> Callable[[torch.Tensor], None]:
    """In place on anchor weights ``(T, 24)``: during the crawl each limb (left hand, right hand,
    left knee, right knee) weighs its stance share (1 - swing), so the stance limbs anchor the body."""
    first, n = params["frames"]
    cycles = params["cycles"]

    def edit(w: torch.Tensor) -> None:
        t = torch.arange(first, first + n, dtype=torch.float64)
        u = (t - first) / n
        env, ph = torch.sin(math.pi * u) ** 2, 2 * math.pi * cycles * u  # as the crawl's overlay
        a = torch.clamp(torch.cos(ph), min=0.0) * env  # left hand / right knee swing
        b = torch.clamp(-torch.cos(ph), min=0.0) * env
        for c, share in (("left_hand", 1 - a), ("right_hand", 1 - b), ("left_knee", 1 - b), ("right_knee", 1 - a)):
            w[first:first + n, CONTACT_ANCHORS[c]] = share
    return edit


_BUILDERS = {"squat": _squat, "kneel": _kneel, "pickup": _pickup, "sit": _sit, "lie": _lie, "crawl": _crawl,
             "reach": _reach}


def procedural_motion(family: str, g: torch.Generator, body: Any, fps: float = 60.0, *,
                      body_shape: bool = True) -> MotionSequence:
    """One clip of ``family`` (:data:`FAMILIES`, module doc) drawn from ``g`` on ``body``.

    Returns:
        A :class:`MotionSequence` at ``fps`` (``meta`` as :func:`place` documents).
    """
    _check(family)
    betas = sample_betas(g, NUM_BETAS, dtype=torch.float64) if body_shape else torch.zeros(NUM_BETAS, dtype=torch.float64)
    heading = _u(g, -180.0, 180.0)
    skin = _Skin(body, betas)
    stand = _stance(g)
    out = _BUILDERS[family](g, body, skin, fps, stand)
    start, phases, params = out[:3]
    overlay = out[3] if len(out) > 3 else None
    plan = Plan(family, start, phases, heading, betas, sway=family != "crawl", params=params, overlay=overlay,
                keep_feet_width=family not in ("kneel", "crawl"))
    if family == "crawl":
        plan.anchor_weights = _crawl_anchor_weights(params)
    return place(plan, body, fps, g)


def procedural_clip(family: str, index: int, body: Any, *, seed: int = 0, namespace: str = "train",
                    fps: float = 60.0, body_shape: bool = True) -> MotionSequence:
    """Clip ``index`` of ``family`` in seed ``namespace`` (``"eval"`` for held-out sets), named
    :func:`clip_id` in ``meta["clip"]``; the same arguments give the same clip."""
    g = torch.Generator().manual_seed(procedural_seed(family, index, seed, namespace))
    seq = procedural_motion(family, g, body, fps, body_shape=body_shape)
    seq.meta.update({"clip": clip_id(family, namespace, index), "split": namespace, "seed": int(seed)})
    return seq


def contact_report(seq: MotionSequence, body: Any) -> dict[str, Any]:
    """What a check needs of a placed clip: ``lowest`` ``(T,)`` m (whole mesh), and per segment of
    ``meta["segments"]`` and contact part: the part's highest lowest-vertex height over the
    segment (m; <= 0.01 means it stays on the floor) and its anchor joint's largest horizontal
    distance from where it was at the segment's start (m)."""
    skin = _Skin(body, seq.betas.double())
    low, parts = skin.lowest(seq.pose.double())
    low = low + seq.trans[:, 1].double()
    with torch.no_grad():
        J = body(seq.pose.to(body.dtype), seq.betas.to(body.dtype), seq.trans.to(body.dtype),
                 return_vertices=False).joints.double()
    rows = []
    for name, first, n, contacts in seq.meta.get("segments", []):
        for c in contacts:
            h = parts[c][first:first + n] + seq.trans[first:first + n, 1].double()
            a = J[first:first + n, CONTACT_ANCHORS[c]][:, [0, 2]]
            rows.append({"segment": name, "first": first, "frames": n, "contact": c, "height_max": float(h.max()),
                         "height_min": float(h.min()), "slide_max": float((a - a[0]).norm(dim=-1).max())})
    return {"lowest": low, "contacts": rows}


def joint_limit_violations(pose: torch.Tensor) -> list[str]:
    """Joints of local rotations ``pose`` ``(T, 24, 3, 3)`` beyond :data:`JOINT_LIMITS_DEG`, or
    hinges (:data:`HINGES`) bending the wrong way or off their axis by more than 2 deg; one
    message per joint (empty: all within)."""
    aa = matrix_to_axis_angle(pose.double())  # (T, 24, 3)
    ang = aa.norm(dim=-1) * 180.0 / math.pi
    out = []
    for j, name in enumerate(JOINT_NAMES):
        if float(ang[:, j].max()) > JOINT_LIMITS_DEG[name] + 1e-6:
            out.append(f"{name}: {float(ang[:, j].max()):.1f} deg > {JOINT_LIMITS_DEG[name]}")
        if name in HINGES:
            ax, sign = HINGES[name]
            flex = sign * aa[:, j, ax] * 180.0 / math.pi
            off = torch.cat([aa[:, j, :ax], aa[:, j, ax + 1:]], -1).norm(dim=-1) * 180.0 / math.pi
            if float(flex.min()) < -1e-6 or float(off.max()) > 2.0:
                out.append(f"{name}: flexion min {float(flex.min()):.2f} deg, off-axis {float(off.max()):.2f} deg")
    return out


def describe() -> list[dict[str, Any]]:
    """One row per family (name and what it is) for ``--help`` and the docs."""
    return [{"family": f, "doc": (_BUILDERS[f].__doc__ or "").strip()} for f in FAMILIES]


__all__ = ["FAMILIES", "NAMESPACES", "Posture", "procedural_motion", "procedural_clip", "procedural_seed", "clip_id",
           "contact_report", "joint_limit_violations", "JOINT_LIMITS_DEG", "CONTACT_PARTS", "CONTACT_ANCHORS"]
