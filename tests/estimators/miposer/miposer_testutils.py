"""Helpers of the MI-Poser tests: a tiny in-memory corpus of smooth synthetic motions."""

from __future__ import annotations

import math
import zlib

import torch

from wearpose.geometry import axis_angle_to_matrix
from wearpose.motion import MotionSequence


def synthetic_motion(seed: int, seconds: float = 2.0, fps: float = 60.0, amp: float = 0.4) -> MotionSequence:
    """Smooth random joint rotations (sinusoids), a turning, walking root; float32."""
    g = torch.Generator().manual_seed(seed)
    T = int(round(seconds * fps))
    t = torch.arange(T, dtype=torch.float64)[:, None, None] / fps
    f = 0.3 + 1.2 * torch.rand(1, 24, 3, generator=g, dtype=torch.float64)
    ph = 2 * math.pi * torch.rand(1, 24, 3, generator=g, dtype=torch.float64)
    aa = amp * torch.sin(2 * math.pi * f * t + ph)
    aa[:, 0] = 0.0
    aa[:, 0, 1] = float(torch.rand(1, generator=g)) * 6.0 + 0.6 * t[:, 0, 0]  # heading + slow turn
    pose = axis_angle_to_matrix(aa)
    trans = torch.zeros(T, 3, dtype=torch.float64)
    trans[:, 0] = 0.3 * t[:, 0, 0]
    trans[:, 1] = 0.95
    return MotionSequence(pose.float(), torch.zeros(10), trans.float(), fps, {})


class FakeStore:
    """The part of :class:`~wearpose.motion.CorpusStore` the MI-Poser code uses."""

    def __init__(self, root, n: int = 2, seconds: float = 2.0) -> None:
        self.root, self.n, self.seconds = root, n, seconds

    def clips(self, split=None):
        return [f"{split}/clip{i}" for i in range(self.n)]

    def load(self, cid):
        return synthetic_motion(zlib.crc32(cid.encode()), self.seconds)

    def entry(self, cid):
        return {"description": f"wave-{cid[-1]} (style: test)", "clip": cid}

