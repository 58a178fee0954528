"""A calibration T-pose at the start of a recording, and the meta entry that marks it.

IMU methods (PIP, BiRAE's inertial alignment) need the wearer to stand in a known pose for a
moment so that each sensor's mounting (sensor -> bone) and the world heading can be solved
(``docs/calibration.md``). A real capture starts with it because the operator asks for it; a
*simulated* recording only has it when the motion has it. :func:`prepend_tpose` gives a motion
that opening hold (:func:`tpose_then`: ``hold_s`` of SMPL's T-pose at the clip's
first position and heading, a ``blend_s`` smoothstep slerp into the first frame, then the clip;
then lifted to stand on the clip's floor, as a wearer stands; MI-Poser's training data uses
:func:`tpose_then` alone, whose T-pose sinks 2-6 cm: docs/placement.md),
and :func:`tpose_meta` / :func:`calibration_window` write and read where the hold is:

``meta["calibration_window"] = {"pose": "tpose", "start_s": a, "stop_s": b, "prefix_s": p}``

``a``..``b`` (seconds on the sensors' clock) lies inside the hold (a little margin at the start,
the last held frame at the end); ``p`` is where the original clip starts (after the blend), so
tools can drop the prefix again. ``meta`` is free JSON in format version 1, so this needs no
version bump; a recording without the entry is read exactly as before.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import torch

from wearpose.errors import ConfigError, ShapeError
from wearpose.geometry import heading, rotation_y, slerp_matrix

#: The meta key marking a recording's calibration pose.
CALIBRATION_WINDOW_KEY = "calibration_window"
#: Default blend from the held T-pose into the clip, seconds (MI-Poser's ``blend_s``).
DEFAULT_BLEND_S = 0.5


def _smoothstep(n: int) -> torch.Tensor:
    """``(n,)`` float64 blend weights strictly between 0 and 1: no velocity jump at either end."""
    x = torch.arange(1, n + 1, dtype=torch.float64) / (n + 1)
    return x * x * (3 - 2 * x)


def tpose_then(motion: Any, hold_s: float, blend_s: float) -> tuple[Any, int]:
    """``hold_s`` of the T-pose at the clip's first position and heading, a ``blend_s`` slerp
    into the first frame, then the clip.

    Returns:
        ``(motion, prefix)``: the longer :class:`~wearpose.motion.MotionSequence` and the number
        of frames before the clip's first frame.
    """
    from wearpose.body import calibration_pose  # start-up: wearpose.body adds ~15 ms to import wearpose.recording
    from wearpose.motion import MotionSequence  # start-up: wearpose.motion adds ~70 ms to import wearpose.recording

    fps = motion.fps
    nh, nb = int(round(hold_s * fps)), int(round(blend_s * fps))
    pose = motion.pose.to(torch.float64)
    base = calibration_pose("tpose").clone()
    base[0] = rotation_y(heading(pose[0, 0]))  # the wearer faces where the clip starts
    w = _smoothstep(nb)
    blend = slerp_matrix(base.expand(nb, 24, 3, 3), pose[0].expand(nb, 24, 3, 3), w[:, None].expand(nb, 24))
    full = torch.cat([base.expand(nh, 24, 3, 3), blend, pose]).to(motion.pose.dtype)
    trans = torch.cat([motion.trans[:1].expand(nh + nb, 3), motion.trans])
    return MotionSequence(full, motion.betas, trans, fps, dict(motion.meta)), nh + nb


def _on_the_clips_floor(full: Any, prefix: int, hold: int, clip: Any) -> tuple[Any, int]:
    """``full`` (:func:`tpose_then`'s) with its held T-pose standing on the floor the clip
    stands on, and the blend easing from that height into the clip's first frame.

    :func:`tpose_then` holds the T-pose at the clip's first root position: straight legs under a
    walking pelvis put the soles 2-6 cm under the floor (5.4 cm before CMU's walk 05_01), where
    no wearer stands for a calibration. The clip's floor here is the median lowest point of its
    first second (one glitched first frame does not move it).
    """
    from wearpose.body import BodyModel  # start-up: as in tpose_then

    body = BodyModel()
    first = clip.slice(0, max(1, min(clip.num_frames, int(round(clip.fps)))))
    with torch.no_grad():
        floor = body.lowest_height(first.pose.to(body.dtype), first.betas.to(body.dtype), first.trans.to(body.dtype)).median()
        held = body.lowest_height(full.pose[:1].to(body.dtype), full.betas.to(body.dtype), full.trans[:1].to(body.dtype))[0]
    lift = torch.zeros(full.num_frames, dtype=full.trans.dtype)
    lift[:hold] = float(floor - held)
    lift[hold:prefix] = (float(floor - held) * (1 - _smoothstep(prefix - hold))).to(lift.dtype)  # as the pose blends
    trans = full.trans.clone()
    trans[:, 1] += lift
    return replace(full, trans=trans), prefix


def prepend_tpose(motion: Any, hold_s: float, blend_s: float = DEFAULT_BLEND_S) -> tuple[Any, dict[str, Any]]:
    """``motion`` with a calibration T-pose held before it, standing on the clip's floor.

    Args:
        motion: a :class:`wearpose.motion.MotionSequence` (any fps).
        hold_s: seconds of T-pose (> 0; 1 s is what PIP's calibration reads).
        blend_s: seconds of blend from the T-pose into the first frame.

    Returns:
        ``(longer_motion, window)``: ``window`` is the dict stored under
        ``meta["calibration_window"]`` (see module doc), in seconds from the first frame.
    """
    if not hold_s > 0:
        raise ConfigError(f"the T-pose hold must be > 0 s, got {hold_s!r}")
    fps = float(motion.fps)
    hold = int(round(hold_s * fps))
    if hold < 2:
        raise ConfigError(f"a {hold_s} s T-pose is {hold} frame(s) at {fps:g} fps; expected at least 2 frames")
    full, prefix = _on_the_clips_floor(*tpose_then(motion, float(hold_s), float(blend_s)), hold, motion)
    # Same margins as MI-Poser's calibration window: skip the first instant, end on the last held frame.
    window = {"pose": "tpose", "start_s": round(min(0.1, 0.25 * hold_s), 6), "stop_s": round((hold - 1) / fps, 6),
              "prefix_s": round(prefix / fps, 6)}
    return full, window


def calibration_window(recording: Any) -> tuple[float, float] | None:
    """The ``(start_s, stop_s)`` of the T-pose a recording's meta marks, or None.

    Raises:
        wearpose.errors.ShapeError: the entry is there but malformed (a typo must not silently
            fall back to another window).
    """
    w = (getattr(recording, "meta", None) or {}).get(CALIBRATION_WINDOW_KEY)
    if w is None:
        return None
    try:
        if w.get("pose", "tpose") != "tpose":
            raise ValueError(f"pose {w.get('pose')!r}")
        a, b = float(w["start_s"]), float(w["stop_s"])
        if not 0 <= a < b:
            raise ValueError(f"start_s {a} / stop_s {b}")
    except (AttributeError, KeyError, TypeError, ValueError) as exc:
        raise ShapeError(f"meta[{CALIBRATION_WINDOW_KEY!r}] = {w!r} is malformed ({exc}); expected "
                         "{'pose': 'tpose', 'start_s': a, 'stop_s': b} with 0 <= a < b seconds") from None
    return a, b
