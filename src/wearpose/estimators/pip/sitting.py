"""Synthetic sitting motion for PIP (the corpus has no sitting clip).

PIP's learned RNN initialisation matters most for poses the six IMUs cannot tell apart, the
paper's example being sitting still vs standing still (Sec. 3.1.2, Fig. 6, Fig. 9): the pelvis
and lower-leg sensors read the same orientations and zero acceleration in both. Our corpus
(CMU + Bandai) holds no sitting at all, so a network trained on it never sees the ambiguity and
the learned initialisation cannot show its effect. :func:`sitting_motion` synthesises clips
with it: stand still -> sit down -> sit still -> (stand up -> stand still), or starting
already seated, with

- seated hip flexion 75-100 deg and the same knee flexion, so the shanks stay vertical (the
  lower-leg IMUs read what they read when standing; a first version with knee = hip +-10 deg
  left the shank tilt as a cue, and a network trained without learned initialisation read the
  seated state from it);
- an upright pelvis (small random tilt shared by both holds) and a random heading;
- one random arm/spine/head posture shared by the standing and seated holds, so the upper body
  does not give the state away either;
- a slow sway (< 2 deg, 0.1-0.5 Hz) on the spine, neck and arms during the holds (people do not
  hold perfectly still; the IMU noise model adds sensor noise on top);
- feet planted: the translation keeps the midpoint of the two ankles fixed, so the pelvis
  moves down and back by itself;
- transitions (``transitions``): ``"slerp"`` (sitting version 2, what every model up to the
  session-7 ``pip_cpu`` saw) slerps stand -> sit with the pelvis orientation fixed, no trunk lean
  and the shanks vertical throughout, leaving ~1 s of 1-3 m/s^2 pelvis/head acceleration as the
  only sign of a sit-down; ``"lean"`` shapes each sit-down / stand-up like a person's
  (:func:`lean_transition`): the pelvis pitches forward 15-40 deg and the spine flexes a further
  5-20 deg (the head partly counter-rotates), the knees travel forward over the feet (shanks tilt
  8-20 deg), all peaking mid-transition and back to zero at its ends, so the holds are the same
  frames as with ``"slerp"`` (same seed) and stay ambiguous; only the transition tells.

Everything is drawn from a ``torch.Generator`` seeded by the caller.
"""

from __future__ import annotations

import math
from typing import Any

import torch

from wearpose.body import calibration_pose
from wearpose.body.skeleton import JOINT_INDEX
from wearpose.estimators.seeding import clip_seed
from wearpose.geometry import axis_angle_to_matrix, rotation_x, rotation_y, rotation_z, slerp_matrix

_SWAY_JOINTS = ("spine1", "spine2", "spine3", "neck", "head", "left_shoulder", "right_shoulder", "left_elbow",
                "right_elbow")


def _u(g: torch.Generator, lo: float, hi: float) -> float:
    return lo + (hi - lo) * float(torch.rand((), generator=g))


def sitting_pose(hip_deg: float = 90.0, knee_deg: float = 90.0, base: torch.Tensor | None = None) -> torch.Tensor:
    """A seated pose ``(24, 3, 3)``: ``base`` (default: the calibration I-pose, arms down) with
    both thighs flexed forward by ``hip_deg`` (rotation about -X) and both knees by ``knee_deg``."""
    P = (calibration_pose("ipose") if base is None else base).float().clone()
    for side in ("left", "right"):
        P[JOINT_INDEX[f"{side}_hip"]] = rotation_x(torch.tensor(-math.radians(hip_deg))) @ P[JOINT_INDEX[f"{side}_hip"]]
        P[JOINT_INDEX[f"{side}_knee"]] = rotation_x(torch.tensor(math.radians(knee_deg))) @ P[JOINT_INDEX[f"{side}_knee"]]
    return P


def _upper_body(g: torch.Generator) -> torch.Tensor:
    """A random standing posture ``(24, 3, 3)``: arms hanging or resting forward, elbows bent
    0-90 deg, small spine/head tilts; legs straight."""
    P = calibration_pose("ipose").float().clone()
    for name, lim in (("spine1", 6.0), ("spine3", 6.0), ("neck", 10.0), ("head", 10.0)):
        aa = torch.tensor([_u(g, -lim, lim), _u(g, -lim, lim), _u(g, -lim / 2, lim / 2)]).mul(math.pi / 180)
        P[JOINT_INDEX[name]] = axis_angle_to_matrix(aa)
    for side in ("left", "right"):
        fwd, out, elbow = _u(g, 0.0, 50.0), _u(g, -5.0, 20.0), _u(g, 0.0, 90.0)
        _pose_arm(P, side, fwd, out, elbow)
    return P


def _pose_arm(P: torch.Tensor, side: str, fwd_deg: float, out_deg: float, elbow_deg: float) -> None:
    """In place on ``P`` ``(24, 3, 3)``: swing the hanging ``side`` arm forward (+Z) by ``fwd_deg``
    and outward (+-X) by ``out_deg``, and bend its forearm forward by ``elbow_deg``."""
    sh = P[JOINT_INDEX[f"{side}_shoulder"]]
    s = 1.0 if side == "left" else -1.0
    M = rotation_x(torch.tensor(-math.radians(fwd_deg))) @ rotation_z(torch.tensor(s * math.radians(out_deg))) @ sh
    P[JOINT_INDEX[f"{side}_shoulder"]] = M
    # bend the forearm forward about the world X axis, expressed in the upper arm's frame
    P[JOINT_INDEX[f"{side}_elbow"]] = M.T @ rotation_x(torch.tensor(-math.radians(elbow_deg))) @ M


def arms_forward(fwd_deg: float, elbow_deg: float) -> torch.Tensor:
    """The calibration I-pose ``(24, 3, 3)`` with both arms swung forward by ``fwd_deg`` and both
    elbows bent by ``elbow_deg`` (a base posture for :func:`sitting_sequence`)."""
    P = calibration_pose("ipose").float().clone()
    for side in ("left", "right"):
        _pose_arm(P, side, fwd_deg, 0.0, elbow_deg)
    return P


def _sway(g: torch.Generator, T: int, fps: float) -> torch.Tensor:
    """``(T, 24, 3, 3)`` slow small rotations (identity outside :data:`_SWAY_JOINTS`)."""
    R = torch.eye(3).repeat(T, 24, 1, 1)
    t = torch.arange(T, dtype=torch.float32) / fps
    for name in _SWAY_JOINTS:
        f = torch.rand(3, generator=g) * 0.4 + 0.1
        ph = torch.rand(3, generator=g) * 2 * math.pi
        amp = torch.rand(3, generator=g) * math.radians(1.5)
        aa = amp * torch.sin(2 * math.pi * f * t[:, None] + ph)
        R[:, JOINT_INDEX[name]] = axis_angle_to_matrix(aa)
    return R


def _planted_trans(body: Any, pose: torch.Tensor, betas: torch.Tensor) -> torch.Tensor:
    """Root translation ``(T, 3)`` m that keeps the midpoint of the two ankles where it is in
    frame 0 and puts frame 0's lower foot on y = 0, for local rotations ``pose`` ``(T, 24, 3, 3)``."""
    with torch.no_grad():
        j = body(pose, betas, torch.zeros(pose.shape[0], 3), return_vertices=False).joints.float()
    ankles = j[:, [JOINT_INDEX["left_ankle"], JOINT_INDEX["right_ankle"]]].mean(1)
    trans = ankles[0] - ankles
    trans[:, 1] += float(-j[0, [JOINT_INDEX["left_foot"], JOINT_INDEX["right_foot"]], 1].min())
    return trans


#: Seconds of a synthetic clip's seated hold (low, high).
SIT_HOLD_S: tuple[float, float] = (3.0, 20.0)
#: Seconds of its standing holds by default (low, high); ``SIT_HOLD_S`` = balanced.
STAND_HOLD_S: tuple[float, float] = (1.0, 4.0)


#: Kinds of synthetic sit-down / stand-up (module doc); the first is the default.
TRANSITIONS: tuple[str, ...] = ("slerp", "lean")


def _check_transitions(transitions: str) -> None:
    if transitions not in TRANSITIONS:
        raise ValueError(f"sitting transitions: expected one of {TRANSITIONS}, got {transitions!r}")


def _bump(n: int, peak: float) -> torch.Tensor:
    """``(n,)`` 0 -> 1 -> 0 with zero slope at both ends and the maximum at fraction ``peak``
    (sin^2 over a time axis bent piecewise linearly so its middle lands on ``peak``)."""
    u = torch.linspace(0.0, 1.0, n)
    w = torch.where(u <= peak, 0.5 * u / peak, 0.5 + 0.5 * (u - peak) / (1.0 - peak))
    return torch.sin(math.pi * w) ** 2


def lean_transition(pose: torch.Tensor, first: int, n: int, pelvis_deg: float, spine_deg: float, shank_deg: float,
                    neck_factor: float = 0.4, peak: float = 0.5) -> None:
    """In place on local rotations ``pose`` ``(T, 24, 3, 3)`` (root = the pelvis' world
    orientation): over frames ``first .. first + n`` pitch the pelvis forward by up to
    ``pelvis_deg`` (the hips flex by as much, so the thighs keep their world direction), flex the
    spine by a further ``spine_deg`` (spread over spine1-3) while the neck takes back
    ``neck_factor`` of the trunk lean, and tilt the shanks back by ``shank_deg`` (knees ahead of
    the feet); every angle follows :func:`_bump` (0 at both ends, maximum at ``peak``)."""
    b = _bump(n, peak)
    sl = slice(first, first + n)
    rad = math.pi / 180.0
    # trunk forward = +X rotation of an upward segment; thigh/shank forward = -X of a downward one
    pose[sl, 0] = pose[sl, 0] @ rotation_x(b * pelvis_deg * rad)
    for side in ("left", "right"):
        hip, knee = JOINT_INDEX[f"{side}_hip"], JOINT_INDEX[f"{side}_knee"]
        pose[sl, hip] = rotation_x(-b * pelvis_deg * rad) @ pose[sl, hip]
        pose[sl, knee] = rotation_x(b * shank_deg * rad) @ pose[sl, knee]
    for name in ("spine1", "spine2", "spine3"):
        pose[sl, JOINT_INDEX[name]] = rotation_x(b * spine_deg / 3.0 * rad) @ pose[sl, JOINT_INDEX[name]]
    neck = JOINT_INDEX["neck"]
    pose[sl, neck] = rotation_x(-b * neck_factor * (pelvis_deg + spine_deg) * rad) @ pose[sl, neck]


def sitting_motion(g: torch.Generator, body: Any, fps: float = 60.0, hold_s: tuple[float, float] = SIT_HOLD_S,
                   stand_s: tuple[float, float] = STAND_HOLD_S, transitions: str = "slerp",
                   hanging_arms: float = 0.0) -> Any:
    """One synthetic sitting clip (module doc) as a :class:`~wearpose.motion.MotionSequence`
    at ``fps`` with zero betas; ``meta["segments"]`` lists ``(name, first_frame, frames)``.
    Seated holds last ``hold_s`` seconds, standing holds ``stand_s``: with ``stand_s = hold_s``
    still standing and still sitting with the same upper-body posture are equally common, so a
    still posture alone does not tell them apart (with the default short stands a network
    learns "arms bent forward and still = seated", see docs/pip.md, "Long sitting").
    ``transitions``: :data:`TRANSITIONS` (module doc); the ``"lean"`` shapes are drawn after
    everything else, so the same seed gives the same clip outside the transitions.
    ``hanging_arms``: probability that the clip's arms hang nearly straight (swung forward 0-8
    deg, outward -3-8, elbows 0-15) instead of the default posture's 0-50 / -5-20 / 0-90 deg,
    in both holds alike (the random posture rarely comes near the calibration I-pose, and the
    corpus stands with straight arms all the time, so a network learns "straight arms =
    standing"); drawn after the transitions, so 0 leaves every clip as it was."""
    # start-up: wearpose.motion adds ~60 ms to importing this module
    from wearpose.motion import MotionSequence

    _check_transitions(transitions)
    stand = _upper_body(g)
    hip = _u(g, 75.0, 100.0)
    sit = sitting_pose(hip, hip, base=stand)  # shanks vertical, as when standing: the IMUs cannot tell
    start_seated = _u(g, 0, 1) < 0.3
    end_seated = _u(g, 0, 1) < 0.3
    plan: list[tuple[str, int]] = []
    if not start_seated:
        plan += [("stand", int(_u(g, *stand_s) * fps)), ("down", int(_u(g, 0.8, 2.0) * fps))]
    plan.append(("sit", int(_u(g, *hold_s) * fps)))
    if not end_seated:
        plan += [("up", int(_u(g, 0.8, 2.0) * fps)), ("stand", int(_u(g, *stand_s) * fps))]
    s_parts, segs, first = [], [], 0
    for name, n in plan:
        if name == "stand":
            s_parts.append(torch.zeros(n))
        elif name == "sit":
            s_parts.append(torch.ones(n))
        else:
            ramp = 0.5 - 0.5 * torch.cos(torch.linspace(0, math.pi, n))
            s_parts.append(ramp if name == "down" else 1 - ramp)
        segs.append((name, first, n))
        first += n
    s = torch.cat(s_parts)
    T = len(s)
    pose = slerp_matrix(stand.expand(T, 24, 3, 3), sit.expand(T, 24, 3, 3), s[:, None].expand(T, 24))
    sway = _sway(g, T, fps)
    pose = pose @ sway
    tilt = rotation_x(torch.tensor(math.radians(_u(g, -5.0, 5.0))))
    pose[:, 0] = rotation_y(torch.tensor(_u(g, -math.pi, math.pi))) @ tilt
    if transitions == "lean":
        for name, first, n in segs:
            if name in ("down", "up"):  # standing up leans further forward than sitting down
                lean_transition(pose, first, n, pelvis_deg=_u(g, 15.0, 30.0) if name == "down" else _u(g, 20.0, 40.0),
                                spine_deg=_u(g, 5.0, 20.0), shank_deg=_u(g, 8.0, 20.0),
                                neck_factor=_u(g, 0.2, 0.6), peak=_u(g, 0.35, 0.65))
    if hanging_arms > 0.0 and _u(g, 0.0, 1.0) < hanging_arms:
        arms = calibration_pose("ipose").float()  # arms hanging straight, swung from there
        for side in ("left", "right"):
            _pose_arm(arms, side, _u(g, 0.0, 8.0), _u(g, -3.0, 8.0), _u(g, 0.0, 15.0))
            for j in (JOINT_INDEX[f"{side}_shoulder"], JOINT_INDEX[f"{side}_elbow"]):
                pose[:, j] = arms[j] @ sway[:, j]  # the arms are the same standing and seated
    betas = torch.zeros(10)
    trans = _planted_trans(body, pose, betas)
    return MotionSequence(pose, betas, trans, fps, {"clip": "synthetic/sitting", "segments": segs})


def sitting_sequence(body: Any, seconds_stand: float = 1.0, seconds_down: float = 1.5, fps: float = 60.0,
                     base: torch.Tensor | None = None, transitions: str = "slerp") -> Any:
    """Deterministic stand (arms down, or the posture ``base`` ``(24, 3, 3)``) -> sit down (90/90
    deg) -> one second seated: the start of the long-sitting test (Fig. 6 / Fig. 9).
    ``transitions="lean"``: the sit-down leans like the middle of :func:`sitting_motion`'s ranges
    (pelvis 22.5, spine 12.5, shanks 14 deg, neck 0.4, peak mid-way)."""
    # start-up: wearpose.motion adds ~60 ms to importing this module
    from wearpose.motion import MotionSequence

    _check_transitions(transitions)

    stand = calibration_pose("ipose").float() if base is None else base.float()
    sit = sitting_pose(base=stand)
    n0, n1 = int(seconds_stand * fps), int(seconds_down * fps)
    s = torch.cat([torch.zeros(n0), 0.5 - 0.5 * torch.cos(torch.linspace(0, math.pi, n1)), torch.ones(int(fps))])
    T = len(s)
    pose = slerp_matrix(stand.expand(T, 24, 3, 3), sit.expand(T, 24, 3, 3), s[:, None].expand(T, 24))
    if transitions == "lean":
        lean_transition(pose, n0, n1, pelvis_deg=22.5, spine_deg=12.5, shank_deg=14.0)
    trans = _planted_trans(body, pose, torch.zeros(10))
    return MotionSequence(pose, torch.zeros(10), trans, fps, {"clip": "synthetic/sit-down"})


def heldout_sitting_clip(i: int, body: Any, fps: float = 60.0, seed: int = 0, transitions: str = "slerp") -> Any:
    """Synthetic sitting clip ``i`` of the *test* namespace (``synthetic/sitting/test/<i>``, seeded
    like the train/val clips of :func:`wearpose.estimators.pip.data.build_split`, which never
    draws test ids), cut after its seated hold: it ends seated (input for
    :func:`~wearpose.estimators.pip.evaluate.sitting_drift`'s ``seq``); ``transitions`` as in
    :func:`sitting_motion`."""
    m = sitting_motion(torch.Generator().manual_seed(clip_seed(sitting_clip_id("test", i), seed, "pip-sitting")),
                       body, fps, transitions=transitions)
    _, first, n = next(sg for sg in m.meta["segments"] if sg[0] == "sit")
    return m.slice(0, first + n)


#: Clip-id prefix of every synthetic sitting clip.
SITTING_PREFIX = "synthetic/sitting/"


def sitting_clip_id(split: str, i: int) -> str:
    """Id of synthetic sitting clip ``i`` of ``split`` (its seed derives from it)."""
    return f"{SITTING_PREFIX}{split}/{i:04d}"
