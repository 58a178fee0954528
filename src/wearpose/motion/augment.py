"""Motion augmentation for training data: the left/right mirror image of a clip and a clip
played faster or slower.

Both return new, valid :class:`~wearpose.motion.MotionSequence` objects that the sensor
simulator turns into consistent virtual sensor data (the sensors are simulated *after*
augmenting, so accelerations, orientations and every target follow the augmented motion).
"""

from __future__ import annotations

import copy
import math
from typing import Any

import torch

from wearpose.body.skeleton import MIRROR
from wearpose.errors import ShapeError
from wearpose.geometry import mirror_points, mirror_rotation
from wearpose.motion.sequence import MotionSequence


def mirror(seq: MotionSequence, root_rest: torch.Tensor | None = None) -> MotionSequence:
    """The left/right mirror image of ``seq`` through the world plane x = 0.

    Joint ``j`` of the result turns like joint ``MIRROR[j]`` of the input, reflected
    (``M R M``, :func:`wearpose.geometry.mirror_rotation`); on a left/right symmetric body every
    joint position is then the reflection of its mirror joint's. ``root_rest`` ``(3,)`` (the
    body's zero-pose pelvis joint, m; ``trans`` is SMPL's, so the pelvis is at ``root_rest +
    trans``) makes the *pelvis* path the exact reflection; without it the pelvis path is off by
    the constant ``2 * root_rest.x`` in x (millimetres for SMPL-like bodies; no sensor sees a
    constant offset). ``betas`` are kept: the same person, mirrored.

    Args:
        seq: ``T`` frames; root_rest: optional ``(3,)``.

    Returns:
        A new sequence, ``meta["augment"]`` extended by ``"mirror"``.
    """
    pose = mirror_rotation(seq.pose[:, list(MIRROR)])
    trans = mirror_points(seq.trans)
    if root_rest is not None:
        r = torch.as_tensor(root_rest).to(trans)
        trans = trans + mirror_points(r) - r
    return MotionSequence(pose, seq.betas.clone(), trans, seq.fps, _tagged(seq.meta, "mirror"))


def play_speed(seq: MotionSequence, factor: float) -> MotionSequence:
    """``seq`` played ``factor`` times faster (``factor`` < 1: slower): the same frames at
    ``fps * factor``; resample afterwards for a fixed output rate. Velocities scale by
    ``factor``, accelerations by ``factor**2`` (gravity does not: a faster jump is not a
    ballistic one, keep factors near 1).

    Returns:
        A new sequence, ``meta["augment"]`` extended by ``"speed=<factor>"``.
    """
    factor = float(factor)
    if not math.isfinite(factor) or factor <= 0:
        raise ShapeError(f"play_speed: factor must be a positive number, got {factor!r}")
    return MotionSequence(seq.pose.clone(), seq.betas.clone(), seq.trans.clone(), seq.fps * factor,
                          _tagged(seq.meta, f"speed={factor:.4g}"))


def _tagged(meta: dict[str, Any], tag: str) -> dict[str, Any]:
    out = copy.deepcopy(meta)
    out["augment"] = [*out.get("augment", []), tag]
    return out
