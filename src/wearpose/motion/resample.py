"""Change a sequence's frame rate: slerp for rotations, linear interpolation for translation."""

from __future__ import annotations

import copy
import math

import torch

from wearpose.errors import ShapeError
from wearpose.geometry import slerp_matrix
from wearpose.motion.sequence import MotionSequence


def resample(seq: MotionSequence, fps: float) -> MotionSequence:
    """Resample ``seq`` to ``fps`` frames per second.

    Source frame ``i`` is at time ``i / seq.fps``. The output frames are at ``t_k = k / fps`` for
    every ``k >= 0`` with ``t_k <= (T - 1) / seq.fps`` (no extrapolation past the last sample),
    each interpolated between its two neighbouring source frames: per-joint rotations by slerp
    (shortest path, constant angular velocity between samples), ``trans`` linearly.

    Args:
        seq: input sequence, ``T`` frames.
        fps: target rate (> 0).

    Returns:
        A new :class:`MotionSequence` with ``fps`` set and ``meta["resampled_from_fps"]`` recorded.
    """
    fps = float(fps)
    if not math.isfinite(fps) or fps <= 0:
        raise ShapeError(f"resample: fps must be a positive number, got {fps!r}")
    meta = copy.deepcopy(seq.meta)
    meta.setdefault("resampled_from_fps", seq.fps)
    T = seq.num_frames
    if abs(fps - seq.fps) < 1e-9:
        return MotionSequence(seq.pose.clone(), seq.betas.clone(), seq.trans.clone(), fps, meta)
    if T == 1:
        return MotionSequence(seq.pose.clone(), seq.betas.clone(), seq.trans.clone(), fps, meta)
    last = (T - 1) / seq.fps
    # Small tolerance so that a grid point landing on the last sample is not lost to rounding.
    n_out = int(math.floor(last * fps + 1e-6)) + 1
    t = torch.arange(n_out, dtype=torch.float64) / fps
    u = (t * seq.fps).clamp(0, T - 1)
    i0 = torch.floor(u).long().clamp(max=T - 2)
    w = (u - i0.to(torch.float64)).clamp(0.0, 1.0)
    R0, R1 = seq.pose[i0].to(torch.float64), seq.pose[i0 + 1].to(torch.float64)
    pose = slerp_matrix(R0, R1, w[:, None].expand(n_out, R0.shape[1]))
    tr0, tr1 = seq.trans[i0].to(torch.float64), seq.trans[i0 + 1].to(torch.float64)
    trans = tr0 + (tr1 - tr0) * w[:, None]
    return MotionSequence(pose.to(seq.dtype), seq.betas.clone(), trans.to(seq.dtype), fps, meta)
